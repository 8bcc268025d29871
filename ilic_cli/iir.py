"""IIR filtering exactly as SciPy computes it, without importing ``scipy.signal``.

``scipy.signal`` takes most of a second to import (it pulls in ``scipy.stats``),
several times what ``ilic identify`` spends identifying. The few operations
identification needs are here, compiled once (numba, cached on disk):
``lfilter`` in transposed direct form II and ``sosfilt``, with the same
operations in the same order as SciPy's C code, so the results are
bit-identical (``tests/test_iir.py`` checks it), and ``filtfilt`` /
``sosfiltfilt`` with odd padding as SciPy builds them. Filter designs come
from :data:`DESIGNS` (SciPy's own coefficients for the default settings,
checked by the tests) or from ``scipy.signal`` for any other setting.

Pure functions on arrays, filtering along the last axis.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _lfilter_rows(b: np.ndarray, a: np.ndarray, x: np.ndarray, z: np.ndarray) -> None:  # pragma: no cover - compiled
    """Filter each row of ``x`` in place; ``z`` (rows, n-1) is the initial state, left as the final one.

    ``y = z0 + b0 x``; ``z_j = z_(j+1) + x b_(j+1) - y a_(j+1)``; ``z_last = x b_last - y a_last``.
    """
    rows, N = x.shape
    n = b.shape[0]
    for i in range(rows):
        for k in range(N):
            xk = x[i, k]
            yk = z[i, 0] + b[0] * xk
            for j in range(n - 2):
                z[i, j] = z[i, j + 1] + xk * b[j + 1] - yk * a[j + 1]
            z[i, n - 2] = xk * b[n - 1] - yk * a[n - 1]
            x[i, k] = yk


@njit(cache=True, nogil=True)
def _sosfilt_rows(sos: np.ndarray, x: np.ndarray, z: np.ndarray) -> None:  # pragma: no cover - compiled
    """Filter each row of ``x`` in place through the sections; ``z`` is (rows, sections, 2)."""
    rows, N = x.shape
    ns = sos.shape[0]
    for i in range(rows):
        for k in range(N):
            xc = x[i, k]
            for s in range(ns):
                xn = sos[s, 0] * xc + z[i, s, 0]
                z[i, s, 0] = sos[s, 1] * xc - sos[s, 4] * xn + z[i, s, 1]
                z[i, s, 1] = sos[s, 2] * xc - sos[s, 5] * xn
                xc = xn
            x[i, k] = xc


def _normalised(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``b, a`` divided by ``a[0]`` and zero-padded to one length (as SciPy's filters use them)."""
    b = np.atleast_1d(np.asarray(b, dtype=np.float64))
    a = np.atleast_1d(np.asarray(a, dtype=np.float64))
    if a[0] != 1.0:
        b, a = b / a[0], a / a[0]
    n = max(len(a), len(b))
    return np.r_[b, np.zeros(n - len(b))], np.r_[a, np.zeros(n - len(a))]


def lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The state of a filter in the steady state of a unit step (``scipy.signal.lfilter_zi``)."""
    b, a = _normalised(b, a)
    n = len(a)
    companion = np.zeros((n - 1, n - 1))
    companion[0, :] = -a[1:] / a[0]
    companion[np.arange(1, n - 1), np.arange(0, n - 2)] = 1.0
    return np.asarray(np.linalg.solve(np.eye(n - 1) - companion.T, b[1:] - a[1:] * b[0]))


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Steady-state states of the sections for a unit step (``scipy.signal.sosfilt_zi``)."""
    sos = np.asarray(sos, dtype=np.float64)
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s in range(sos.shape[0]):
        b, a = sos[s, :3], sos[s, 3:]
        zi[s] = scale * lfilter_zi(b, a)
        scale *= np.sum(b) / np.sum(a)
    return zi


def lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """``scipy.signal.lfilter(b, a, x, axis=-1, zi=zi)[0]`` for a 2-D ``x`` (rows) and ``zi`` of shape (rows, n-1)."""
    b, a = _normalised(b, a)
    y = np.array(x, dtype=np.float64, order="C")
    _lfilter_rows(b, a, y, np.array(zi, dtype=np.float64, order="C"))
    return y


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """``scipy.signal.sosfilt(sos, x, axis=-1, zi=...)[0]`` for a 2-D ``x``; ``zi`` is (rows, sections, 2)."""
    y = np.array(x, dtype=np.float64, order="C")
    _sosfilt_rows(np.ascontiguousarray(sos, dtype=np.float64), y, np.array(zi, dtype=np.float64, order="C"))
    return y


