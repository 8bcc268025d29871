"""Package-wide promises: instant --help (lazy imports), documented public API."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from tests.clirun import run_cli

ROOT = Path(__file__).parents[2]
HEAVY = ("numpy", "pandas", "scipy", "matplotlib", "rosbags", "mcap", "numba")


def test_help_imports_no_heavy_library() -> None:
    code = (
        "import sys; from ilic_cli.cli import cli; "
        "import click.testing as t; t.CliRunner().invoke(cli, ['--help']); "
        f"print([m for m in {HEAVY!r} if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("command", ["simulate", "replay", "identify", "diagnose", "convert", "info"])
def test_every_subcommand_has_useful_help(command: str) -> None:
    res = run_cli(command, "--help")
    assert res.status == 0, res.stderr
    assert f"Usage: ilic {command}" in res.stdout
    assert len(res.stdout.splitlines()) > 8


def test_top_level_help_lists_commands() -> None:
    res = run_cli("--help")
    assert res.status == 0
    for command in ("simulate", "replay", "identify", "diagnose", "convert", "info"):
        assert command in res.stdout


def test_unknown_option_is_one_line_exit_2() -> None:
    res = run_cli("identify", "--no-such-option")
    assert res.status == 2
    assert res.stderr.startswith("ilic: error: ") and res.stderr.count("\n") == 1


def _public_defs(path: Path) -> list[tuple[str, ast.AST]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: list[tuple[str, ast.AST]] = [(f"{path.name}:module", tree)]
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            found.append((f"{path.name}:{node.name}", node))
    return found


def test_public_functions_and_classes_have_docstrings() -> None:
    missing = []
    for package in ("ilic_cli", "plant"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if path.name == "__main__.py":
                continue
            for name, node in _public_defs(path):
                if name.endswith(":command"):
                    continue
                if ast.get_docstring(node) is None:  # type: ignore[arg-type]
                    missing.append(f"{path.relative_to(ROOT)} {name}")
    assert missing == []


def test_numpy_style_parameters_sections_name_real_parameters() -> None:
    """Where a docstring has a NumPy 'Parameters' section, every name in it is a real parameter."""
    wrong = []
    for package in ("ilic_cli", "plant"):
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if not isinstance(node, ast.FunctionDef):
                    continue
                doc = ast.get_docstring(node) or ""
                if "Parameters\n    ----------" not in doc and "Parameters\n----------" not in doc:
                    continue
                section = doc.split("----------", 1)[1].split("\n\n")[0] if "\n\n" in doc.split("----------", 1)[1] else doc.split("----------", 1)[1]
                names = {a.arg for a in node.args.args + node.args.kwonlyargs}
                for line in section.splitlines():
                    if line and not line.startswith(" ") and " : " in line:
                        for declared in line.split(" : ")[0].split(","):
                            if declared.strip() not in names:
                                wrong.append(f"{path.name}:{node.name} documents '{declared.strip()}'")
    assert wrong == []
