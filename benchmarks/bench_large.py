"""A 1-hour, 1 kHz log: read and write rates of every format, and ``ilic info`` / ``identify`` time and memory.

Generates the log once (3.6 M samples, about 10.8 M ROS 2 messages) and
caches it under ``out/bench/hour_1khz.mcap``; then

1. runs

       ilic info out/bench/hour_1khz.mcap --format json
       ilic identify out/bench/hour_1khz.mcap --method ls --format json
       ilic identify out/bench/hour_1khz.mcap --method both --format json

   each in its own subprocess and prints its wall time, CPU time (user +
   sys: steadier than wall on a shared machine) and peak resident set size
   (from ``os.wait4``, i.e. that child's ``ru_maxrss``), and that peak over
   the decoded columns (samples x channels x 8 bytes, from ``info``'s JSON). The goals
   are at most 8 s and 600 MB each, and a peak of at most twice the columns (issue 33);
2. writes and reads the log in every format with the fast paths
   (:mod:`bench_io`; ``--per-message`` adds the per-message paths, which
   take about half an hour on a 2-core machine).

Never asserted by tests: run it with ``make bench-large`` or
``python benchmarks/bench_large.py [--regenerate] [--per-message] [--skip-formats]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
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


def run(args: list[str]) -> tuple[float, float, float, int, str, str]:
    """Run ``python -m ilic_cli ARGS``; return wall time (s), CPU time (user + sys, s), peak RSS (MB), status, stderr tail and stdout."""
    env = dict(os.environ, CI="1")  # no progress bar in the measurement
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out:
        proc = subprocess.Popen([sys.executable, "-m", "ilic_cli", *args], stdout=out, stderr=subprocess.PIPE, cwd=ROOT, env=env)
        assert proc.stderr is not None
        err = proc.stderr.read().decode("utf-8", "replace")
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        out.seek(0)
        text = out.read().decode("utf-8", "replace")
    rss_mb = usage.ru_maxrss / 1024.0  # Linux: kilobytes
    return wall, usage.ru_utime + usage.ru_stime, rss_mb, proc.returncode, err.strip().splitlines()[-1] if err.strip() else "", text


def main(argv: list[str] | None = None) -> None:
    """Generate the log when missing, then measure ``info`` and ``identify``, then every format."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--regenerate", action="store_true", help="write the log again even when it is cached")
    parser.add_argument("--per-message", action="store_true", help="also time the per-message paths (about half an hour)")
    parser.add_argument("--skip-formats", action="store_true", help="only the ilic info / identify processes")
    parser.add_argument("--generate-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.generate_only:
        seconds = generate(CACHE)
        print(f"  written in {seconds:.1f} s ({CACHE.stat().st_size / 2**20:.0f} MiB)", flush=True)
        return
    if args.regenerate or not CACHE.exists():
        print(f"generating {CACHE.relative_to(ROOT)} ...", flush=True)
        # in a process of its own: this one would grow to the log's some 700 MB, and each command's child counts the
        # parent's pages between fork and exec in its peak (the commands' peaks read 699 MB, 3.63x, when generated here)
        subprocess.run([sys.executable, __file__, "--generate-only"], check=True)
    samples = 3_600_000
    print(f"log: {CACHE.relative_to(ROOT)} ({CACHE.stat().st_size / 2**20:.0f} MiB, {samples} samples at 1 kHz)")
    rows = []
    columns_mib = None
    for name, cmd in (
        ("info", ["info", str(CACHE), "--format", "json"]),
        ("identify --method ls --format json", ["identify", str(CACHE), "--method", "ls", "--format", "json"]),
        ("identify --method both --format json", ["identify", str(CACHE), "--method", "both", "--format", "json"]),
    ):
        wall, cpu, rss, status, last, text = run(cmd)
        if name == "info" and status == 0:
            summary = json.loads(text)
            columns_mib = summary["samples"] * len(summary["channels"]) * 8 / 2**20  # float64 columns
        rows.append((name, wall, rss, status))
        flag = "ok" if rss <= LIMIT_MB and wall <= LIMIT_S else f"OVER {LIMIT_S:.0f} s / {LIMIT_MB:.0f} MB"
        ratio = f"  {rss / columns_mib:.2f}x the columns" if columns_mib else ""  # ru_maxrss is in KiB: rss is MiB
        print(
            f"ilic {name:<38} status {status}  wall {wall:7.1f} s  cpu {cpu:7.1f} s  peak RSS {rss:7.0f} MB  [{flag}]  "
            f"{samples / wall / 1e3:.0f} k samples/s{ratio}" + (f"  ({last})" if status else ""),
            flush=True,
        )
    if columns_mib:
        print(f"decoded columns: {columns_mib:.0f} MiB (goal: each peak <= 2x)", flush=True)
    worst = max(r[2] for r in rows)
    print(f"peak RSS over the commands: {worst:.0f} MB (goal <= {LIMIT_MB:.0f} MB, each <= {LIMIT_S:.0f} s)", flush=True)
    # after the subprocesses: a child's peak RSS counts the parent's pages
    # between fork and exec, and the formats make this process large
    if not args.skip_formats:
        formats(args.per_message)


if __name__ == "__main__":
    main(sys.argv[1:])
