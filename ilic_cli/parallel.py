"""Independent replays on the machine's cores: threads over the compiled closed loop.

The closed loop's kernel (:mod:`plant.kernel`) is compiled with ``nogil``, so
replays in threads run side by side (measured: 8 Stribeck replays of a 30 s
trapezoid, 0.87 s one after another, 0.48 s in two threads, bit-identical
logs). Each item is computed by a pure function of its own inputs and the
results come back in the items' order, so the outcome does not depend on the
number of threads or their timing.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from typing import TypeVar

from ilic_cli.errors import ParameterError

T = TypeVar("T")
R = TypeVar("R")

THREADS_ENV = "ILIC_THREADS"
"""Environment variable: the most threads to use (default: the cores this process may run on)."""


def threads() -> int:
    """The threads :func:`ordered_map` uses: ``$ILIC_THREADS`` when set, else the cores available.

    Raises
    ------
    ParameterError
        ``$ILIC_THREADS`` is not a whole number of at least 1.
    """
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        if not (env.isdigit() and int(env) >= 1):
            raise ParameterError(THREADS_ENV, env, "a whole number of threads, at least 1")
        return int(env)
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not on every platform
        return max(os.cpu_count() or 1, 1)


BLAS_THREADS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""Environment variables that set the BLAS's threads, read once, when numpy's BLAS loads."""


def one_blas_thread() -> None:
    """One BLAS thread for this process: set before numpy loads (after, it changes nothing).

    The parallelism is :func:`ordered_map`'s, whose results do not depend on its threads. The BLAS's
    threads split its sums, so the last bits followed the machine's cores: ``ilic diagnose DATA_EMPS.mat``
    with two BLAS threads and with one differed from the lag locator's bound on (0.16723908713533895 ms
    against 0.1672390871352219), ``identify --method iv`` in its estimates. Nor did they pay: on 2 cores two BLAS
    threads took 1.72x the CPU of one and 1.10x the wall time (``diagnose DATA_EMPS.mat``), 1.19x and
    1.03x on a 10-minute 6-joint arm's identification (``benchmarks/bench_robot.py identify``).
    """
    for name in BLAS_THREADS_ENV:
        os.environ[name] = "1"


PREFIX = "ilic-worker"
"""Name prefix of :func:`ordered_map`'s threads."""


def ordered_map(fn: Callable[[T], R], items: Sequence[T], most: int | None = None) -> list[R]:
    """``[fn(x) for x in items]``, computed in up to :func:`threads` threads (and ``most``), in the items' order.

    Only the outermost call shares work out: called from one of its own
    threads (the folds of each Monte-Carlo replicate, say), it runs in that
    thread. An exception in any item is raised here (the first in order);
    items not yet started are then cancelled.
    """
    n = min(threads(), len(items), most or len(items))
    if n <= 1 or threading.current_thread().name.startswith(PREFIX):
        return [fn(x) for x in items]
    from concurrent.futures import ThreadPoolExecutor  # deferred: only where work is shared out

    ex = ThreadPoolExecutor(max_workers=n, thread_name_prefix=PREFIX)
    try:
        futures = [ex.submit(fn, x) for x in items]
        return [f.result() for f in futures]
    finally:
        ex.shutdown(wait=False, cancel_futures=True)
