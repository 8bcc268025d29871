"""The command line's results do not depend on the BLAS's threads (:func:`ilic_cli.parallel.one_blas_thread`).

numpy's BLAS splits its sums over as many threads as the environment (or the machine's cores) gives it, and the
last bits followed: ``ilic identify DATA_EMPS.mat --method iv`` with two BLAS threads differed from one.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from ilic_cli.cli import main
from ilic_cli.parallel import BLAS_THREADS_ENV

ROOT = Path(__file__).parents[2]


def _identify_iv(mat: Path, blas_threads: str) -> str:
    env = os.environ | dict.fromkeys(BLAS_THREADS_ENV, blas_threads)
    proc = subprocess.run(
        [sys.executable, "-m", "ilic_cli", "identify", str(mat), "--method", "iv", "--format", "json"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        env=env,
        check=True,
    )
    return proc.stdout


def test_one_and_two_blas_threads_give_the_same_bits(emps_mat: Path) -> None:
    one = _identify_iv(emps_mat, "1")
    assert '"iv"' in one
    assert _identify_iv(emps_mat, "2") == one


def test_the_command_line_sets_one_blas_thread_whatever_the_environment_says(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in BLAS_THREADS_ENV:
        monkeypatch.setenv(name, "2")
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert {name: os.environ[name] for name in BLAS_THREADS_ENV} == dict.fromkeys(BLAS_THREADS_ENV, "1")
