"""numba's ``njit`` for the plant's compiled loops, with numba's BLAS check answered without importing ``scipy.linalg``.

When numba first compiles or loads a function from its cache, it imports its
array implementations (``numba.np.arraymath``), whose module body checks once
that a BLAS is there (``numba.np.linalg.ensure_blas``: ``import
scipy.linalg.cython_blas``, which imports all of ``scipy.linalg`` and, through
scipy's array-API layer, ``numpy.f2py``): about 0.3 s of CPU before a cached
loop runs (``ilic simulate``; profiled, 0.33 s of the 0.8 s of a first 1 s
simulation). The plant's loops call no BLAS.

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
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
from pathlib import Path

import numba.np.linalg
from numba import njit

__all__ = ["njit"]


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
