"""Read and write rates of every log format: the fast (vectorised) path beside the per-message path.

Simulates a ``paper-sim`` log (120 s at 1 kHz, 120k samples; ``--samples N``
for another length, cut from a longer simulation when needed), writes it in
every format -- ``.mat``, CSV, MCAP, ROS 1 ``.bag``, ROS 2 bag with sqlite3
and with MCAP storage -- with ``WriteOptions(fast=True)`` and
``fast=False``, and reads each file with ``read_log(..., fast=True)`` and
``fast=False``, in one process, one format after the other. Prints samples
per second for each path and their ratio, and the fast paths' rates in
process CPU time (steadier than wall time on a shared machine); ``n/a`` where a format has no
per-message path (``.mat``) or does not take the keyword yet (a
``TypeError``). Every read is checked to give the written columns.

Then times ``ilic info`` on a 600 s log (600k samples) in every format as a
whole process (start-up included), each paired against ``ilic info`` on the
MCAP file (issue 33: at least 500k samples/s everywhere), and
``ilic simulate --scenario paper-sim --duration 300`` to ``.mat``, ``.mcap``,
CSV, ``.bag`` and ROS 2 bags (``--format rosbag2``, ``--storage sqlite3`` and
``mcap``), each paired against a process that imports and simulates the same
and writes nothing; prints each as a multiple of real time, with the process's
CPU time (user + system).

Never asserted by tests: run it with ``make bench`` (or
``python benchmarks/bench_io.py [--samples N] [--repeat R] [--fast-only] [--no-simulate]``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

# name, file or folder name, write options (besides fast)
FORMATS: list[tuple[str, str, dict[str, Any]]] = [
    ("mat", "log.mat", {}),
    ("csv", "log.csv", {}),
    ("mcap", "log.mcap", {}),
    ("rosbag1", "log.bag", {}),
    ("rosbag2-sqlite3", "bag_sqlite3", {"storage": "sqlite3"}),
    ("rosbag2-mcap", "bag_mcap", {"storage": "mcap"}),
]
NO_PER_MESSAGE = {"mat"}
"""Formats read and written whole, without a per-message path to compare with."""


def paper_sim(samples: int) -> Any:
    """A ``paper-sim`` log of ``samples`` samples at 1 kHz (deterministic, seed 1)."""
    sys.path.insert(0, str(ROOT))
    from ilic_cli.runlog import RunLog
    from ilic_cli.simulation.scenarios import Overrides, run_scenario

    log = run_scenario("paper-sim", Overrides(duration_s=max(samples / 1000.0, 31.0), seed=1))
    if len(log) > samples:
        log = RunLog({k: v[:samples] for k, v in log.channels.items()}, dict(log.units), dict(log.meta))
    return log


CPU_TIMES: list[float | None] = []
"""The best process CPU time of each :func:`timed` call, in order."""


def timed(run: Callable[[], Any], repeat: int) -> tuple[float | None, Any]:
    """Best wall time of ``repeat`` runs and the last result; None when the format module has no ``fast`` keyword yet.

    The best CPU time of the runs is appended to :data:`CPU_TIMES`.
    """
    best = None
    cpu = None
    result = None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            result = run()
        except TypeError as exc:
            if "fast" not in str(exc):  # only a module without the keyword is "n/a"
                raise
            CPU_TIMES.append(None)
            return None, None
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        best = dt if best is None else min(best, dt)
        cpu = dc if cpu is None else min(cpu, dc)
    CPU_TIMES.append(cpu)
    return best, result


def remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()


def same_columns(a: Any, b: Any) -> bool:
    return list(a.channels) == list(b.channels) and all(np.array_equal(a.channels[k].view(np.uint64), b.channels[k].view(np.uint64)) for k in a.channels)


def rate(samples: int, seconds: float | None) -> str:
    return "n/a" if seconds is None else f"{samples / seconds / 1e3:9.0f}k"


def ratio(fast: float | None, slow: float | None) -> str:
    return "n/a" if fast is None or slow is None else f"{slow / fast:6.1f}x"


def bench(log: Any, repeat: int = 3, per_message: bool = True, formats: list[str] | None = None) -> list[dict[str, Any]]:
    """Write and read ``log`` in every format; return one row of timings per format."""
    from ilic_cli.io import WriteOptions, read_log, write_log

    n = len(log)
    rows = []
    work = Path(tempfile.mkdtemp(prefix="ilic-bench-io-"))
    try:
        for name, file_name, extra in FORMATS:
            if formats and name not in formats:
                continue
            path = work / file_name
            row: dict[str, Any] = {"format": name}

            def write(fast: bool, path: Path = path, extra: dict[str, Any] = extra) -> Path:
                remove(path)
                return write_log(log, path, options=WriteOptions(fast=fast, **extra))

            row["write_fast"], _ = timed(lambda: write(True), repeat)
            row["write_cpu"] = CPU_TIMES[-1]
            row["size_mb"] = sum(p.stat().st_size for p in (path.iterdir() if path.is_dir() else [path])) / 2**20
            row["read_fast"], back = timed(lambda: read_log(path, fast=True), repeat)
            row["read_cpu"] = CPU_TIMES[-1]
            row["exact"] = same_columns(back, log) if name != "mat" else None
            row["write_slow"] = row["read_slow"] = None
            if per_message and name not in NO_PER_MESSAGE:
                row["read_slow"], slow = timed(lambda: read_log(path, fast=False), 1)
                if slow is not None and not same_columns(slow, back):
                    row["exact"] = False
                if row["read_slow"] is not None:  # a module without the keyword ignores WriteOptions.fast too
                    row["write_slow"], _ = timed(lambda: write(False), 1)
            remove(path)
            rows.append(row)
            print(
                f"{name:<16} write {rate(n, row['write_fast'])} vs {rate(n, row['write_slow'])} per message ({ratio(row['write_fast'], row['write_slow'])})"
                f"   read {rate(n, row['read_fast'])} vs {rate(n, row['read_slow'])} per message ({ratio(row['read_fast'], row['read_slow'])})"
                f"   {row['size_mb']:6.1f} MiB   CPU: write {rate(n, row['write_cpu'])} read {rate(n, row['read_cpu'])}"
                + ("" if row["exact"] is not False else "   COLUMNS DIFFER"),
                flush=True,
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


SIMULATE_OUTPUTS: list[tuple[str, list[str]]] = [
    ("x.mat", []),
    ("x.mcap", []),
    ("x.csv", []),
    ("x.bag", []),
    ("x_bag", ["--format", "rosbag2", "--storage", "sqlite3"]),
    ("m_bag", ["--format", "rosbag2", "--storage", "mcap"]),
]
"""``ilic simulate`` outputs timed: .mat, MCAP, CSV, ROS 1 bag, ROS 2 bags with sqlite3 and MCAP storage."""

SIMULATION_ONLY = (
    "import os, sys; sys.argv = ['ilic', 'simulate']; from ilic_cli.commands import simulate; "
    "from ilic_cli.simulation.scenarios import Overrides, run_scenario; run_scenario('paper-sim', Overrides(duration_s={duration}, seed=0)); "
    "os._exit(0)"
)
"""The baseline of ``ilic simulate``: the same imports and simulation in a process that writes nothing, and ends as ``ilic`` does
(without the interpreter's teardown, :func:`ilic_cli.cli.run`)."""


def simulate_rates(duration_s: float = 300.0, runs: int = 3) -> None:
    """``ilic simulate`` to each output as a whole process, as a multiple of real time, paired against the simulation alone."""
    import statistics

    from benchmarks.bench_commands import paired

    work = Path(tempfile.mkdtemp(prefix="ilic-bench-sim-"))
    env = dict(os.environ, CI="1")  # no progress display
    base = [sys.executable, "-c", SIMULATION_ONLY.format(duration=duration_s)]
    try:
        for out, extra in SIMULATE_OUTPUTS:
            args = [sys.executable, "-m", "ilic_cli", "simulate", "--scenario", "paper-sim", "--duration", f"{duration_s:g}", "-o", str(work / out), *extra]
            res = paired(args, base, runs, env)
            wall = statistics.median(res["a"])
            label = f"{out} {' '.join(extra)}".strip()
            print(
                f"ilic simulate --duration {duration_s:g} -o {label:<40} {wall:6.2f} s wall = {duration_s / wall:6.1f}x real time "
                f"({statistics.median(res['a_cpu']):5.2f} s CPU); {statistics.median(res['ratio']):4.2f}x the simulation alone "
                f"({statistics.median(res['b']):5.2f} s = {duration_s / statistics.median(res['b']):6.1f}x real time)",
                flush=True,
            )
            remove(work / out)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def simulate_stages(duration_s: float = 300.0) -> None:
    """Where ``ilic simulate`` spends its CPU time, stage by stage, in one process: imports, the compiled loop's load, the loop, each writer."""
    import subprocess as sp

    code = f"""
import time
c0 = time.process_time()
from ilic_cli.commands import simulate
from ilic_cli.io import WriteOptions, write_log
from ilic_cli.simulation.scenarios import Overrides, run_scenario
c1 = time.process_time()
run_scenario('paper-sim', Overrides(duration_s=1.0, seed=0))
c2 = time.process_time()
log = run_scenario('paper-sim', Overrides(duration_s={duration_s}, seed=0))
c3 = time.process_time()
print(f'  stages (CPU s): imports {{c1 - c0:.2f}}, compiled loop load {{c2 - c1:.2f}}, {duration_s:g} s loop and log {{c3 - c2:.2f}}; writing:', end='')
import pathlib, tempfile
work = pathlib.Path(tempfile.mkdtemp())
for name, fmt, extra in [('x.mat', None, {{}}), ('x.mcap', None, {{}}), ('x.csv', None, {{}}), ('x.bag', None, {{}}),
                         ('q', 'rosbag2', {{'storage': 'sqlite3'}}), ('m', 'rosbag2', {{'storage': 'mcap'}})]:
    a, w = time.process_time(), time.perf_counter()
    write_log(log, work / name, fmt, WriteOptions(**extra))
    print(f' {{name}} {{time.process_time() - a:.2f}} ({{time.perf_counter() - w:.2f}} wall)', end='')
print()
import shutil
shutil.rmtree(work)
"""
    sp.run([sys.executable, "-c", code], cwd=ROOT, env=dict(os.environ, CI="1"), check=False)


INFO_FILES: list[tuple[str, str, dict[str, Any]]] = [
    ("mcap", "log.mcap", {}),
    ("mat", "log.mat", {}),
    ("csv", "log.csv", {}),
    ("rosbag1", "log.bag", {}),
    ("rosbag2-sqlite3", "bag_sqlite3", {"storage": "sqlite3"}),
    ("rosbag2-mcap", "bag_mcap", {"storage": "mcap"}),
]
"""``ilic info`` on the same log in each format; MCAP first (the yardstick)."""


def info_rates(log: Any, runs: int = 3) -> None:
    """``ilic info`` on ``log`` in every format as a whole process: samples per second, paired against ``ilic info`` on its MCAP file."""
    import statistics

    from benchmarks.bench_commands import paired
    from ilic_cli.io import WriteOptions, write_log

    work = Path(tempfile.mkdtemp(prefix="ilic-bench-info-"))
    env = dict(os.environ, CI="1")
    ilic = [sys.executable, "-m", "ilic_cli", "info"]
    try:
        paths = {name: write_log(log, work / file_name, options=WriteOptions(**extra)) for name, file_name, extra in INFO_FILES}
        yardstick = [*ilic, str(paths["mcap"])]
        for name, path in paths.items():
            res = paired([*ilic, str(path)], yardstick, runs, env)
            wall = statistics.median(res["a"])
            print(
                f"ilic info {name:<16} {len(log)} samples: {wall:5.2f} s wall = {len(log) / wall / 1e3:5.0f}k samples/s "
                f"({statistics.median(res['a_cpu']):5.2f} s CPU = {len(log) / statistics.median(res['a_cpu']) / 1e3:5.0f}k samples/CPU-s); "
                f"{statistics.median(res['ratio']):4.2f}x ilic info on the MCAP file ({statistics.median(res['b']):5.2f} s)",
                flush=True,
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)


def main(argv: list[str] | None = None) -> None:
    """Simulate the log, then measure every format."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=120_000)
    parser.add_argument("--repeat", type=int, default=3, help="runs of each fast path (best is shown); per-message paths run once")
    parser.add_argument("--fast-only", action="store_true", help="skip the per-message paths")
    parser.add_argument("--format", action="append", help="only this format (repeatable)")
    parser.add_argument("--no-simulate", action="store_true", help="skip the ilic simulate timings")
    parser.add_argument("--info-seconds", type=float, default=600.0, help="length of the log of the ilic info timings (0: skip them)")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from benchmarks.bench_commands import bytecode

    bytecode()  # the processes timed below start from bytecode, as an installed package does
    t0 = time.perf_counter()
    log = paper_sim(args.samples)
    print(f"paper-sim log: {len(log)} samples ({len(log) / 1000:.0f} s at 1 kHz), simulated in {time.perf_counter() - t0:.1f} s")
    print("rates in samples/s, fast path vs per-message path (ratio = per-message time / fast time); best of", args.repeat, "fast runs")
    bench(log, repeat=args.repeat, per_message=not args.fast_only, formats=args.format)
    if args.info_seconds > 0:
        info_rates(paper_sim(int(args.info_seconds * 1000)))
    if not args.no_simulate:
        simulate_rates()
        simulate_stages()


if __name__ == "__main__":
    main(sys.argv[1:])
