"""One log's task, and the places tasks run: this process, local processes, ``dask.distributed``.

A task (:class:`Task`) names a log and the settings; :func:`run_task` reads the
log, identifies it (:func:`ilic_cli.identify.identify`), optionally diagnoses it
(:func:`ilic_cli.diagnosis.diagnose`), and returns a JSON document: a pure
function of the log's bytes and the settings. A bad log gives a document with
its error, never an exception (only an interrupt ends a batch).

Where a task runs does not change its document: every worker computes with one
BLAS thread (dask's nanny sets the same for its workers, and the local pool's
fork server before numpy loads, :mod:`ilic_cli.fleet.preload`), and the caller writes the documents
and builds the table from them in a fixed order (:mod:`ilic_cli.fleet.table`).

This module imports nothing heavy at import time: a spawned worker unpickles
:func:`run_task` from here before it loads numpy.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from ilic_cli.errors import IlicError
from ilic_cli.parallel import BLAS_THREADS_ENV, THREADS_ENV, threads

WORKER_THREAD_VARIABLES = (*BLAS_THREADS_ENV, "NUMBA_NUM_THREADS", THREADS_ENV)
"""Environment variables that set a worker's BLAS, numba and replay threads (:mod:`ilic_cli.parallel`): the workers share the cores."""


@dataclass(frozen=True)
class TaskSettings:
    """What a batch computes on each log (part of every log's key: other settings, other results).

    Attributes
    ----------
    method : str
        :func:`ilic_cli.identify.identify`'s ``method``.
    structure : str
        The model structure.
    window_s : float
        IDIM-ILIC's window.
    diagnose : bool
        Also diagnose the log (its findings go to the table).
    """

    method: str = "both"
    structure: str = "rigid-offset"
    window_s: float = 6.2
    diagnose: bool = False

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Task:
    """One log to compute: its path, its key (content and settings) and the settings."""

    path: str
    key: str
    settings: TaskSettings


def one_thread_worker() -> None:
    """Initialise a worker process: one BLAS thread, as dask's workers have (set before numpy loads), and one replay thread."""
    for name in WORKER_THREAD_VARIABLES:
        os.environ[name] = "1"


def run_task(task: Task) -> dict[str, Any]:
    """The document of one log: its metadata, one entry per method and window, the findings; or its error.

    Keys: ``key``, ``path``, ``settings``, ``meta`` (``machine``, ``joint``,
    ``joint_type``, ``start_time_ns`` as the log gives them), ``estimates``
    (``method``, ``window``, ``t_start``, ``t_end``, ``parameters``: name ->
    ``[value, std, rel_std_pct]``, ``relative_error_pct``), ``findings`` (effect
    ids, ``None`` without ``diagnose``), ``not_judged`` (the effects proposed that
    no replay could judge: :attr:`ilic_cli.diagnosis.Diagnosis.unjudged`; ``None``
    without ``diagnose``), ``error`` (``None`` when identified), ``warnings``.
    """
    doc: dict[str, Any] = {
        "key": task.key,
        "path": task.path,
        "settings": task.settings.to_dict(),
        "meta": {},
        "estimates": [],
        "findings": None,
        "not_judged": None,
        "error": None,
        "warnings": [],
    }
    try:
        _identify_into(doc, task)
    except IlicError as exc:
        doc["error"] = exc.message()
    except (MemoryError, RecursionError):
        raise
    except Exception as exc:  # an internal failure on one log is that log's row, not the end of the batch
        doc["error"] = f"{task.path}: internal error: {type(exc).__name__}: {exc}"
    return doc


def _identify_into(doc: dict[str, Any], task: Task) -> None:
    # deferred: these load numpy, and a spawned worker imports this module (to unpickle run_task) before one_thread_worker
    # has set its BLAS threads; numpy must load after that (module docstring)
    from ilic_cli.identify import identify
    from ilic_cli.idim_ilic import ILICSettings
    from ilic_cli.io import read_log

    s = task.settings
    log = read_log(task.path)
    doc["meta"] = log_meta(log.meta)
    report = identify(log, method=s.method, structure=s.structure, ilic_settings=ILICSettings(window_s=s.window_s))
    d = report.to_dict()
    doc["meta"]["joint"] = d["joint"] if d["joint"] is not None else doc["meta"].get("joint")
    doc["meta"]["joint_type"] = d["joint_type"]
    doc["warnings"] = list(d["warnings"])
    for name in ("ls", "didim", "iv"):
        part = d[name]
        if part is not None:
            doc["estimates"].append(_estimate(part["method"], 0, None, None, part))
    if d["ilic"] is not None:
        for w in d["ilic"]["windows"]:
            doc["estimates"].append(_estimate("IDIM-ILIC", int(w["k"]), w["t_start"], w["t_end"], w))
    if s.diagnose:
        from ilic_cli.diagnosis import DiagnoseSettings, diagnose  # deferred: only with --diagnose

        try:  # a diagnosis that cannot run leaves the log's estimates, and says why in its rows
            diagnosis = diagnose(log, settings=DiagnoseSettings(model=s.structure)).to_dict()
        except IlicError as exc:
            doc["warnings"].append(f"diagnose: {exc.message()}")
        except (MemoryError, RecursionError):
            raise
        except Exception as exc:  # a failed diagnosis is said in the log's rows; its estimates stand
            doc["warnings"].append(f"diagnose: {task.path}: internal error: {type(exc).__name__}: {exc}")
        else:
            doc["findings"] = [f["effect"] for f in diagnosis["findings"]]
            doc["not_judged"] = list(diagnosis["not_judged"])


