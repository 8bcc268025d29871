"""A selection the log's format has nothing to apply to is refused, never ignored.

Reading a ``.mat`` with ``--joint wrist`` used to read its only joint as if the
option had not been given; now every selection field names the formats that
have what it selects (:data:`ilic_cli.io.SELECTED_BY`).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io import SELECTED_BY, Selection, read_log, write_log
from tests.clirun import run_cli
from tests.conftest import make_synthetic_log

OPTIONS = {"topic": "/joint_states", "ref_topic": "/joint_reference", "joint": "axis", "effort": "/joint_states", "columns": (("t", "t"),)}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("sel")
    log = make_synthetic_log(samples=2000)
    return {fmt: write_log(log, folder / f"log.{fmt}") for fmt in ("mat", "csv", "mcap")}


@pytest.mark.parametrize("fmt", ["mat", "csv", "mcap"])
@pytest.mark.parametrize("field", list(SELECTED_BY))
def test_a_selection_is_applied_or_refused(logs: dict[str, Path], fmt: str, field: str) -> None:
    selection = Selection(**{field: OPTIONS[field]})
    if fmt in SELECTED_BY[field][1]:
        if field == "effort":  # an ilic log's effort is its own: refused too, never ignored
            with pytest.raises(LogError, match="another effort topic cannot be chosen"):
                read_log(logs[fmt], selection=selection)
        else:
            read_log(logs[fmt], selection=selection)  # applies (the names are those of the file)
        return
    with pytest.raises(ChoiceError) as exc:
        read_log(logs[fmt], selection=selection)
    assert exc.value.choice == field.replace("_", "-") and f"a {fmt} log has no {SELECTED_BY[field][0]} to select" in str(exc.value)


def test_cli_refuses_in_one_line(logs: dict[str, Path]) -> None:
    res = run_cli("identify", str(logs["mat"]), "--method", "ls", "--joint", "wrist")
    assert res.status == 2 and res.stdout == ""
    assert res.stderr == f"ilic: error: {logs['mat']}: a mat log has no joint names to select with --joint\n"
