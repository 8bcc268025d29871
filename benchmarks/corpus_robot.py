"""The robot corpus measured with the current code (issue 29 item 8; ``make corpus``).

Every case of :func:`tests.corpus.robot.cases` (four axes from 0.01 kg·m² to 200 kg, both joint types, 250 Hz to
8 kHz, S-curve and trapezoid moves with dwells, chirps, multisines; every catalogue effect, gravity, drift and
pairs, each sized on its own log; three seeds each) is built, written to CSV or a ROS 2 bag and diagnosed through
``ilic diagnose --controller pd --kp --kv --drive-gain`` (a share), or through the library (the rest), and
``identify --method ls`` is run on the clean dwell-and-move logs (:func:`tests.corpus.measure.run_case`).

Prints the issue's rates (:func:`tests.corpus.measure.summary`), their breakdown by rate, joint, axis, trajectory,
noise model, writer and effect, and every failure with the diagnosis's reason (its JSON ``decisions``), as
Markdown. ``--check``: exit 1 when a rate of the "Done when" does not hold (:func:`tests.corpus.measure.failures`).

``--reseed K``: every case with another seed (its seed plus ``K`` times :data:`RESEED_STEP`; the same axis, rate,
trajectory, noise model, effects and target): new noise, disturbance and draws, a check that the rates do not rest on
the corpus's own seeds.

``--beyond``: the logs beyond the design instead (:func:`tests.corpus.robot.beyond_cases`: other axes from 0.002 kg·m²
to 50 kg, rates of 400 Hz, 1.5 and 4 kHz, PD loops of 6 to 15 Hz), a check that the rates do not rest on its axes,
rates and loop.

Usage: python benchmarks/corpus_robot.py [--jobs 2] [--cases GLOB] [--json FILE] [--rows FILE] [--check] [--reseed K] [--beyond]
"""

from __future__ import annotations

import argparse
import dataclasses
import fnmatch
import json
import math
import os
import sys
import time
from concurrent.futures import as_completed
from contextlib import nullcontext as _nullcontext
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.corpus.measure import BY, IDENTIFY_TOLERANCE, below_band, breakdown, failures, run_case, summary  # noqa: E402
from tests.corpus.robot import BAND_PTS, TOLERANCE, beyond_cases, cases  # noqa: E402

RESEED_STEP = 3000
"""``--reseed K`` adds ``K`` times this to every seed: a multiple of 3, so each case keeps its variant (``Case.variant``)."""


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({k / n:.0%})" if n else "-"


def _order(key: Any) -> tuple[float, str]:
    """Rates in numeric order (``250 Hz`` before ``1000 Hz``), anything else by name."""
    head = str(key).split(" ")[0]
    try:
        return float(head), ""
    except ValueError:
        return math.inf, str(key)


def table(rows: list[dict[str, Any]], by: str) -> str:
    """The rates per value of ``by``, one Markdown row each."""
    head = f"| {by} | clean logs with a false alarm | effect logs named exactly | effects named | parameters within 15 % | identify within 2 % | same rows |"
    lines = [head, "|---|---|---|---|---|---|---|"]
    for key, s in sorted(breakdown(rows, by).items(), key=lambda kv: _order(kv[0])):
        lines.append(
            f"| {key} | {_pct(s['clean_with_false_alarm'], s['clean'])} | {_pct(s['named_exactly'], s['effect_logs'])} | "
            f"{_pct(s['effects_named'], s['effects_total'])} | {_pct(s['parameters_within'], s['parameters_compared'])} | "
            f"{_pct(s['identify_within'], s['identify_logs'])} | {_pct(s['identify_same_rows'], s['identify_logs'])} |"
        )
    return "\n".join(lines)


def _fmt(p: dict[str, float] | None) -> str:
    return "" if not p else "(" + ", ".join(f"{k}={v:.3g}" for k, v in p.items()) + ")"


STATED = {True: "within what the diagnosis states", False: "beyond what the diagnosis states", None: ""}
"""A failure's last column for a parameter beyond the tolerance, by :func:`tests.corpus.robot.within_stated`'s verdict."""


def failure_list(rows: list[dict[str, Any]]) -> str:
    """Each failing log: what went wrong and the diagnosis's reason."""
    lines = ["| case | size (pts) | failure | reason |", "|---|---|---|---|"]
    for r in rows:
        if r.get("refused"):
            lines.append(f"| {r['case']} | {r['size_pts']} | refused | {r['refused']} |")
            continue
        if below_band(r):
            said = ", ".join(f["effect"] for f in r["findings"]) or "no finding"
            lines.append(f"| {r['case']} | {r['size_pts']} | below the band, in no rate: {'+'.join(r['effects'])} | {said} |")
            continue
        for f, v in zip(r["findings"], r["verdicts"], strict=True):
            if v == "false alarm":
                reason = r["false_alarm_reasons"].get(f["effect"], "")
                lines.append(f"| {r['case']} | {r['size_pts']} | false alarm: {f['effect']}{_fmt(f['plant'])} | {reason} |")
        for eid in r["missed"]:
            lines.append(f"| {r['case']} | {r['size_pts']} | missed: {eid}{_fmt(r['truth'][eid])} | {r['missed_reasons'].get(eid, '')} |")
        for eid, err in r["parameter_error"].items():
            if not err <= TOLERANCE:
                got = next((f["plant"] for f in r["findings"] if f["effect"] == eid), None)
                lines.append(
                    f"| {r['case']} | {r['size_pts']} | {eid} off by {err:.0%}: {_fmt(got)}, truth {_fmt(r['truth'][eid])} | "
                    f"{STATED[r.get('parameter_stated', {}).get(eid)]} |"
                )
        ident = r["identify"]
        if ident is not None and not all(abs(e) <= IDENTIFY_TOLERANCE for e in ident["error"].values()):
            zs = ident.get("z", {})
            lines.append(f"| {r['case']} | | identify: {', '.join(f'{k} {e:+.1%} ({zs.get(k, math.nan):+.1f} σ)' for k, e in ident['error'].items())} | |")
        if ident is not None and not ident["same_rows"]:
            lines.append(f"| {r['case']} | | identify fits {ident['rows']} rows, diagnose {r['diagnose_rows']} | |")
    return "\n".join(lines)


