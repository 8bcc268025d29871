"""``-p tests.cpu_durations``: the tests' CPU time, a child's included, listed by cost (``tests/cpu_durations.py``)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

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


def test_the_costliest_tests_are_listed_with_their_children_s_cpu(tmp_path: Path) -> None:
    (tmp_path / "test_burn.py").write_text(BURN)
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.cpu_durations", "--cpu-durations=2", "-o", "addopts=", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert res.returncode == 0, res.stdout + res.stderr
    listed = re.findall(r"^\s*([\d.]+)s cpu (\S+)$", res.stdout, re.MULTILINE)
    assert [name.split("::")[1] for _, name in listed] == ["test_spins_in_a_child", "test_spins_itself"], res.stdout  # the sleep costs none
    assert float(listed[0][0]) >= 0.25 and 0.12 <= float(listed[1][0]) < 0.25, res.stdout
    assert "most CPU time: 2 of 3 tests" in res.stdout
