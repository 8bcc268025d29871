"""Derivatives of sampled signals (pure functions on arrays): the benchmark's central differences and the five-point
stencil IDIM-LS takes below 1 kHz (:func:`ilic_cli.filtering.rows_stencil` chooses)."""

from __future__ import annotations

import numpy as np


def central_difference(x: np.ndarray, dt_s: float) -> np.ndarray:
    """Derivative by central differences along the first axis, one-sided at both ends (MATLAB ``gradient``).

    A 1-D signal is differenced into its result with no temporary beside it (a 1-hour log's IDIM-LS holds at most
    two such arrays beside its columns: issue 33), the bits of ``np.gradient``'s (tested); else ``np.gradient``.
    """
    x = np.asarray(x)
    if x.ndim != 1 or len(x) < 2:
        return np.gradient(x, dt_s, axis=0)
    out = np.empty(np.shape(x), dtype=np.float64)
    np.subtract(x[2:], x[:-2], out=out[1:-1])
    np.divide(out[1:-1], 2.0 * dt_s, out=out[1:-1])
    out[0] = (x[1] - x[0]) / dt_s
    out[-1] = (x[-1] - x[-2]) / dt_s
    return out


def derivative(x: np.ndarray, dt_s: float, points: int = 3) -> np.ndarray:
    """Derivative along the first axis by a ``points``-point central stencil (:func:`ilic_cli.filtering.rows_stencil` chooses it).

    ``3``: :func:`central_difference` (the benchmark's; gain ``sin(ωT)/(ωT)``, 1 - (ωT)²/6). ``5``:
    ``(x[k-2] - 8 x[k-1] + 8 x[k+1] - x[k+2]) / 12T`` (gain ``(8 sin ωT - sin 2ωT)/(6ωT)``, 1 - (ωT)⁴/30), central
    differences on the samples next to the ends, one-sided at both ends.
    """
    if points == 3:
        return central_difference(x, dt_s)
    if points != 5:
        raise ValueError(f"a derivative stencil has 3 or 5 points, not {points}")
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 5:
        return central_difference(x, dt_s)
    out = central_difference(x, dt_s)  # the ends and their neighbours
    mid = out[2:-2]
    np.subtract(x[3:-1], x[1:-3], out=mid)
    mid *= 8.0
    mid += x[:-4]
    mid -= x[4:]
    mid /= 12.0 * dt_s
    return out
