"""numba's ``njit`` for the plant's compiled loops, with numba's BLAS check answered without importing ``scipy.linalg``.

When numba first compiles or loads a function from its cache, it imports its
array implementations (``numba.np.arraymath``), whose module body checks once
that a BLAS is there: ``import scipy.linalg.cython_blas``, which imports all of
``scipy.linalg`` and, through scipy's array-API layer, ``numpy.f2py`` -- about
0.3 s of CPU before a cached loop runs (``ilic simulate``; profiled, 0.33 s of
the 0.8 s of a first 1 s simulation). The plant's loops call no BLAS.

:func:`_arraymath_without_scipy_linalg` imports ``numba.np.arraymath`` while
``sys.modules`` holds a placeholder for ``scipy.linalg.cython_blas`` (only when
neither is imported yet), then takes it out again. numba's check reads the
same answer (``_HAVE_BLAS`` True, scipy's integer width read from
``scipy.__config__`` as always); a function compiled later that calls a BLAS
routine imports the real ``scipy.linalg.cython_blas`` then (numba imports it
again at typing, and its C helpers look the routines up by that module's name
when called), so nothing that needs ``scipy.linalg`` goes without it
(``tests/plant/test_jit.py``).
"""

from __future__ import annotations

import sys
import types

from numba import njit

__all__ = ["njit"]

BLAS_MODULE = "scipy.linalg.cython_blas"
"""The module numba's BLAS check imports (``numba.np.linalg.ensure_blas``)."""


def _arraymath_without_scipy_linalg() -> None:
    """Import ``numba.np.arraymath`` with :data:`BLAS_MODULE` answered by a placeholder taken out right after."""
    if "numba.np.arraymath" in sys.modules or BLAS_MODULE in sys.modules:
        return
    try:
        import scipy  # noqa: F401  numba's check imports scipy's top package (numba's own import did already)
    except ImportError:  # no scipy: numba's check finds no BLAS, as it would anyway
        return
    placeholder = types.ModuleType(BLAS_MODULE, "placeholder while numba checks for a BLAS (plant.jit)")
    sys.modules[BLAS_MODULE] = placeholder
    try:
        import numba.np.arraymath  # noqa: F401  imported here, under the placeholder, instead of at numba's first compile or cache load
    finally:
        if sys.modules.get(BLAS_MODULE) is placeholder:
            del sys.modules[BLAS_MODULE]


_arraymath_without_scipy_linalg()
