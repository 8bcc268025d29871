"""Imported first by the local workers' fork server: one BLAS thread, then the numerics, once for every worker.

The workers of a local batch (:func:`ilic_cli.fleet.execute.local_processes`)
are forked from a fork server that imported this module: each starts with
numpy, the readers, identification, the diagnosis and the compiled plant
already loaded (some 0.7 s of CPU a worker saved when the diagnosis runs), and
with one BLAS thread set before numpy loaded, as dask's workers have.
"""

from __future__ import annotations

import importlib

from ilic_cli.fleet.execute import one_thread_worker

PRELOADED = ("numpy", "ilic_cli.io", "ilic_cli.io.mcaplog", "ilic_cli.identify", "ilic_cli.diagnosis", "plant.kernel")
"""Modules every worker starts with."""


def preload() -> None:
    """One BLAS thread (before numpy), then import :data:`PRELOADED`."""
    one_thread_worker()
    for name in PRELOADED:
        importlib.import_module(name)


preload()
