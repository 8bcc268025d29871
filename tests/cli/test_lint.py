"""The tree passes the project's lint configuration (``[tool.ruff]`` in pyproject.toml)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_ruff_passes() -> None:
    res = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_ruff_format_holds() -> None:
    """One layout for every file (``ruff format``, the line length of ``[tool.ruff]``)."""
    res = subprocess.run([sys.executable, "-m", "ruff", "format", "--check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_no_blanket_noqa() -> None:
    """Every ``noqa`` names the rule it silences."""
    offenders = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in sorted(ROOT.rglob("*.py"))
        if ".venv" not in p.parts
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if "# noqa" in line and "# noqa:" not in line
    ]
    assert not offenders, offenders
