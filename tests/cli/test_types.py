"""The library type-checks (``[tool.mypy]`` in pyproject.toml; issue 32, item 6)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("ilic_cli", "plant")


def test_mypy_passes() -> None:
    """``mypy ilic_cli plant`` reports no error: one cold run, no cache written (``--cache-dir /dev/null``, mypy's documented way:
    not in the tree, none shared between workers; a run that writes its cache took 19.3-20.4 s against 18.0 s)."""
    res = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", os.devnull, "--no-color-output", *PACKAGES], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_no_blanket_type_ignores() -> None:
    """No module or override silences mypy wholesale, and every line-level ``type: ignore`` names its error code."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
    assert "ignore_errors" not in config
    assert all("ignore_errors" not in override for override in config.get("overrides", []))
    offenders = [
        f"{p.relative_to(ROOT)}:{i}"
        for package in PACKAGES
        for p in sorted((ROOT / package).rglob("*.py"))
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if re.search(r"#\s*type:\s*ignore(?!\[)", line) or re.match(r"\s*#\s*mypy:", line)
    ]
    assert not offenders, offenders
