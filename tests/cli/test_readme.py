"""Every example of the README runs as written (from a folder with ``../shared`` beside it)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tests.clirun import run_cli
from tests.conftest import require_shared

README = (Path(__file__).resolve().parents[2] / "README.md").read_text()


def _block(after: str, lang: str) -> str:
    section = README.split(after, 1)[1]
    return re.search(rf"```{lang}\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]


@pytest.fixture()
def beside_shared(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder whose ``../shared`` is the real one, as from the repository root."""
    emps = require_shared()
    (tmp_path / "shared").symlink_to(emps.parent)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return work


def test_shell_examples_run(beside_shared: Path) -> None:
    lines = [line for line in _block("### Examples", "sh").splitlines() if line.strip()]
    assert len(lines) >= 8
    for line in lines:
        args = shlex.split(line)
        assert args[0] == "ilic"
        res = run_cli(*args[1:])
        assert res.status == 0, (line, res.stderr)
    assert (beside_shared / "report" / "model.json").is_file() and (beside_shared / "replayed.mcap").is_file()


def test_python_api_example_runs(beside_shared: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = _block("### Python API", "python")
    namespace: dict[str, object] = {}
    exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 - the README's own example
    frame = namespace["frame"]
    assert list(frame[frame.method == "IDIM-LS"].parameter) == ["M", "Fv", "Fc", "offset"]  # type: ignore[attr-defined]
    assert round(float(namespace["report"].ls.result.theta[0]), 4) == 95.1089  # type: ignore[attr-defined]
    assert "IDIM-LS" in capsys.readouterr().out  # the printed frame
