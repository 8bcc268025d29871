"""Speed of the closed-loop plant: simulated time / wall time.

(a) paper-sim, 124 s, CTC + online IDIM-ILIC (20 windows), 10 RK4 substeps per 1 ms;
(b) emps-benchmark PD replay of DATA_EMPS.mat (24.84 s), if ../shared/emps is there;
(c) baseline: scipy.integrate.solve_ivp (RK45) over the same CTC loop, control held
    per period (one solve per period), on a shorter span;
(d) the same compiled loop run as plain Python (NUMBA_DISABLE_JIT=1, in a subprocess),
    on a shorter span: the figure that justified numba.

Usage: python benchmarks/bench_plant.py [--quick]
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def best_of(fn, repeat: int = 3) -> float:  # type: ignore[no-untyped-def]
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def ours_paper_sim(duration: float = 124.0) -> float:
    from ilic_cli.simulation.scenarios import Overrides, run_scenario

    run_scenario("paper-sim", Overrides(duration_s=6.3))  # JIT compile, scipy.signal import: outside the timing
    wall = best_of(lambda: run_scenario("paper-sim", Overrides(duration_s=duration)))
    return duration / wall


def ours_emps() -> float | None:
    from ilic_cli.simulation.scenarios import DEFAULT_EMPS_LOG, Overrides, run_scenario

    if not DEFAULT_EMPS_LOG.exists():
        return None
    wall = best_of(lambda: run_scenario("emps-benchmark", Overrides()))
    return 24.84 / wall


def scipy_baseline(duration: float = 6.2) -> float:
    """solve_ivp (RK45) per control period with the CTC force held; sign friction; no online update."""
    import numpy as np
    from scipy.integrate import solve_ivp

    from plant.trajectories import exciting_cycle

    M, Fv, Fc = 95.0, 200.0, 20.0
    chi = (100.0, 0.0, 0.0)
    Kp, Kv, alpha, T = (2 * math.pi * 20) ** 2, 2 * (math.sqrt(2) / 2) * 2 * math.pi * 20, 1000.0, 1e-3
    n = int(round(duration * 1000))
    _, q_r, qd_r, qdd_r = exciting_cycle().sample(n, 1000.0)

    def run() -> None:
        x = np.array([q_r[0], qd_r[0]])
        q_prev = q_r[0] - qd_r[0] * T
        for k in range(n):
            qd_hat = (x[0] - q_prev) / T
            q_prev = x[0]
            w = Kp * (q_r[k] - x[0]) + Kv * (qd_r[k] - qd_hat) + qdd_r[k]
            u = chi[0] * w + chi[1] * qd_r[k] + chi[2] * (2 / math.pi) * math.atan(alpha * qd_r[k])
            sol = solve_ivp(lambda t, y: (y[1], (u - Fv * y[1] - Fc * np.sign(y[1])) / M), (0.0, T), x, rtol=1e-9, atol=1e-12)
            x = sol.y[:, -1]

    return duration / best_of(run, repeat=1)


def pure_python(duration: float = 2.0) -> float:
    code = (
        "import time,sys; sys.path.insert(0, %r)\n"
        "from ilic_cli.simulation.scenarios import Overrides, run_scenario\n"
        "t0=time.perf_counter(); run_scenario('paper-sim', Overrides(duration_s=%r)); print(time.perf_counter()-t0)\n"
    ) % (str(ROOT), duration)
    env = dict(os.environ, NUMBA_DISABLE_JIT="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return duration / float(out.stdout.strip().splitlines()[-1])


def main() -> None:
    quick = "--quick" in sys.argv
    t0 = time.perf_counter()
    from plant.kernel import run_periods  # noqa: F401  (import = load or compile the cached machine code)

    print(f"import + JIT load/compile: {time.perf_counter() - t0:.2f} s")
    a = ours_paper_sim(31.0 if quick else 124.0)
    print(f"(a) paper-sim CTC + online IDIM-ILIC : {a:8.0f} x real time")
    b = ours_emps()
    print(f"(b) emps-benchmark PD replay 24.84 s : {b:8.0f} x real time" if b else "(b) emps-benchmark: ../shared/emps absent, skipped")
    c = scipy_baseline(1.0 if quick else 6.2)
    print(f"(c) scipy solve_ivp baseline (CTC)   : {c:8.2f} x real time   -> ours/baseline = {a / c:.0f}")
    d = pure_python(0.5 if quick else 2.0)
    print(f"(d) same loop, plain Python (no JIT) : {d:8.2f} x real time   -> numba speed-up = {a / d:.0f}")


if __name__ == "__main__":
    main()
