"""How ``ilic diagnose`` does on the corpus of simulated logs with known truth (issue #11, tests/corpus/__init__.py).

Runs :func:`ilic_cli.diagnosis.core.diagnose` (what ``ilic diagnose`` runs,
default settings, replay included) on every case of :data:`tests.corpus.CASES`
and prints a Markdown table, one row a case: the truth, the findings, and per
finding ``right`` / ``false alarm``, plus the effects ``missed``. Scoring
(:func:`tests.corpus.score`):

* ``offset`` is always right (the rigid-offset model's column, not physics);
* a ``delay`` on a log with a current loop and no concealed lag is right when
  its drive lag (beyond the hold) is within 50 % of the loop's time constant;
* a concealed effect named is right; any other finding is a false alarm.

Summary: the false-alarm rate on clean cases (cases with any false alarm),
the detection rate on effect cases (effects named; cases named exactly), the
parameter error of the effects named (worst relative error of their main
parameters; the lag of a ``delay`` is measured beyond the hold and compared
with the concealed lag plus the current loop's time constant), whether the
closed-loop simulated force error improved where something was accepted, how
many of those kept the closed-loop refit's estimates (:mod:`ilic_cli.diagnosis.refit`), and
the distribution of the first round's best p-value on clean cases.

``--reseed N``: each chosen effect case is run again with ``N`` other seeds
(its seed plus 1000, 2000, ...; named ``case@sSEED``), the effects and their
sizes as they are: how an estimate scatters over recordings, not over one.

``--design``: calibrate the effect cases anew (:func:`tests.corpus.design`) and
print them as the literal of ``tests/corpus/__init__.py`` (about two minutes).

Usage: python benchmarks/diagnose_corpus.py [--jobs 2] [--cases GLOB] [--json FILE] [--reseed N] [--design]
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.corpus import CASES, PARAM_TOLERANCE, build_case, case_of, reseeded, score  # noqa: E402


def run_case(name: str) -> dict[str, Any]:
    """Build one case's log and diagnose it (a worker of the pool)."""
    from ilic_cli.diagnosis.core import diagnose
    from ilic_cli.errors import IlicError

    case = case_of(name)
    t0 = time.process_time()
    log = build_case(case)
    t1 = time.process_time()
    try:
        diag = diagnose(log)
    except IlicError as exc:
        raise RuntimeError(f"{name}: {exc}") from exc
    t2 = time.process_time()
    findings = [(f.effect.id, f.plant_effect) for f in diag.findings]
    first = [e.test.p_value for e in diag.tried[0]] if diag.tried else []
    return {
        "case": name,
        "clean": case.clean,
        "truth": case.effects,
        "size_pts": case.size_pts,
        "findings": [{"effect": eid, "plant": plant} for eid, plant in findings],
        **score(case, findings),
        "first_round_min_p": min(first) if first else None,
        "refit": None if diag.refit is None else {"accepted": diag.refit.accepted, "reason": diag.refit.reason},
        "fit": diag.fit,
        "cpu_s": {"simulate": t1 - t0, "diagnose": t2 - t1},
    }


def _fmt_effects(effects: dict[str, Any]) -> str:
    return "; ".join(f"{k}({', '.join(f'{n}={v:.3g}' for n, v in p.items())})" for k, p in effects.items()) or "-"


