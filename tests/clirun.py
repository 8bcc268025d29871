"""Run the ``ilic`` command line in-process and capture its streams and status."""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

from ilic_cli.cli import main


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
