"""``-p tests.cpu_durations``: the tests' CPU time, a child's included, listed by cost (``tests/cpu_durations.py``).

The inner session runs in this process (``pytester.runpytest_inprocess``) on the plugin this module imported, its totals
emptied for it and put back after: ``tools/mutation.py`` serves its planted bugs from memory, and a session in a child process read the file
and never saw them (both planted bugs survived); an outer session run with the plugin (``make test PYTEST_ARGS="-p
tests.cpu_durations ..."``) keeps its own totals."""

from __future__ import annotations

import re

import pytest

from tests import cpu_durations

pytest_plugins = ["pytester"]

BURN = """
import subprocess, sys, time

def _spin(seconds):
    end = time.process_time() + seconds
    while time.process_time() < end:
        pass

def test_spins_in_a_child():
    subprocess.run([sys.executable, "-c", "import time\\nend = time.process_time() + 0.25\\nwhile time.process_time() < end: pass"], check=True)

def test_spins_itself():
    _spin(0.12)

def test_sleeps():
    time.sleep(0.15)
"""


def test_the_costliest_tests_are_listed_with_their_children_s_cpu(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_burn=BURN)
    outer = dict(cpu_durations._totals)  # an outer session's with the plugin: put back before this test's own report
    cpu_durations._totals.clear()
    try:
        res = pytester.runpytest_inprocess("-q", "-p", "no:cacheprovider", "-p", "tests.cpu_durations", "--cpu-durations=2", "-o", "addopts=")
    finally:
        cpu_durations._totals.clear()
        cpu_durations._totals.update(outer)
    out = res.stdout.str()
    assert res.ret == 0, out
    listed = re.findall(r"^\s*([\d.]+)s cpu (\S+)$", out, re.MULTILINE)
    assert [name.split("::")[1] for _, name in listed] == ["test_spins_in_a_child", "test_spins_itself"], out  # the sleep costs none
    assert float(listed[0][0]) >= 0.25 and 0.12 <= float(listed[1][0]) < 0.25, out
    assert "most CPU time: 2 of 3 tests" in out
