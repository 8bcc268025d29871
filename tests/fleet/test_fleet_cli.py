"""``ilic batch`` and ``ilic trend`` on the command line: help, and no heavy import for it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from ilic_cli.commands import batch as batch_cmd
from ilic_cli.commands import trend as trend_cmd
from ilic_cli.commands.groups import option_group
from ilic_cli.errors import IlicError
from ilic_cli.fleet import execute
from ilic_cli.fleet.trend import TrendSettings
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


def test_an_option_group_reaches_the_command_as_one_typed_object() -> None:
    """``option_group``: the options keep their help order and the command gets the object ``build`` made of them, nothing else."""
    seen: dict[str, object] = {}

    @click.command()
    @click.option("--first", default=1, type=int)
    @option_group("pair", lambda a, b: (a, b), click.option("--a", default=2, type=int), click.option("--b", "b", default="x"))
    @click.option("--last", default=3, type=int)
    def cmd(**kwargs: object) -> None:
        seen.update(kwargs)

    res = CliRunner().invoke(cmd, ["--b", "y", "--last", "4"])
    assert res.exit_code == 0, res.output
    assert seen == {"first": 1, "pair": (2, "y"), "last": 4}
    assert [p.name for p in cmd.params] == ["first", "a", "b", "last"]


def test_batch_builds_its_task_settings_and_placement_from_the_options() -> None:
    """``ilic batch``'s option groups: the task's settings and where tasks run, typed; a contradiction names its option."""
    assert batch_cmd._task_settings("ls", "rigid", 3.0, True) == execute.TaskSettings(method="ls", structure="rigid", window_s=3.0, diagnose=True)
    assert batch_cmd._placement(None, "local:3", None) == execute.Placement(dask_workers=3)
    assert batch_cmd._placement(2, None, None).runner(1) is execute.in_process  # one log: no pool
    assert batch_cmd._placement(2, None, None).runner(5).__qualname__.startswith("local_processes")
    assert execute.Placement(scheduler="tcp://h:1").runner(5).__qualname__.startswith("dask_runner")
    for args, option in [((1, "local:2", None), "--jobs"), ((None, None, "h:1"), "--scheduler"), ((None, "local:0", None), "--dask")]:
        with pytest.raises(IlicError) as info:
            batch_cmd._placement(*args)
        assert info.value.message().startswith(option)


def test_trend_builds_its_settings_from_the_options() -> None:
    assert trend_cmd._trend_settings("DIDIM", 0.05, 15.0, "bh") == TrendSettings(alpha=0.05, min_change_pct=15.0, correction="bh", method="DIDIM")
