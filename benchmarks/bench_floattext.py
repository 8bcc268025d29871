"""The CSV writer's formatter (issue 33): compiled shortest float text against Python's ``repr``, and a sweep of its bytes.

Times, in process CPU time (steadier than wall time on a shared machine):

* ns per value of :func:`ilic_cli.io.floattext.texts`' kernel and of
  ``repr`` (``repr(list)`` and ``map(repr)``) on 1M standard normals;
* the compiled formatter's first call in a fresh process (numba's cache load);
* ``ilic simulate``'s stages in a fresh process (``bench_io.simulate_stages``):
  imports, the loop's load, the loop, each writer's (CSV's among them);
* the stages of writing a ``paper-sim`` log of ``--duration`` seconds to CSV:
  the compiled rows (:func:`ilic_cli.io.floattext.csv_rows`) and the whole
  ``csvlog.write`` against ``repr`` of the same values.

``--sweep N`` also compares ``N`` random bit patterns and ``N`` values of
several kinds with ``repr``, byte for byte (larger than the tests' sweeps),
and prints the mismatches (none expected).

Never asserted by tests: ``python benchmarks/bench_floattext.py [--duration S] [--sweep N]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FIRST_CALL = """
import time
import numpy as np
import numba
t0 = time.process_time()
from ilic_cli.io.floattext import csv_rows
t1 = time.process_time()
csv_rows([np.arange(4.0)], 0, 4)
t2 = time.process_time()
print(f"{t1 - t0:.4f} {t2 - t1:.4f}")
"""


def cpu(run: object, repeat: int = 3) -> float:
    """The least process CPU seconds of ``repeat`` calls of ``run``."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        run()  # type: ignore[operator]
        best = min(best, time.process_time() - t0)
    return best


def per_value(values: np.ndarray) -> None:
    from ilic_cli.io import floattext

    floattext.texts(values[:10])  # the cache load
    bits = values.view(np.uint64)
    out = np.empty(len(values) * floattext.MAX_TEXT, dtype=np.uint8)
    ends = np.empty(len(values), dtype=np.int64)
    kernel = cpu(lambda: floattext._texts(bits, out, ends, *floattext.tables()))
    as_list = values.tolist()
    rep_list = cpu(lambda: repr(as_list))
    rep_map = cpu(lambda: list(map(repr, as_list)))
    n = len(values)
    print(f"{n} normals: compiled {kernel / n * 1e9:.1f} ns/value; repr(list) {rep_list / n * 1e9:.1f}; map(repr) {rep_map / n * 1e9:.1f} ns/value")


def first_call() -> None:
    runs = [subprocess.run([sys.executable, "-c", FIRST_CALL], capture_output=True, text=True, check=True, cwd=ROOT).stdout.split() for _ in range(3)]
    print("fresh process, numba imported: floattext import, first csv_rows call (cache load), CPU s:", "; ".join(" ".join(r) for r in runs))


def writer(duration_s: float) -> None:
    from ilic_cli.io import WriteOptions, csvlog, floattext
    from ilic_cli.simulation.scenarios import Overrides, run_scenario

    log = run_scenario("paper-sim", Overrides(duration_s=duration_s, seed=0))
    names = list(log.channels)
    columns = [np.asarray(log.channels[n], dtype=np.float64) for n in names]
    n = len(log)
    values = n * len(names)
    floattext.csv_rows(columns, 0, 2)

    def rows() -> None:
        buffer = None
        for start in range(0, n, csvlog.ROWS_PER_BLOCK):
            buffer, _ = floattext.csv_rows(columns, start, min(n, start + csvlog.ROWS_PER_BLOCK), buffer)

    with tempfile.TemporaryDirectory() as tmp:
        fast, slow = Path(tmp) / "fast.csv", Path(tmp) / "slow.csv"
        t_rows = cpu(rows)
        t_write = cpu(lambda: csvlog.write(log, fast, WriteOptions(fast=True)))
        t_repr = cpu(lambda: [list(map(repr, c.tolist())) for c in columns])
        csvlog.write(log, slow, WriteOptions(fast=False))
        same = fast.read_bytes() == slow.read_bytes()
        size = fast.stat().st_size
    print(
        f"paper-sim {duration_s:g} s, {n} rows x {len(names)} columns ({values} values, {size / 1e6:.1f} MB): "
        f"compiled rows {t_rows:.3f} s ({t_rows / values * 1e9:.1f} ns/value); csvlog.write {t_write:.3f} s; "
        f"map(repr) of the same values {t_repr:.3f} s ({t_repr / values * 1e9:.1f} ns/value); byte-identical to the repr writer: {same}"
    )


def _short_decimals(rng: np.random.Generator, count: int) -> np.ndarray:
    """Decimals of 1 to 17 random digits at random exponents read as float64, with the float64 on either side of each (a third each)."""
    third = count // 3
    digits = rng.integers(1, 18, size=third)
    mantissas = [int(rng.integers(10 ** (d - 1), 10**d)) for d in digits.tolist()]
    exponents = rng.integers(-340, 310, size=third).tolist()
    values = np.array([float(f"{m}e{e}") for m, e in zip(mantissas, exponents)])
    values = values[np.isfinite(values) & (values != 0.0)]
    return np.concatenate([values, np.nextafter(values, np.inf), np.nextafter(values, -np.inf)])


def sweep(count: int) -> None:
    from ilic_cli.io import floattext

    rng = np.random.default_rng(33)
    kinds = {
        "bit patterns": rng.integers(0, 2**64, size=count, dtype=np.uint64, endpoint=False).view(np.float64),
        "normals x 10^U(-300,300)": rng.standard_normal(count) * 10.0 ** rng.uniform(-300, 300, count),
        "uniform(0, 1)": rng.uniform(0.0, 1.0, count),
        "k / 1000": np.arange(count) / 1000.0,
        "k * 1e-6": np.arange(count) * 1e-6,
        "integers": rng.integers(-(2**53), 2**53, size=count).astype(np.float64),
        "short decimals and their neighbours": _short_decimals(rng, count),
        "every exponent, random significands": (
            rng.integers(1, 2**52, size=count, dtype=np.uint64) | (rng.integers(0, 2047, size=count, dtype=np.uint64) << np.uint64(52))
        ).view(np.float64),
    }
    for kind, values in kinds.items():
        got = floattext.texts(values)
        bad = [(repr(v), g) for v, g in zip(values.tolist(), got) if repr(v).encode() != g]
        print(f"sweep {kind}: {count} values, {len(bad)} differ from repr {bad[:3]}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--sweep", type=int, default=0)
    args = parser.parse_args(argv)
    per_value(np.random.default_rng(1).standard_normal(1_000_000))
    first_call()
    from benchmarks.bench_io import simulate_stages  # the stages of `ilic simulate` with each writer, CSV's among them

    simulate_stages(args.duration)
    writer(args.duration)
    if args.sweep:
        sweep(args.sweep)


if __name__ == "__main__":
    main()
