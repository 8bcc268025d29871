"""``ilic_cli/jit.py`` (issue 33): numba's BLAS check answered without ``scipy.linalg`` (the same answer, and BLAS still there when asked for);
the cached loop loaded without numba's registries, which a function not in the cache still gets."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

PROBE = """
import json, sys
import numpy as np
from ilic_cli.simulation.scenarios import Overrides, run_scenario
log = run_scenario('paper-sim', Overrides(duration_s=0.5, seed=0))
from numba.core.registry import cpu_target
report = {"registries_after_loop": len(cpu_target.target_context._registries)}
sys.path.insert(0, sys.argv[1])
import uncached  # a function numba's cache does not have: compiled, with the registries
report["uncached"] = uncached.twice(3.0)
report["bare_cache"] = type(uncached.twice._cache).__name__
report["registries_after_compile"] = len(cpu_target.target_context._registries)
import numba.np.arraymath
import numba.np.linalg
report |= {"samples": len(log), "linalg_after_loop": "scipy.linalg" in sys.modules, "have_blas": numba.np.arraymath._HAVE_BLAS,
          "numbas_check_back": numba.np.linalg.ensure_blas is numba.np.arraymath.ensure_blas and numba.np.linalg.ensure_blas.__module__ == "numba.np.linalg"}
from numba import njit
dot = njit(lambda a, b: np.dot(a, b))  # a BLAS routine compiled after the loop's load
a, b = np.linspace(0.0, 1.0, 64), np.linspace(1.0, 2.0, 64)
report["dot_matches"] = bool(np.isclose(dot(a, b), a @ b, rtol=1e-14))
report["blas_imported"] = hasattr(sys.modules.get("scipy.linalg.cython_blas"), "__pyx_capi__")
print(json.dumps(report))
"""


def test_loop_loads_without_scipy_linalg_and_blas_still_works(tmp_path: Path) -> None:
    # The first run fills numba's cache where it is cold (a clean clone: the loop is compiled there, with the
    # registries); the second is what every later process does, a load from the cache.
    # Each run gets its own new module, which numba's cache cannot have.
    for run in range(2):
        folder = tmp_path / f"run{run}"
        folder.mkdir()
        (folder / "uncached.py").write_text("from ilic_cli.jit import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2.0 * x\n")
        proc = subprocess.run([sys.executable, "-c", PROBE, str(folder)], capture_output=True, text=True, check=True, timeout=300)
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["samples"] == 500
    assert report["registries_after_loop"] == 0  # the cached loop loaded without numba's target registries
    assert report["uncached"] == 6.0 and report["bare_cache"] == "_CacheLoadedBare"
    assert report["registries_after_compile"] > 0  # a function not in the cache refreshed them, as numba's own load does
    assert report["linalg_after_loop"] is False  # the loop ran without importing scipy.linalg
    assert report["numbas_check_back"] is True  # numba's own ensure_blas is back where it was
    assert report["have_blas"] is True  # numba's check gave the answer it gives with scipy.linalg imported
    assert report["dot_matches"] is True and report["blas_imported"] is True  # a BLAS call compiled later imports the real module
