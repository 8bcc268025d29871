"""Run the ``ilic`` command line in-process and capture its streams and status."""

from __future__ import annotations

import contextlib
import io
import shutil
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from ilic_cli.cli import main
from tests.shared_cache import folder_for, shared


@dataclass
class CliResult:
    status: int
    stdout: str
    stderr: str


def run_cli(*args: str) -> CliResult:
    """Call ``ilic ARGS`` through :func:`ilic_cli.cli.main`; return status and output."""
    out, err = io.StringIO(), io.StringIO()
    status = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main(list(args))
        except SystemExit as exc:
            status = int(exc.code or 0)
    return CliResult(status, out.getvalue(), err.getvalue())


@cache
def shared_run(*args: str) -> tuple[CliResult, Path]:
    """``ilic ARGS --out FOLDER`` once per test session, for every test (in either xdist worker) that asserts on that run:
    its status and output, and the folder it wrote (:func:`tests.shared_cache.folder_for`; read it, do not change it).

    ``ilic diagnose DATA_EMPS.mat --format json`` costs some 3 s of CPU, and three tests assert on it. Once per process too
    (``-n 0``: no shared folder, :func:`tests.shared_cache.shared` only computes).
    """
    key = "cli:" + "\0".join(args)
    out = folder_for(key)

    def run() -> CliResult:
        shutil.rmtree(out, ignore_errors=True)  # a folder a killed run left: written anew
        return run_cli(*args, "--out", str(out))

    return shared(key, run), out
