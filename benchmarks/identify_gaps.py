"""``identify --method ls`` on clean dwell-and-move logs with a gap in the time stamps (docs/logs.md, "Time base").

Every axis of :data:`tests.corpus.robot.AXES` x rate (250 Hz to 8 kHz) x S-curve and trapezoid, sensor noise alone, one seed
each; 0.3 s of samples removed at 30, 55 and 80 % of the log (120 logs). Prints each log beyond 2 % of M, Fv or Fc (or refused)
and the count within, beside the same log without its gap.

Usage: python benchmarks/identify_gaps.py
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ilic_cli.errors import IlicError  # noqa: E402
from ilic_cli.identify import identify  # noqa: E402
from ilic_cli.runlog import RunLog  # noqa: E402
from tests.corpus.robot import AXES, DWELL_TRAJECTORIES, Case, simulate  # noqa: E402

RATES_HZ = (250.0, 500.0, 1000.0, 2000.0, 8000.0)
AT = (0.3, 0.55, 0.8)
"""Where the gap starts, as a share of the log's length."""
GAP_S = 0.3
SEED0 = 4500


def errors(log: RunLog, axis: str) -> list[float]:
    """``identify --method ls``'s relative errors (%) of M, Fv, Fc on ``log``."""
    fit = identify(log, method="ls").ls
    assert fit is not None
    theta = dict(zip(fit.result.names, fit.result.theta, strict=True))
    return [100.0 * (theta[p] / AXES[axis].truth[p] - 1.0) for p in ("M", "Fv", "Fc")]


def main() -> int:
    within = total = refused = 0
    print("| log | gap at (s) | error with the gap: M, Fv, Fc (%) | without it (%) |")
    print("|---|---|---|---|")
    for k, (axis, fs, trajectory) in enumerate(itertools.product(AXES, RATES_HZ, DWELL_TRAJECTORIES)):
        case = Case(axis, trajectory, fs, "sensor", SEED0 + k)
        log = simulate(case, {})
        whole = errors(log, axis)
        t = log.t
        for at in AT:
            g0 = at * float(t[-1])
            keep = (t < g0) | (t > g0 + GAP_S)
            gapped = RunLog({n: np.asarray(log[n])[keep] for n in ("t", "q", "tau", "q_ref")}, log.units, log.meta)
            total += 1
            try:
                e = errors(gapped, axis)
            except IlicError as exc:
                refused += 1
                print(f"| {case.name} | {g0:.2f} | refused: {exc} | {', '.join(f'{x:+.2f}' for x in whole)} |")
                continue
            if max(abs(x) for x in e) <= 2.0:
                within += 1
            else:
                print(f"| {case.name} | {g0:.2f} | {', '.join(f'{x:+.2f}' for x in e)} | {', '.join(f'{x:+.2f}' for x in whole)} |")
    print(f"\nwithin 2 % of M, Fv and Fc: {within} of {total}; refused: {refused}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
