"""Calibration and power of the replay's Monte-Carlo null (``ilic diagnose --null montecarlo``; issue #11 item 3).

Calibration (``--clean``): on clean corpus logs (:data:`tests.corpus.CLEAN_CASES`,
no physics beyond the rigid plant and its noise) every applicable catalogue
effect is forced through the replay's decision as the first candidate (its
nonlinear parameter searched on the log as the selection does,
:func:`ilic_cli.diagnosis.null.reproposed`), whatever the inverse model's
tests say of it. Each trial gives the asymptotic Diebold-Mariano p and the
Monte-Carlo p with ``B`` replicates. Under the null, ``P(p_MC <= k/(B+1)) =
k/(B+1)``: with ``B = 19``, 5 % of the trials should have ``p_MC <= 0.05``.

Power (``--effects``): on concealed single-effect corpus logs the true effect
is forced the same way; it should be accepted (``p_MC <= 1/(B+1)`` at ``B = 19``
is the smallest p there is).

On a log whose reference dwells, the closed loop's own Stribeck proposal
(:mod:`ilic_cli.diagnosis.dwell`) is one more trial, ``stribeck (dwells)``:
the diagnosis of the log, where the replay judges it after the effects it kept
(its level and ``vs`` searched per fold; too few folds with an estimate inside
the grid is a gate; Diebold-Mariano only).

Prints one Markdown row per trial and a summary; ``--json FILE`` keeps them.

``--replicates 0``: the Diebold-Mariano p alone (no Monte-Carlo null).
``--mc-below P``: the Monte-Carlo null only for trials whose Diebold-Mariano p
is at most ``P`` (the rule of both, ``--null montecarlo``, can only reject
there; the Monte-Carlo p alone is then measured on those trials only).
``--more-seeds K``: clean logs of seeds 3 .. K + 2 too (every trajectory under
every noise model), built as the corpus builds its own.

Each trial also records whether the diagnosis would judge it at all: the
gates before any replay (materiality, an estimate outside the effect's
physics or on the edge of its search) and whether the corpus's scoring counts
the forced finding as right (a delay of a current loop's size). The summary's
``judged_spurious`` rates are over the rest: the candidates the replay's test
alone must reject.

Usage: python benchmarks/null_calibration.py [--clean GLOB] [--effects GLOB] [--replicates 19] [--jobs 1]
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.corpus import CASES, CLEAN_CASES, EFFECT_CASES, NOISE_MODELS, TRAJECTORY_KINDS, Case  # noqa: E402


def forced_trials(name: str, replicates: int, seed: int = 0, effects: tuple[str, ...] | None = None, mc_below: float = 1.0) -> list[dict[str, Any]]:
    """Force each effect of ``effects`` (default: every applicable one; a concealed case: its own) through the replay on case ``name``."""
    import numpy as np

    from ilic_cli.diagnosis import dwell
    from ilic_cli.diagnosis.baseline import hold_s
    from ilic_cli.diagnosis.core import _prepare, diagnose, effect_fit, model_parameters
    from ilic_cli.diagnosis.decide import materiality, replay_decide
    from ilic_cli.diagnosis.null import MonteCarloNull, reproposed
    from ilic_cli.diagnosis.select import Searcher, Step, at_edge, fit_system, moving_rows, system
    from ilic_cli.effects import EFFECTS, applicable, catalogue_ids
    from ilic_cli.idim_ls import LSSettings
    from ilic_cli.prepare import prepare_log
    from ilic_cli.regressor import get_model
    from ilic_cli.runlog import joint_type
    from ilic_cli.simulation.replay import tau_sensor
    from tests.corpus import build_case, score

    case = CASES[name] if name in CASES else extra_clean_case(name)
    log = prepare_log(build_case(case)).log
    ls = LSSettings()
    base = get_model("rigid-offset")
    prep = lambda lg: _prepare(prepare_log(lg), base, ls)  # noqa: E731
    data = prep(log)
    rows = moving_rows(data)
    hold = hold_s(tau_sensor(log), log.fs_hz)

    def plant_of(steps, names, theta):  # type: ignore[no-untyped-def]
        return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))), hold)

    _, _, names = system(data, base, [], rows)
    joint = joint_type(log.units.get("q"))  # what the diagnosis proposes on this joint (gravity: revolute only)
    ids = effects or (
        tuple(case.effects) if case.effects else tuple(i for i in catalogue_ids(joint) if EFFECTS[i].identifiable and applicable(EFFECTS[i], names))
    )
    null = MonteCarloNull(replicates, seed, ls, prep)
    out = []
    for eid in ids:
        t0 = time.perf_counter()
        step = reproposed(data, base, [], Step(EFFECTS[eid]), rows)
        edge = at_edge(step.effect, Searcher(data, data.fs_hz, rows).grid(step.effect)[0], step.value) if step.effect.nonlinear else None
        # the gates the diagnosis applies before any replay (select.forward_select, decide.materiality): a gated candidate is never judged
        fit = fit_system(data, base, [step], rows)
        names1, theta1 = fit.names, fit.theta
        impossible = step.effect.impossible(theta1[data.W.shape[1] :], step.value) if step.effect.impossible is not None else None
        small = materiality(data, base, [], step, rows)
        # a forced finding the corpus's scoring counts as right (a delay of a current loop's size is physics),
        # in the effect's own vocabulary (a lag within the sample is realised in the plant as the current loop)
        right = score(case, [(eid, effect_fit(step, names1, theta1, np.zeros((len(theta1),) * 2), None, hold)[1])])["false_alarms"] == 0
        _, (dm,) = replay_decide(log, data, base, [], [step], rows, plant_of, alpha=0.0)
        row: dict[str, Any] = {"case": name, "effect": eid, "value": step.value, "edge": edge, "dm_p": dm.p_value}
        row.update({"gated": edge or impossible or small, "right": right})
        row.update({"force_before": dm.force_before, "force_after": dm.force_after})
        # the Monte-Carlo null only where the replay's test decides: not for a gated candidate, nor for a clean log's finding that is right
        if dm.p_value is not None and dm.p_value <= mc_below and replicates > 0 and not row["gated"] and not (case.clean and right):
            dist = null.distribution(log, data, base, [], step, rows, plant_of, 5, dm.p_value)
            row.update({"mc_p": dist.p_value, "t_obs": dist.t_obs, "t_null": dist.t_null.tolist(), "noise": dist.noise.to_dict()})
        row["wall_s"] = time.perf_counter() - t0
        out.append(row)
    if "stribeck" in ids and dwell.dwells(np.asarray(log["q_ref"]), log.fs_hz):
        # the closed loop's own proposal on a log whose reference dwells (diagnosis.dwell), judged where the diagnosis
        # judges it: after the effects the replay kept on that log (on a current-loop log, the loop's lag)
        t0 = time.perf_counter()
        diag = diagnose(log)
        (dm,) = [v for v in diag.decisions if v.effect == "stribeck" and v.proposed_by == dwell.METHOD]
        found = [(f.effect.id, f.plant_effect) for f in diag.findings if f.effect.id == "stribeck"]
        row = {"case": name, "effect": "stribeck (dwells)", "value": found[0][1] if found else None, "edge": None, "dm_p": dm.p_value}
        row.update({"gated": None if dm.p_value is not None else dm.reason, "right": bool(found) and score(case, found)["false_alarms"] == 0})
        row.update({"force_before": dm.force_before, "force_after": dm.force_after, "wall_s": time.perf_counter() - t0})
        out.append(row)
    return out


def extra_clean_case(name: str) -> Case:
    """A clean case beyond the corpus's two seeds, named as they are (``clean-TRAJECTORY-NOISE-sSEED``)."""
    _, traj, noise, seed = name.split("-")
    return Case(name, traj, noise, int(seed[1:]))


