"""``ilic identify DATA_EMPS.mat --method oe`` as a user runs it, process start included: medians of several runs.

The output-error fit of issue 31 (budget: 10 s end to end), beside ``--method ls`` (its IDIM-LS start, the
process start-up and the reading of the file) run in turn with it, so the difference is the fit's own cost.
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
EMPS = ROOT.parent / "shared" / "emps"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    repeat = parser.parse_args().repeat
    if not (EMPS / "DATA_EMPS.mat").is_file():
        print("  ../shared/emps absent: nothing to time")
        return
    ilic = [sys.executable, "-m", "ilic_cli", "identify", str(EMPS / "DATA_EMPS.mat")]
    pulses = str(EMPS / "DATA_EMPS_PULSES.mat")
    jobs = [
        ("--method ls", [*ilic, "--method", "ls"]),
        ("--method oe", [*ilic, "--method", "oe"]),
        ("--method oe --oe-state protocol --validate PULSES", [*ilic, "--method", "oe", "--oe-state", "protocol", "--validate", pulses]),
        ("--method cloe", [*ilic, "--method", "cloe"]),
    ]
    times: dict[str, list[float]] = {label: [] for label, _ in jobs}
    for i in range(repeat + 1):  # in turn, so that a drift of the machine's speed touches every job alike; the first round warms up
        for label, args in jobs:
            t0 = time.perf_counter()
            subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
            if i:
                times[label].append(time.perf_counter() - t0)
    for label, ts in times.items():
        print(f"  identify DATA_EMPS.mat {label:50s} median {statistics.median(ts):6.3f} s   (min {min(ts):.3f}, max {max(ts):.3f}, {repeat} runs)")


if __name__ == "__main__":
    main()
