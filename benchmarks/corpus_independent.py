"""Logs of a simulator written apart from ``ilic``'s plant, diagnosed and identified (issue 29: right on logs nobody tuned it to).

Every case runs :func:`tests.corpus.independent.simulate` (the textbook PD loop, the backward difference of the measured
position, acting at its sample or one period later; semi-implicit Euler; Coulomb friction with stiction; the effects
written out in the force balance) on the 12 kg linear axis and the 0.08 kg·m² revolute joint of
:mod:`tests.logs.test_rates`, at 500 Hz, 1 and 2 kHz. Each log is diagnosed and, when clean, identified with
``identify --method ls``, through the library, with the loop declared as a CSV would declare it (no ``vir``).

Prints one Markdown row per log: what the diagnosis names, each named value against the truth (the largest relative
error), and for the clean logs ``identify``'s largest error of M, Fv, Fc; then the counts.

Usage: python benchmarks/corpus_independent.py [--jobs 2]
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RATES_HZ = (500.0, 1000.0, 2000.0)
LOOPS = ("same", "previous")

# (axis, name, effects, repeat, seed, the named effect and its values as the diagnosis reports them)
CASES: tuple[tuple[str, str, dict[str, Any], int, int, str | None, dict[str, float]], ...] = (
    ("linear", "clean", {}, 1, 11, None, {}),
    ("revolute", "clean", {}, 1, 21, None, {}),
    ("linear", "warm-up", {"drift": {"dFv": -11.0, "tau": 2.0}}, 2, 12, "friction_drift", {"Fv_change": -11.0, "Fv_tau": 2.0}),
    ("revolute", "warm-up", {"drift": {"dFv": -0.06, "tau": 2.0}}, 2, 23, "friction_drift", {"Fv_change": -0.06, "Fv_tau": 2.0}),
    ("revolute", "gravity", {"gravity": {"MX": 0.02, "MY": 0.01}}, 1, 22, "gravity", {"MX": 0.02, "MY": 0.01}),
    ("linear", "spring", {"spring": {"k": 15.0, "q0": 0.0}}, 1, 16, "spring", {"k": 15.0}),
    # the catalogue's Fs is the static friction above Coulomb's (here 6 - 4 and 0.45 - 0.3)
    ("linear", "Stribeck", {"stribeck": {"Fs": 6.0, "vs": 0.02}}, 1, 14, "stribeck", {"Fs": 2.0, "vs": 0.02}),
    ("revolute", "Stribeck", {"stribeck": {"Fs": 0.45, "vs": 0.1}}, 1, 25, "stribeck", {"Fs": 0.15, "vs": 0.1}),
    ("linear", "payload", {"payload": {"dM": 3.0, "t": 4.3}}, 2, 13, "payload_change", {"dM": 3.0, "t_change": 4.3}),
    ("linear", "delay 2 ms", {"delay": {"delay": 0.002}}, 1, 18, "delay", {"delay": -0.002}),
)


def run(case: tuple[Any, ...], fs_hz: float, loop: str) -> dict[str, Any]:
    from ilic_cli.diagnosis import DiagnoseSettings, diagnose
    from ilic_cli.identify import identify
    from tests.corpus.independent import simulate
    from tests.logs.test_rates import AXES

    axis, name, effects, repeat, seed, named, truth = case
    log = simulate(axis, fs_hz, loop, effects, seed, repeat)
    diag = diagnose(log, settings=DiagnoseSettings())
    found = {f.effect.id: {k: v.value for k, v in f.parameters.items()} for f in diag.findings}
    row: dict[str, Any] = {"case": f"{axis} {name}", "rate": fs_hz, "loop": loop, "found": sorted(found)}
    row["exact"] = sorted(found) == ([named] if named else [])
    row["error"] = max((abs(found[named][k] / v - 1.0) for k, v in truth.items()), default=None) if named in found else None
    if named is None:
        ls = identify(log, method="ls").ls
        assert ls is not None
        est = dict(zip(ls.result.names, ls.result.theta, strict=True))
        row["identify"] = max(abs(est[k] / AXES[axis].truth[k] - 1.0) for k in ("M", "Fv", "Fc"))
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    jobs = [(c, fs, loop) for c in CASES for fs in RATES_HZ for loop in LOOPS]
    with ProcessPoolExecutor(args.jobs) as pool:
        rows = list(pool.map(run, *zip(*jobs, strict=True)))
    print("| log | rate | loop | named | largest error of its values | identify: largest error of M, Fv, Fc |")
    print("| --- | --- | --- | --- | --- | --- |")
    for r in rows:
        err = "-" if r["error"] is None else f"{100 * r['error']:.1f} %"
        ident = f"{100 * r['identify']:.2f} %" if "identify" in r else ""
        named = (", ".join(r["found"]) or "nothing") + ("" if r["exact"] else " (not exact)")
        print(f"| {r['case']} | {r['rate']:g} Hz | {r['loop']} | {named} | {err} | {ident} |")
    exact = sum(r["exact"] for r in rows)
    within = [r["error"] for r in rows if r["error"] is not None]
    clean = [r for r in rows if "identify" in r]
    print()
    print(f"named exactly {exact}/{len(rows)}; values within 15 % on {sum(e <= 0.15 for e in within)}/{len(within)} named effects; ", end="")
    print(f"clean logs with a finding {sum(bool(r['found']) for r in clean)}/{len(clean)}; ", end="")
    print(f"identify within 2 % on {sum(r['identify'] <= 0.02 for r in clean)}/{len(clean)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
