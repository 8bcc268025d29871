"""``ilic batch`` as a user runs it, process start included: 2 workers against 1, and the per-log overhead.

- **2 workers vs 1**: ``ilic batch FLEET --diagnose`` with ``--jobs 2`` against
  ``--jobs 1`` on a simulated fleet (:mod:`ilic_cli.fleet.generate`, 8 s logs;
  the diagnosis is the work that outgrows one machine), run in turn (A B A B)
  and the ratio taken pair by pair; each run into an empty folder (no resume),
  one replay thread a worker (``ILIC_THREADS=1``; a batch's workers set it).
  Target >= 1.8x on 2 cores. Beside it, a control: a trivially parallel loop
  in 2 processes against 1, what this machine lets 2 workers gain right now.
- **Per-log overhead**: ``ilic batch`` of N short logs (``--method ls``, one
  process) against N times the identify core in this process
  (:func:`ilic_cli.identify.identify` on the logs already read):
  ``(batch - N x core) / N``, which carries the interpreter's start, the
  imports, reading and hashing each log, its JSON document and the table.
  Target <= 50 ms.

Never asserted by tests: run it with ``make bench``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(args: list[str]) -> float:
    """Wall time (s) of one whole process (one replay thread a worker: ``ILIC_THREADS=1``, as the batch's workers have)."""
    t0 = time.perf_counter()
    env = {**os.environ, "ILIC_THREADS": "1"}
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=env)
    return time.perf_counter() - t0


def spin(n: int) -> float:
    """A trivially parallel task: ``n`` steps of a Python loop."""
    x = 0
    for i in range(n):
        x += i * i
    return float(x)


def control(workers: int) -> float:
    """Wall time (s) of 8 spins on ``workers`` processes: what 2 workers can gain on this machine now, whatever the batch."""
    from concurrent.futures import ProcessPoolExecutor

    t0 = time.perf_counter()
    with ProcessPoolExecutor(workers) as ex:
        list(ex.map(spin, [3_000_000] * 8))
    return time.perf_counter() - t0


def batch(fleet: Path, out: Path, *extra: str) -> list[str]:
    shutil.rmtree(out, ignore_errors=True)
    return [sys.executable, "-m", "ilic_cli", "batch", str(fleet), "--out", str(out), *extra]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument(
        "--diagnosed", type=int, default=96, help="Logs of the 2-vs-1 batch (the workers' start amortised as in a real batch: 96 logs, 1.87x; 48, 1.78x)."
    )
    parser.add_argument("--short", type=int, default=200, help="Logs of the overhead batch.")
    a = parser.parse_args()
    from ilic_cli.fleet.generate import write_fleet
    from ilic_cli.identify import identify
    from ilic_cli.io import read_log

    with tempfile.TemporaryDirectory(prefix="ilic-bench-fleet-") as tmp:
        tmpdir = Path(tmp)
        big, small = tmpdir / "diagnosed", tmpdir / "short"
        t0 = time.perf_counter()
        write_fleet(big, machines=2, days=a.diagnosed // 2, seed=11)
        t1 = time.perf_counter()
        write_fleet(small, machines=10, days=a.short // 10, seed=12, duration_s=2.0)
        t2 = time.perf_counter()
        print(f"  generate: {a.diagnosed} logs of 8 s in {t1 - t0:.2f} s; {a.short} logs of 2 s in {t2 - t1:.2f} s ({1000 * (t2 - t1) / a.short:.1f} ms a log)")

        out = tmpdir / "out"
        run(batch(big, out, "--diagnose", "--jobs", "1"))  # warm-up: numba's cache, the file cache
        one, two = [], []
        for _ in range(a.repeat):
            one.append(run(batch(big, out, "--diagnose", "--jobs", "1")))
            two.append(run(batch(big, out, "--diagnose", "--jobs", "2")))
        ratios = [x / y for x, y in zip(one, two)]
        spins = [control(1) / control(2) for _ in range(a.repeat)]
        print(f"  control, a trivially parallel Python loop in 2 processes vs 1: {statistics.median(spins):.2f}x (a loaded machine gives less than 2x)")
        print(
            f"  batch --diagnose, {a.diagnosed} logs: 1 worker median {statistics.median(one):.2f} s, 2 workers {statistics.median(two):.2f} s; "
            f"2 workers vs 1: {statistics.median(ratios):.2f}x (min {min(ratios):.2f}, max {max(ratios):.2f}; target >= 1.8x)"
        )

        logs = [read_log(p) for p in sorted(small.rglob("*.mcap"))]
        identify(logs[0], method="ls")
        cores = []
        for _ in range(a.repeat):
            c0 = time.perf_counter()
            for log in logs:
                identify(log, method="ls")
            cores.append(time.perf_counter() - c0)
        run(batch(small, out, "--method", "ls", "--jobs", "1"))
        batches = [run(batch(small, out, "--method", "ls", "--jobs", "1")) for _ in range(a.repeat)]
        core, whole = statistics.median(cores), statistics.median(batches)
        print(
            f"  batch --method ls, {len(logs)} logs of 2 s in one process: {whole:.2f} s; identify core in-process {1000 * core / len(logs):.1f} ms a log; "
            f"overhead {1000 * (whole - core) / len(logs):.1f} ms a log (target <= 50 ms)"
        )


if __name__ == "__main__":
    main()
