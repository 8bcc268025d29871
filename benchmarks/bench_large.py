"""A 1-hour, 1 kHz log: read and write rates of every format, and ``ilic info`` / ``identify`` time and memory.

Generates the log once (3.6 M samples, about 10.8 M ROS 2 messages) and
caches it under ``out/bench/hour_1khz.mcap``; then

1. runs

       ilic info out/bench/hour_1khz.mcap
       ilic identify out/bench/hour_1khz.mcap --method both --format json

   each in its own subprocess and prints its wall time, CPU time (user +
   sys: steadier than wall on a shared machine) and peak resident set size
   (from ``os.wait4``, i.e. that child's ``ru_maxrss``). The goal
   is at most 8 s and 600 MB each;
2. writes and reads the log in every format with the fast paths
   (:mod:`bench_io`; ``--per-message`` adds the per-message paths, which
   take about half an hour on a 2-core machine).

Never asserted by tests: run it with ``make bench-large`` or
``python benchmarks/bench_large.py [--regenerate] [--per-message] [--skip-formats]``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "out" / "bench" / "hour_1khz.mcap"
LIMIT_MB = 600.0
LIMIT_S = 8.0


def generate(path: Path, fs: float = 1000.0, hours: float = 1.0) -> float:
    """Write the 1-hour log to ``path`` with ilic's own MCAP writer; return the seconds it took."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.bench_identify import synthetic_hour
    from ilic_cli.io import write_log
    from ilic_cli.runlog import RunLog

    d = synthetic_hour(fs, hours)
    gain = 35.15065188248547
    log = RunLog(
        {**d, "vir": d["tau"] / gain},
        meta={"sample_rate_hz": fs, "drive_gain": gain, "scenario": {"name": "bench-large", "hours": hours}},
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    write_log(log, path)
    return time.perf_counter() - t0


def formats(per_message: bool) -> None:
    """Every format's write and read rates on the cached log (fast paths; per-message ones on request)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_io import bench

    from ilic_cli.io import read_log

    log = read_log(CACHE)
    print(f"formats, {len(log)} samples: fast path" + (" vs per-message path" if per_message else " (--per-message for the per-message paths)"), flush=True)
    bench(log, repeat=1, per_message=per_message)


def run(args: list[str]) -> tuple[float, float, float, int, str]:
    """Run ``python -m ilic_cli ARGS``; return wall time (s), CPU time (user + sys, s), peak RSS (MB), status and stderr tail."""
    env = dict(os.environ, CI="1")  # no progress bar in the measurement
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "ilic_cli", *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT, env=env)
    assert proc.stderr is not None
    err = proc.stderr.read().decode("utf-8", "replace")
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t0
    rss_mb = usage.ru_maxrss / 1024.0  # Linux: kilobytes
    return wall, usage.ru_utime + usage.ru_stime, rss_mb, proc.returncode, err.strip().splitlines()[-1] if err.strip() else ""


def main() -> None:
    """Generate the log when missing, then measure ``info`` and ``identify``, then every format."""
    if "--regenerate" in sys.argv or not CACHE.exists():
        print(f"generating {CACHE.relative_to(ROOT)} ...", flush=True)
        seconds = generate(CACHE)
        print(f"  written in {seconds:.1f} s ({CACHE.stat().st_size / 2**20:.0f} MiB)", flush=True)
    samples = 3_600_000
    print(f"log: {CACHE.relative_to(ROOT)} ({CACHE.stat().st_size / 2**20:.0f} MiB, {samples} samples at 1 kHz)")
    rows = []
    for name, args in (
        ("info", ["info", str(CACHE)]),
        ("identify --method both --format json", ["identify", str(CACHE), "--method", "both", "--format", "json"]),
    ):
        wall, cpu, rss, status, last = run(args)
        rows.append((name, wall, rss, status))
        flag = "ok" if rss <= LIMIT_MB and wall <= LIMIT_S else f"OVER {LIMIT_S:.0f} s / {LIMIT_MB:.0f} MB"
        print(
            f"ilic {name:<38} status {status}  wall {wall:7.1f} s  cpu {cpu:7.1f} s  peak RSS {rss:7.0f} MB  [{flag}]  {samples / wall / 1e3:.0f} k samples/s"
            + (f"  ({last})" if status else ""),
            flush=True,
        )
    worst = max(r[2] for r in rows)
    print(f"peak RSS over both commands: {worst:.0f} MB (goal <= {LIMIT_MB:.0f} MB, each <= {LIMIT_S:.0f} s)", flush=True)
    # after the subprocesses: a child's peak RSS counts the parent's pages
    # between fork and exec, and the formats make this process large
    if "--skip-formats" not in sys.argv:
        formats("--per-message" in sys.argv)


if __name__ == "__main__":
    main()
