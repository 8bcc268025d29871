"""The ``ilic`` process's end (:func:`ilic_cli.cli.run`, issue 33): without the interpreter's teardown, but as Python ends one.

Non-daemon threads joined, ``atexit`` functions run, buffered output flushed
into a pipe, the status of :func:`ilic_cli.cli.main` kept.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]

PROBE = """
import atexit, sys, threading
atexit.register(lambda: print("atexit ran"))
done = threading.Event()
threading.Thread(target=lambda: (done.wait(), print("thread finished"))).start()
threading._register_atexit(done.set)  # run by the interpreter's exit before it joins the threads (as concurrent.futures' executors)
sys.argv = ["ilic", *sys.argv[1:]]
from ilic_cli.cli import run
run()
"""


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # stdout into a pipe is then buffered: lost unless flushed
    return subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=ROOT, timeout=120, env=env)


def test_output_threads_and_atexit_as_python_ends() -> None:
    proc = _run("--version")
    assert proc.returncode == 0
    lines = proc.stdout.splitlines()
    assert lines[0] == "ilic, version " + lines[0].split()[-1]  # buffered (a pipe) and still written
    assert lines[1:] == ["thread finished", "atexit ran"]  # threads released and joined first, then atexit, as the interpreter does


def test_status_of_an_error_is_kept(tmp_path: Path) -> None:
    proc = _run("info", str(tmp_path / "missing.mat"))
    assert proc.returncode == 2
    assert "no such file" in proc.stderr
