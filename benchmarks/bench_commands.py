"""Whole commands as a user runs them, process start included: medians of several runs.

``ilic --help``, ``ilic identify DATA_EMPS.mat --method ls`` (the small job of
the start-up budget) and ``ilic diagnose DATA_EMPS.mat`` (replays included),
each run ``--repeat`` times after one warm-up; prints the median and the range.
Never asserted by tests: run it with ``make bench``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EMPS = ROOT.parent / "shared" / "emps" / "DATA_EMPS.mat"


def timed(args: list[str], repeat: int) -> list[float]:
    """Wall times (s) of ``repeat`` runs of ``args`` after one warm-up run."""
    out = []
    for i in range(repeat + 1):
        t0 = time.perf_counter()
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
        if i:
            out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    repeat = parser.parse_args().repeat
    ilic = [sys.executable, "-m", "ilic_cli"]
    jobs = [("ilic --help", [*ilic, "--help"])]
    if EMPS.is_file():
        jobs += [
            ("ilic identify DATA_EMPS.mat --method ls", [*ilic, "identify", str(EMPS), "--method", "ls"]),
            ("ilic diagnose DATA_EMPS.mat", [*ilic, "diagnose", str(EMPS)]),
        ]
    else:
        print("  ../shared/emps absent: the DATA_EMPS.mat jobs are skipped")
    for label, args in jobs:
        times = timed(args, repeat)
        print(f"  {label:42s} median {statistics.median(times):6.3f} s   (min {min(times):.3f}, max {max(times):.3f}, {repeat} runs)")


if __name__ == "__main__":
    main()
