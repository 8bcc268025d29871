"""What the small job of the start-up budget imports (issue 33): ``ilic identify DATA_EMPS.mat --method ls``.

The job computes in some 25 ms; its start-up is the imports. Run in a fresh
interpreter, it must not load the heavy libraries that other paths defer
(plots, data frames, scipy's signal processing, I/O and sparse matrices).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("pandas", "matplotlib", "scipy", "dask", "pyarrow", "numba", "rosbags", "mcap", "zstandard", "sqlite3", "plant")
"""Top-level packages (or their submodules) the identify --method ls path must not import."""

PROBE = """
import json, sys
from ilic_cli.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    status = exc.code
print(json.dumps({"status": status, "modules": sorted(sys.modules)}), file=sys.stderr)
"""


def _modules_of(*args: str) -> tuple[int, set[str]]:
    proc = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, check=False, timeout=120)
    report = json.loads(proc.stderr.strip().splitlines()[-1])
    return report["status"], set(report["modules"])


@pytest.mark.parametrize("extra", [[], ["--format", "json"]], ids=["markdown", "json"])
def test_identify_ls_imports_no_heavy_library(emps_mat: Path, extra: list[str]) -> None:
    status, modules = _modules_of("identify", str(emps_mat), "--method", "ls", *extra)
    assert status == 0
    assert "ilic_cli.idim_ls" in modules and "numpy" in modules  # the probe saw the job's own imports
    heavy = sorted(m for m in modules if m.split(".")[0] in HEAVY)
    assert heavy == [], heavy


def test_help_imports_no_numpy() -> None:
    status, modules = _modules_of("--help")
    assert status == 0 and "click" in modules
    assert not [m for m in modules if m.split(".")[0] in ("numpy", *HEAVY)]
