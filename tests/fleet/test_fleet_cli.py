"""``ilic batch`` and ``ilic trend`` on the command line: help, and no heavy import for it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.clirun import run_cli

ROOT = Path(__file__).parents[2]


@pytest.mark.parametrize("command", ["batch", "trend"])
def test_help_is_useful_and_listed(command: str) -> None:
    res = run_cli(command, "--help")
    assert res.status == 0, res.stderr
    assert f"Usage: ilic {command}" in res.stdout and "Examples:" in res.stdout and len(res.stdout.splitlines()) > 15
    assert command in run_cli("--help").stdout


def test_their_help_imports_no_dask_pyarrow_or_pandas() -> None:
    code = (
        "import sys; from ilic_cli.cli import cli; import click.testing as t; "
        "[t.CliRunner().invoke(cli, [c, '--help']) for c in ('batch', 'trend')]; "
        "print([m for m in ('dask', 'distributed', 'pyarrow', 'pandas', 'numpy', 'matplotlib') if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"