def odd_ext(x: np.ndarray, n: int) -> np.ndarray:
    """Odd extension of ``n`` samples at both ends of the last axis (``scipy.signal``'s ``odd_ext``)."""
    if n < 1:
        return x
    if n > x.shape[-1] - 1:
        raise ValueError(f"the padding ({n} samples) must be shorter than the signal ({x.shape[-1]} samples)")
    left_end, right_end = x[..., :1], x[..., -1:]
    left_ext = x[..., n:0:-1]
    right_ext = x[..., -2 : -(n + 2) : -1]
    return np.concatenate((2 * left_end - left_ext, x, 2 * right_end - right_ext), axis=-1)


def _rows(x: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    x = np.asarray(x, dtype=np.float64)
    return x.reshape(-1, x.shape[-1]), x.shape


def filtfilt(b: np.ndarray, a: np.ndarray, x: np.ndarray, padlen: int) -> np.ndarray:
    """Zero-phase filtering along the last axis (``scipy.signal.filtfilt``, ``padtype="odd"``, ``method="pad"``)."""
    rows, shape = _rows(x)
    ext = odd_ext(rows, padlen)
    zi = lfilter_zi(b, a)
    y = lfilter(b, a, ext, zi[None, :] * ext[:, :1])
    y = lfilter(b, a, y[:, ::-1], zi[None, :] * y[:, -1:])[:, ::-1]
    if padlen > 0:
        y = y[:, padlen:-padlen]
    return y.reshape(shape)


def sosfiltfilt(sos: np.ndarray, x: np.ndarray, padlen: int | None = None) -> np.ndarray:
    """Zero-phase filtering through second-order sections along the last axis (``scipy.signal.sosfiltfilt``)."""
    sos = np.asarray(sos, dtype=np.float64)
    if padlen is None:
        ntaps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
        padlen = 3 * ntaps
    rows, shape = _rows(x)
    ext = odd_ext(rows, padlen)
    zi = sosfilt_zi(sos)
    y = sosfilt(sos, ext, zi[None, :, :] * ext[:, :1, None])
    y = sosfilt(sos, y[:, ::-1], zi[None, :, :] * y[:, -1:, None])[:, ::-1]
    if padlen > 0:
        y = y[:, padlen:-padlen]
    return y.reshape(shape)


DESIGNS: dict[tuple[object, ...], object] = {
    ("butter", 4, 0.2, "ba"): (
        (0.004824343357716228, 0.019297373430864913, 0.02894606014629737, 0.019297373430864913, 0.004824343357716228),
        (1.0, -2.369513007182038, 2.313988414415881, -1.054665405878568, 0.18737949236818502),
    ),
    ("cheby1", 8, 0.05, 0.08, "ba"): (
        (3.5863243209995223e-09, 2.869059456799618e-08, 1.0041708098798663e-07, 2.0083416197597326e-07, 2.5104270246996655e-07,
         2.0083416197597326e-07, 1.0041708098798663e-07, 2.869059456799618e-08, 3.5863243209995223e-09),
        (1.0, -7.397720470943626, 24.07272776096697, -44.99891466598326, 52.84346676692241, -39.91591435246841, 18.93766580976049,
         -5.159179426375672, 0.6178695015203624),
    ),
    ("butter", 4, 0.01, "sos"): (
        (5.845142433144487e-08, 1.1690284866288973e-07, 5.845142433144487e-08, 1.0, -1.9426382305401135, 0.9435972784703671),
        (1.0, 2.0, 1.0, 1.0, -1.975269634851873, 0.9762447923594398),
    ),
}
"""SciPy's designs for the default settings (IDIM-LS position filter at 1 kHz, MATLAB's
decimation filter for r = 10, the IDIM-ILIC 5 Hz filter at 1 kHz), so that the default
path needs no ``scipy.signal``; ``tests/test_iir.py`` checks them against SciPy."""


@functools.lru_cache(maxsize=64)
def butter(order: int, wn: float, output: str = "ba") -> tuple[np.ndarray, ...]:
    """Butterworth low-pass ``(b, a)`` or ``(sos,)`` (``scipy.signal.butter``)."""
    known = DESIGNS.get(("butter", order, wn, output))
    if known is not None:
        arrays = tuple(np.array(c) for c in known)  # type: ignore[attr-defined]
        return (np.array(arrays),) if output == "sos" else arrays
    from scipy import signal  # deferred: scipy.signal costs most of a second to import

    if output == "sos":
        return (signal.butter(order, wn, output="sos"),)
    return tuple(signal.butter(order, wn))


@functools.lru_cache(maxsize=64)
def cheby1(order: int, ripple_db: float, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev type I low-pass ``(b, a)`` (``scipy.signal.cheby1``)."""
    known = DESIGNS.get(("cheby1", order, ripple_db, wn, "ba"))
    if known is not None:
        b, a = (np.array(c) for c in known)  # type: ignore[attr-defined]
        return b, a
    from scipy import signal  # deferred: see butter

    b, a = signal.cheby1(order, ripple_db, wn)
    return b, a
