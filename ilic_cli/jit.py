"""numba's ``njit`` for the compiled loops (the plant's, the CSV writer's float text): the BLAS check answered without ``scipy.linalg``; a cached
function loaded without numba's registries.

In the lowest layer (types) so that every layer may compile through it: the I/O layer's CSV writer
(:mod:`ilic_cli.io.floattext`) as well as the plant.

When numba first compiles or loads a function from its cache, it imports its
array implementations (``numba.np.arraymath``), whose module body checks once
that a BLAS is there (``numba.np.linalg.ensure_blas``: ``import
scipy.linalg.cython_blas``, which imports all of ``scipy.linalg`` and, through
scipy's array-API layer, ``numpy.f2py``): about 0.3 s of CPU before a cached
loop runs (``ilic simulate``; profiled, 0.33 s of the 0.8 s of a first 1 s
simulation). The plant's loops and the float text call no BLAS.

:func:`_arraymath_without_scipy_linalg` imports ``numba.np.arraymath`` while
``ensure_blas`` is :func:`_blas_installed`: the same answer (numba's
``_HAVE_BLAS``), from scipy's files instead of an import, and numba's own check
of scipy's integer width. Then ``ensure_blas`` is numba's again: a function
compiled later that calls a BLAS routine imports the real
``scipy.linalg.cython_blas`` (numba checks again at typing, and its C helpers
look the routines up by that module's name when called), so nothing that
needs ``scipy.linalg`` goes without it (``tests/plant/test_jit.py``). No
module is put in ``sys.modules``: a thread importing ``scipy.linalg``
meanwhile gets the real one.

A function that numba loads from its cache does not need numba's target
registries (the implementations its compiler looks up): numba's
``Cache.load_overload`` nevertheless refreshes the target context first,
which imports and installs them -- 0.09-0.14 s of CPU of the 0.15 s a
process spends loading the loop (measured in ``ilic simulate``; the loads
themselves and a 1 s simulation take 0.02 s). :class:`_CacheLoadedBare`
initialises only numba's runtime (NRT), which the cached code calls, and
loads the function; when the cache has no such function numba compiles it,
and numba's compiler refreshes the context itself before any compile
(``compile_extra``; tested).
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
from pathlib import Path
from typing import Any

import numba
import numba.np.linalg
from numba.core.caching import FunctionCache
from numba.core.runtime.nrt import rtsys

__all__ = ["njit"]


class _CacheLoadedBare(FunctionCache):
    """numba's cache of a function, loaded without refreshing the target context (its registries)."""

    def load_overload(self, sig: Any, target_context: Any) -> Any:
        """numba's ``load_overload`` with :data:`rtsys` initialised instead of the whole context refreshed before the load."""
        rtsys.initialize(target_context)  # the runtime (NRT) the cached machine code calls
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)
        return None  # an I/O error swallowed by the guard, as numba's


def _bare_cache_load(dispatcher: Any) -> Any:
    """``dispatcher`` with its on-disk cache (``cache=True``) loaded by :class:`_CacheLoadedBare`."""
    cache = getattr(dispatcher, "_cache", None)
    if type(cache) is FunctionCache:
        cache.__class__ = _CacheLoadedBare  # the same cache (its files, its index), not a second one numba would set up again
    return dispatcher


def njit(*args: Any, **options: Any) -> Any:
    """numba's ``njit`` (bare or with options); a cached function is loaded by :class:`_CacheLoadedBare`."""
    if args and callable(args[0]):
        return _bare_cache_load(numba.njit(*args, **options))
    decorate = numba.njit(*args, **options)
    return lambda function: _bare_cache_load(decorate(function))


def _blas_installed() -> None:
    """``numba.np.linalg.ensure_blas`` without its import: ImportError when scipy has no ``cython_blas`` extension; numba's integer-width check."""
    spec = importlib.util.find_spec("scipy.linalg")  # imports scipy's top package (numba's own import did already), not scipy.linalg
    places = [Path(p) for p in (spec.submodule_search_locations or [])] if spec is not None else []
    if not any((place / f"cython_blas{suffix}").is_file() for place in places for suffix in importlib.machinery.EXTENSION_SUFFIXES):
        raise ImportError("scipy 0.16+ is required for linear algebra")
    numba.np.linalg._check_lapack_int_width()


def _arraymath_without_scipy_linalg() -> None:
    """Import ``numba.np.arraymath`` with numba's BLAS check answered by :func:`_blas_installed` (numba's own check after)."""
    if "numba.np.arraymath" in sys.modules:
        return
    original = numba.np.linalg.ensure_blas
    numba.np.linalg.ensure_blas = _blas_installed
    try:
        arraymath = importlib.import_module("numba.np.arraymath")  # here, its BLAS check answered, not at numba's first compile or cache load
    finally:
        numba.np.linalg.ensure_blas = original
    setattr(arraymath, "ensure_blas", original)  # noqa: B010  the name it imported, for anything that calls it later (an attribute mypy does not know)


_arraymath_without_scipy_linalg()