def log_meta(meta: dict[str, Any]) -> dict[str, Any]:
    """The fleet's keys of a log's metadata: ``machine``, ``joint`` (strings) and ``start_time_ns`` (whole ns since 1970 UTC)."""
    out: dict[str, Any] = {}
    for name in ("machine", "joint"):
        value = meta.get(name)
        if isinstance(value, (str, int)) and not isinstance(value, bool) and str(value):
            out[name] = str(value)
    start = meta.get("start_time_ns")
    if isinstance(start, (int, float)) and not isinstance(start, bool) and start == start:
        out["start_time_ns"] = int(start)
    return out


def _estimate(method: str, window: int, t_start: float | None, t_end: float | None, part: dict[str, Any]) -> dict[str, Any]:
    return {
        "method": method,
        "window": window,
        "t_start": t_start,
        "t_end": t_end,
        "parameters": {n: [p["value"], p["std"], p["rel_std_pct"]] for n, p in part["parameters"].items()},
        "relative_error_pct": part["relative_error_pct"],
    }


# ---------------------------------------------------------------------------
# where the tasks run
# ---------------------------------------------------------------------------
Runner = Callable[[Sequence[Task]], Iterator[dict[str, Any]]]
"""Runs tasks and yields their documents as they finish (in any order)."""


def in_process(tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
    """Run the tasks here, one after another."""
    for task in tasks:
        yield run_task(task)


def local_processes(workers: int) -> Runner:
    """Run the tasks in ``workers`` spawned local processes (one BLAS thread each)."""

    def run(tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        from concurrent.futures import ProcessPoolExecutor, as_completed  # deferred: only for a parallel batch

        # a fork server, not a fork of this process (whose BLAS may run threads): it sets one BLAS thread before numpy loads and
        # imports the numerics once (ilic_cli.fleet.preload), so the workers it forks start loaded
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["ilic_cli.fleet.preload"])
        ex = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=one_thread_worker)
        try:
            futures = [ex.submit(run_task, t) for t in tasks]
            for f in as_completed(futures):
                yield f.result()
        except BaseException:  # stopped (Ctrl-C, SIGTERM, a failed write): the logs not started are not run
            ex.shutdown(wait=False, cancel_futures=True)
            raise
        ex.shutdown(wait=True)  # the workers end with the batch, not after it

    return run


def dask_runner(address: str | None = None, workers: int | None = None) -> Runner:
    """Run the tasks on ``dask.distributed``: the scheduler at ``address``, or a LocalCluster of ``workers`` processes."""

    def run(tasks: Sequence[Task]) -> Iterator[dict[str, Any]]:
        # deferred: dask.distributed takes about a second to import, and only this runner needs it
        from distributed import Client, LocalCluster, as_completed

        cluster = None
        if address is None:
            cluster = LocalCluster(n_workers=workers or 1, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster if cluster is not None else address)
        try:
            client.run(one_thread_worker)  # the replays' threads (read at each call); the nanny has set BLAS's
            # a task's key is its log's key: the same log and settings are one task, whoever submits them
            futures = [client.submit(run_task, t, key=f"ilic-{t.key}", pure=False) for t in tasks]
            for f in as_completed(futures):
                yield f.result()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()

    return run


@dataclass(frozen=True)
class Placement:
    """Where a batch's tasks run: local processes (``jobs``, None: the cores available, :func:`ilic_cli.parallel.threads`),
    a dask LocalCluster of ``dask_workers`` processes, or the dask scheduler at ``scheduler`` (at most one of the last two)."""

    jobs: int | None = None
    dask_workers: int | None = None
    scheduler: str | None = None

    def runner(self, tasks: int) -> Runner:
        """The runner for ``tasks`` tasks: dask when asked, else as many local processes as tasks allow (one: this process)."""
        if self.dask_workers is not None:
            return dask_runner(workers=self.dask_workers)
        if self.scheduler is not None:
            return dask_runner(address=self.scheduler)
        n = min(self.jobs or threads(), tasks)
        return local_processes(n) if n > 1 else in_process
