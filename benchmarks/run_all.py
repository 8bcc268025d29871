"""Run the speed benchmarks beside this file (``make bench``); print their figures.

Each script runs in its own interpreter: one benchmark's heap (the 1-hour
arrays of ``bench_identify.py``) must not slow the next (it cost the sqlite3
read about 20 % when they shared a process).

``bench_robot.py`` prints issue 30's two limits beside its figures: the
6-joint 10-minute identification (<= 5 s) and the CTC with online ILIC
(>= 100x real time).

``bench_large.py`` (a 1-hour MCAP log: minutes to generate and read) runs only
with ``--large`` (``make bench-large``).

Last, the limit of issue 29's "Done when": ``ilic diagnose DATA_EMPS.mat`` (the
whole process, replays included) in at most :data:`DIAGNOSE_LIMIT_S`, its
median over :data:`DIAGNOSE_RUNS` runs printed beside the limit.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EMPS = ROOT.parent / "shared" / "emps" / "DATA_EMPS.mat"
DIAGNOSE_LIMIT_S = 5.0
"""Issue 29: ``ilic diagnose DATA_EMPS.mat`` <= 5 s in ``make bench``."""
DIAGNOSE_RUNS = 3


def diagnose_limit() -> str:
    """One line: the median wall time of ``ilic diagnose DATA_EMPS.mat`` (whole process, after a warm-up run) against the limit."""
    if not EMPS.is_file():
        return "  ../shared/emps absent: ilic diagnose DATA_EMPS.mat not timed"
    args = [sys.executable, "-m", "ilic_cli", "diagnose", str(EMPS)]
    walls = []
    for i in range(DIAGNOSE_RUNS + 1):
        t0 = time.perf_counter()
        subprocess.run(args, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        if i:
            walls.append(time.perf_counter() - t0)
    med = statistics.median(walls)
    verdict = "within" if med <= DIAGNOSE_LIMIT_S else "OVER"
    spread = f"{min(walls):.2f}-{max(walls):.2f}"
    return f"  ilic diagnose DATA_EMPS.mat: {med:.2f} s median of {len(walls)} runs ({spread}); limit {DIAGNOSE_LIMIT_S:g} s: {verdict}"


def main() -> None:
    here = Path(__file__).parent
    large = "--large" in sys.argv[1:]
    for script in sorted(here.glob("bench_*.py")):
        if (script.name == "bench_large.py") != large:
            continue
        print(f"== {script.name}", flush=True)
        subprocess.run([sys.executable, str(script)], check=True)
        print(flush=True)
    if not large:
        print("== issue 29: ilic diagnose DATA_EMPS.mat <= 5 s", flush=True)
        print(diagnose_limit(), flush=True)


if __name__ == "__main__":
    main()