def _job(args: tuple[str, int, int, float]) -> list[dict[str, Any]]:
    try:
        name, replicates, seed, mc_below = args
        return forced_trials(name, replicates, seed, mc_below=mc_below)
    except Exception as exc:  # one case's failure is a row, not the end of the run
        return [{"case": args[0], "effect": "-", "value": None, "edge": None, "dm_p": None, "force_before": None, "error": repr(exc)}]


def summary(rows: list[dict[str, Any]], replicates: int) -> dict[str, Any]:
    """Rates: p_MC <= 0.05 and p_DM <= 0.05 / 0.01, and the trials without a p."""
    with_mc = [r for r in rows if r.get("mc_p") is not None]
    judged = [r for r in rows if r["dm_p"] is not None and not r.get("gated") and not r.get("right")]
    dm = [r["dm_p"] for r in rows if r["dm_p"] is not None]
    return {
        "trials": len(rows),
        "replicates": replicates,
        "mc_trials": len(with_mc),
        "mc_p_le_0.05": sum(r["mc_p"] <= 0.05 + 1e-12 for r in with_mc),
        "mc_p_le_0.10": sum(r["mc_p"] <= 0.10 + 1e-12 for r in with_mc),
        "dm_p_le_0.05": sum(p <= 0.05 for p in dm),
        "dm_p_le_0.01": sum(p <= 0.01 for p in dm),
        # what the diagnosis would judge: not gated before the replay, and not a finding the scoring counts as right
        "judged_spurious": len(judged),
        "judged_spurious_dm_p_le_0.01": sum(r["dm_p"] <= 0.01 for r in judged),
        "judged_spurious_mc_p_le_0.05": sum(r["mc_p"] <= 0.05 + 1e-12 for r in judged if r.get("mc_p") is not None),
        # the rule of `--null montecarlo`: the Diebold-Mariano p and the Monte-Carlo p both at most the level
        "judged_spurious_both_le_0.05": sum(r["dm_p"] <= 0.05 and r["mc_p"] <= 0.05 + 1e-12 for r in judged if r.get("mc_p") is not None),
        "dm_p_median": sorted(dm)[len(dm) // 2] if dm else None,
        "mc_p_median": sorted(r["mc_p"] for r in with_mc)[len(with_mc) // 2] if with_mc else None,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clean", default=None, help="glob of clean case names (e.g. 'clean-*-s1')")
    ap.add_argument("--effects", default=None, help="glob of concealed single-effect case names")
    ap.add_argument("--replicates", type=int, default=19)
    ap.add_argument("--more-seeds", type=int, default=0, help="clean logs of this many further seeds (3, 4, ...) beside the corpus's two")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument(
        "--mc-below",
        type=float,
        default=1.0,
        help="the Monte-Carlo null only where the Diebold-Mariano p is at most this (the rule of both can only bite there; default: everywhere)",
    )
    args = ap.parse_args(argv)
    clean = [c.name for c in CLEAN_CASES] + [f"clean-{tr}-{nz}-s{sd}" for sd in range(3, 3 + args.more_seeds) for tr in TRAJECTORY_KINDS for nz in NOISE_MODELS]
    names = [n for n in clean if args.clean and fnmatch.fnmatch(n, args.clean)]
    if args.effects:
        names += [c.name for c in EFFECT_CASES if fnmatch.fnmatch(c.name, args.effects)]
    jobs = [(n, args.replicates, args.seed, args.mc_below) for n in names]
    rows: list[dict[str, Any]] = []
    if args.jobs > 1:
        from multiprocessing import get_context

        from ilic_cli.parallel import THREADS_ENV

        os.environ[THREADS_ENV] = "1"  # one log per process: no threads within (the workers inherit it)

        with get_context("spawn").Pool(args.jobs) as pool:
            for rs in pool.imap(_job, jobs):
                rows += rs
                print(f"done {rs[0]['case'] if rs else ''}: {len(rows)} trials", file=sys.stderr, flush=True)
    else:
        for j in jobs:
            rows += _job(j)
            print(f"done {j[0]}: {len(rows)} trials", file=sys.stderr, flush=True)
    print("| case | effect | edge | force before -> after % | DM p | MC p | T_obs | T_b max |\n|---|---|---|---|---|---|---|---|")
    for r in rows:
        fb = "" if r["force_before"] is None else f"{r['force_before']:.3f} -> {r['force_after']:.3f}"
        tmax = max((t for t in r.get("t_null", []) if t == t), default=float("nan"))
        mc = r.get("mc_p")
        print(
            f"| {r['case']} | {r['effect']} | {'yes' if r['edge'] else ''} | {fb} | {r['dm_p'] if r['dm_p'] is None else format(r['dm_p'], '.3g')} | "
            f"{'' if mc is None else format(mc, '.3g')} | {r.get('t_obs', float('nan')):.3g} | {tmax:.3g} |"
        )
    s = summary(rows, args.replicates)
    print()
    print(json.dumps(s))
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "summary": s}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
