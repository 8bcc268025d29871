"""Whole commands as a user runs them, process start included, each paired against a baseline in the same run.

``ilic --help`` and ``ilic identify DATA_EMPS.mat --method ls`` (the small job
of the start-up budget, issue 33: at most 2.5x ``python -c 'import numpy'``)
run in turn with ``python -c 'import numpy'`` -- A B A B ... after one warm-up
pair -- and the ratio is taken pair by pair (a machine whose speed drifts moves
both); ``ilic diagnose DATA_EMPS.mat`` (replays included) likewise, and ``ilic diagnose`` of a
robot-like log (the robot corpus's clean 200 kg trapezoid at 1 kHz, written as CSV,
its PD loop given by flags: dwells, so the closed loop's Stribeck search runs), and ``ilic identify --method ls`` of it
(dwells, so the drive's lag is sought). Prints the
medians, the median ratio and its range. Never asserted by tests: run it with
``make bench``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EMPS = ROOT.parent / "shared" / "emps" / "DATA_EMPS.mat"
ROBOT_LOG = "lin200/trapezoid/1000Hz/sensor/clean/s17"
"""The robot corpus's case timed by ``ilic diagnose`` (``tests/corpus/robot.py``): dwells and moves, no concealed effect."""
NUMPY = [sys.executable, "-c", "import numpy"]
"""The yardstick of start-up: an interpreter that imports NumPy and does nothing."""


def bytecode() -> None:
    """Compile the package's modules to bytecode once, as installing it does (``pip`` compiles at install), before timing processes.

    With ``PYTHONDONTWRITEBYTECODE`` set (as on the shared machine) nothing
    writes it, and every process would compile some 60 modules of
    ``ilic_cli`` and ``plant`` from source again (about 0.1 s of CPU a
    process, measured on ``ilic simulate``). Up-to-date files are left as they are.
    """
    import compileall  # benchmarks only

    for package in ("ilic_cli", "plant"):
        compileall.compile_dir(ROOT / package, quiet=1)


def run_once(args: list[str], env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """Wall time (s), CPU time (user + sys of the child, s) and peak RSS (KiB) of one run of ``args``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(args)}: status {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss


def paired(a: list[str], b: list[str], runs: int, env: dict[str, str] | None = None) -> dict[str, list[float]]:
    """Run ``a`` and ``b`` in turn ``runs`` times after one warm-up pair; wall and CPU times of each, and A/B per pair."""
    out: dict[str, list[float]] = {"a": [], "b": [], "a_cpu": [], "b_cpu": [], "ratio": [], "a_peak_kib": []}
    for i in range(runs + 1):
        wa, ca, pa = run_once(a, env)
        wb, cb, _ = run_once(b, env)
        if i:
            out["a"].append(wa)
            out["b"].append(wb)
            out["a_cpu"].append(ca)
            out["b_cpu"].append(cb)
            out["a_peak_kib"].append(pa)
            out["ratio"].append(wa / wb)
    return out


def describe(label: str, res: dict[str, list[float]], b_label: str) -> str:
    """One line: A's median wall time, B's, and the median ratio of the pairs with its range."""
    med = statistics.median
    return (
        f"  {label:44s} {med(res['a']):6.3f} s median vs {b_label} {med(res['b']):6.3f} s: "
        f"{med(res['ratio']):5.2f}x (pairs {min(res['ratio']):.2f}-{max(res['ratio']):.2f}, {len(res['ratio'])} runs; CPU {med(res['a_cpu']):.3f} s)"
    )


def robot_log(folder: Path) -> list[str]:
    """:data:`ROBOT_LOG` written as CSV in ``folder``: the path and its controller's flags."""
    sys.path.insert(0, str(ROOT))
    from tests.corpus.measure import controller_flags, write_csv  # the corpus's own writer
    from tests.corpus.robot import build, cases

    (case,) = [c for c in cases() if c.name == ROBOT_LOG]
    return [str(write_csv(build(case), folder / "trapezoid.csv")), *controller_flags(case)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=7)
    repeat = parser.parse_args().repeat
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    bytecode()
    ilic = [sys.executable, "-m", "ilic_cli"]
    jobs = [("ilic --help", [*ilic, "--help"], repeat)]
    if EMPS.is_file():
        jobs += [
            ("ilic identify DATA_EMPS.mat --method ls", [*ilic, "identify", str(EMPS), "--method", "ls"], repeat),
            ("ilic diagnose DATA_EMPS.mat", [*ilic, "diagnose", str(EMPS)], 3),
        ]
    else:
        print("  ../shared/emps absent: the DATA_EMPS.mat jobs are skipped")
    with tempfile.TemporaryDirectory() as tmp:
        robot = robot_log(Path(tmp))
        jobs.append(("ilic identify --method ls, robot 1 kHz trapezoid", [*ilic, "identify", robot[0], "--method", "ls", *robot[1:]], repeat))
        jobs.append(("ilic diagnose, robot corpus 1 kHz trapezoid", [*ilic, "diagnose", *robot], 3))
        for label, args, runs in jobs:
            print(describe(label, paired(args, NUMPY, runs), "python -c 'import numpy'"), flush=True)


if __name__ == "__main__":
    main()