def _fmt_finding(f: dict[str, Any]) -> str:
    p = f["plant"]
    return f["effect"] if not p else f"{f['effect']}({', '.join(f'{n}={v:.3g}' for n, v in p.items())})"


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The rates of the issue's "Done when"."""
    clean = [r for r in rows if r["clean"]]
    eff = [r for r in rows if not r["clean"]]
    named = sum(len(r["truth"]) - len(r["missed"]) for r in eff)
    total = sum(len(r["truth"]) for r in eff)
    errs = [e for r in eff for e in r["parameter_error"].values()]
    finite = [e for e in errs if math.isfinite(e)]
    accepted = [r for r in rows if any(f["effect"] != "offset" for f in r["findings"])]

    def improved(r: dict[str, Any]) -> bool:
        s = r["fit"].get("simulation_force_relative_error_pct") or {}
        return s.get("before") is not None and s.get("after") is not None and s["after"] < s["before"]

    ps = sorted(r["first_round_min_p"] for r in clean if r["first_round_min_p"] is not None)

    def q(x: float) -> float | None:
        return ps[min(int(x * len(ps)), len(ps) - 1)] if ps else None

    return {
        "clean_cases": len(clean),
        "clean_without_false_alarm": sum(r["false_alarms"] == 0 for r in clean),
        "false_alarm_rate": sum(r["false_alarms"] > 0 for r in clean) / len(clean) if clean else None,
        "effect_cases": len(eff),
        "effects_named": named,
        "effects_total": total,
        "detection_rate": named / total if total else None,
        "effect_cases_exact": sum(not r["missed"] and r["false_alarms"] == 0 for r in eff),
        "effect_cases_with_false_alarm": sum(r["false_alarms"] > 0 for r in eff),
        "parameter_error_median": sorted(finite)[len(finite) // 2] if finite else None,
        "parameters_within_15pct": sum(e <= PARAM_TOLERANCE for e in finite),
        "parameters_compared": len(errs),
        "accepted_cases": len(accepted),
        "accepted_sim_force_improved": sum(improved(r) for r in accepted),
        "refit_accepted": sum(bool(r.get("refit") and r["refit"]["accepted"]) for r in accepted),
        "clean_first_round_min_p": {"min": ps[0] if ps else None, "q25": q(0.25), "median": q(0.5), "q75": q(0.75), "max": ps[-1] if ps else None},
    }


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{x:.0%}"


def render(rows: list[dict[str, Any]], summ: dict[str, Any]) -> str:
    lines = ["| case | size (pts) | truth | findings | verdicts | missed | param err |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['case']} | {'' if r['size_pts'] is None else r['size_pts']} | {_fmt_effects(r['truth'])} | "
            f"{'; '.join(_fmt_finding(f) for f in r['findings']) or '-'} | {', '.join(r['verdicts']) or '-'} | {', '.join(r['missed']) or '-'} | "
            f"{', '.join(f'{k} {v:.0%}' for k, v in r['parameter_error'].items()) or '-'} |"
        )
    s = summ
    lines += [
        "",
        f"- clean cases without a false alarm: {s['clean_without_false_alarm']}/{s['clean_cases']} (false-alarm rate {_pct(s['false_alarm_rate'])})",
        f"- effects named: {s['effects_named']}/{s['effects_total']} in {s['effect_cases']} effect cases; "
        f"named exactly (nothing else but offset): {s['effect_cases_exact']}; with a false alarm: {s['effect_cases_with_false_alarm']}",
        f"- parameters within 15 %: {s['parameters_within_15pct']}/{s['parameters_compared']} (median worst error {s['parameter_error_median']})",
        f"- closed-loop simulated force error improved: {s['accepted_sim_force_improved']}/{s['accepted_cases']} cases with an accepted effect",
        f"- estimates refitted on the closed loop (DIDIM, nonlinear values searched): {s['refit_accepted']}/{s['accepted_cases']} "
        "(the others keep the inverse model's: see each case's refit reason in --json)",
        f"- clean cases, first round's best p-value: {s['clean_first_round_min_p']}",
    ]
    return "\n".join(lines)


def over_seeds(rows: list[dict[str, Any]]) -> str:
    """``--reseed``: one Markdown row per effect case over its seeds (named, named exactly, worst parameter errors)."""
    by: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if not r["clean"]:
            by.setdefault(r["case"].partition("@s")[0], []).append(r)
    lines = ["| case | seeds | effects named | named exactly | within 15 % | worst parameter error over the seeds |", "|---|---|---|---|---|---|"]
    for name, rs in by.items():
        errs = [max(r["parameter_error"].values()) for r in rs if r["parameter_error"]]
        params = [e for r in rs for e in r["parameter_error"].values()]
        lines.append(
            f"| {name} | {len(rs)} | {sum(len(r['truth']) - len(r['missed']) for r in rs)}/{sum(len(r['truth']) for r in rs)} | "
            f"{sum(not r['missed'] and r['false_alarms'] == 0 for r in rs)}/{len(rs)} | {sum(e <= PARAM_TOLERANCE for e in params)}/{len(params)} | "
            f"{', '.join(f'{e:.0%}' for e in errs) or '-'} |"
        )
    return "\n".join(lines)


class _Serial:
    """A stand-in for a pool of one process."""

    def __enter__(self) -> _Serial:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def map(self, fn: Any, items: Any, chunksize: int = 1) -> list[Any]:
        return [fn(x) for x in items]


def _pool(jobs: int) -> Any:
    """``jobs`` worker processes (spawned: each imports and compiles on its own), or in-process for one."""
    if jobs <= 1:
        return _Serial()
    from multiprocessing import get_context

    from ilic_cli.parallel import THREADS_ENV

    os.environ[THREADS_ENV] = "1"  # one log per process: no threads within (the workers inherit it)
    return get_context("spawn").Pool(jobs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--cases", default="*", help="glob of case names (default all)")
    ap.add_argument("--json", type=Path, default=None, help="also write every row and the summary as JSON")
    ap.add_argument("--reseed", type=int, default=0, metavar="N", help="run each chosen effect case again with N other seeds (the same effects and sizes)")
    ap.add_argument("--design", action="store_true", help="calibrate the effect cases anew and print them")
    args = ap.parse_args(argv)
    if args.design:
        from tests.corpus import design, recipes

        with _pool(args.jobs) as pool:
            for c in pool.map(design, recipes(), chunksize=1):
                print(f"    Case({c.name!r}, {c.trajectory!r}, {c.noise!r}, {c.seed}, {c.effects!r}, {c.size_pts!r}),".replace("'", '"'))
        return 0
    names = [n for n in CASES if fnmatch.fnmatch(n, args.cases)]
    if not names:
        print(f"no case matches {args.cases!r}", file=sys.stderr)
        return 2
    names += [reseeded(n, k) for n in names if not CASES[n].clean for k in range(1, args.reseed + 1)]
    with _pool(args.jobs) as pool:
        rows = pool.map(run_case, names, chunksize=1)
    summ = summary(rows)
    print(render(rows, summ))
    if args.reseed:
        print("\n" + over_seeds(rows))
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "summary": summ}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