def report(rows: list[dict[str, Any]], wall_s: float, jobs: int) -> str:
    s = summary(rows)
    cpu = sum(r["cpu_s"] for r in rows)
    out = [
        f"{len(rows)} logs ({s['clean']} clean, {s['effect_logs']} with effects, {s['below_band']} whose effects change the rigid fit by less "
        f"than the band's {BAND_PTS[0]} points: in no rate); {wall_s:.0f} s wall on {jobs} worker(s); "
        f"{cpu:.0f} s of CPU summed over the logs",
        "",
        f"- clean logs with a finding other than `offset` (or a current loop's lag): {_pct(s['clean_with_false_alarm'], s['clean'])}",
        f"- effect logs named exactly: {_pct(s['named_exactly'], s['effect_logs'])}; effects named {_pct(s['effects_named'], s['effects_total'])}",
        f"- parameters of the effects named within 15 %: {_pct(s['parameters_within'], s['parameters_compared'])}; of the others, "
        f"within what the diagnosis states of them (1.96 stated σ, or stated undetermined): "
        f"{_pct(s['parameters_beyond_within_stated'], s['parameters_beyond_judged'])}",
        f"- concealed effects stated as indistinct from another (`a or b`: the data cannot tell them apart; not named exactly): "
        f"{s['effects_stated_indistinct']}",
        f"- `identify --method ls` within 2 % of M, Fv, Fc on clean dwell-and-move logs: {_pct(s['identify_within'], s['identify_logs'])}; "
        f"the same rows as `diagnose`: {_pct(s['identify_same_rows'], s['identify_logs'])}; the truth within its stated 95 % robust interval "
        f"(1.96 robust σ): {_pct(s['identify_in_interval'], s['identify_interval_compared'])} of M, Fv, Fc",
        f"- logs refused (`ilic: error:`, exit 2): {s['refused']}",
    ]
    for by in BY:
        out += ["", table(rows, by)]
    out += ["", "Failures:", "", failure_list(rows)]
    return "\n".join(out)


def _pool(jobs: int) -> Any:
    """``jobs`` spawned worker processes, one thread each (a log per process), or none for one job.

    A process pool that fails loudly: a worker killed from outside breaks the pool (``BrokenProcessPool``) instead of
    leaving its case waiting forever; ``--rows`` keeps what was done.
    """
    if jobs <= 1:
        return None
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from ilic_cli.parallel import THREADS_ENV

    os.environ[THREADS_ENV] = "1"  # the workers inherit it
    return ProcessPoolExecutor(jobs, mp_context=get_context("spawn"))


def _kept(path: Path | None) -> dict[str, dict[str, Any]]:
    """The rows of ``--rows FILE`` (one JSON object a line), by case name."""
    if path is None or not path.is_file():
        return {}
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return {r["case"]: r for r in rows}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--cases", default="*", help="glob of case names (default all)")
    ap.add_argument("--json", type=Path, default=None, help="also write every row and the summary as JSON")
    ap.add_argument("--check", action="store_true", help="exit 1 when a rate of issue 29's 'Done when' does not hold")
    ap.add_argument("--rows", type=Path, default=None, help="keep each row in FILE as it is done, and reuse the rows already there")
    ap.add_argument("--beyond", action="store_true", help="the logs beyond the design (other axes, rates and loops) instead")
    ap.add_argument("--reseed", type=int, default=0, metavar="K", help="every case with its seed plus K x %d (default 0: the corpus's own)" % RESEED_STEP)
    args = ap.parse_args(argv)
    chosen = [c for c in (beyond_cases() if args.beyond else cases()) if fnmatch.fnmatch(c.name, args.cases)]
    if args.reseed:
        chosen = [dataclasses.replace(c, seed=c.seed + args.reseed * RESEED_STEP) for c in chosen]
    if not chosen:
        print(f"no case matches {args.cases!r}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    done = _kept(args.rows)
    order = sorted((c for c in chosen if c.name not in done), key=lambda c: -c.fs_hz)  # the 8 kHz logs first: the workers end together
    pool = _pool(args.jobs)
    with pool if pool is not None else _nullcontext():
        results = map(run_case, order) if pool is None else (f.result() for f in as_completed([pool.submit(run_case, c) for c in order]))
        for row in results:
            done[row["case"]] = row
            if args.rows is not None:
                with args.rows.open("a", encoding="utf-8") as fh:
                    fh.write(json.dumps(row, default=str) + "\n")
            print(f"[{len(done)}/{len(chosen)}] {row['case']}: {'exact' if row['exact'] else 'NOT exact'}", file=sys.stderr, flush=True)
    rows = [done[c.name] for c in chosen]
    wall = time.perf_counter() - t0
    print(report(rows, wall, args.jobs))
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "summary": summary(rows), "wall_s": wall}, indent=1, default=str))
    missing = failures(summary(rows))
    for line in missing:
        print(f"corpus: not met: {line}", file=sys.stderr)
    return 1 if args.check and missing else 0


if __name__ == "__main__":
    sys.exit(main())
