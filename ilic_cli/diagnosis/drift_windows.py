"""The per-window estimates of a log: every parameter of the model estimated on each of windows of equal duration (issue 29, item 5).

IDIM-ILIC's picture of a non-stationary axis, on the measured regressor (windowed IDIM-LS, with an
autocorrelation-aware standard deviation). :mod:`ilic_cli.diagnosis.drift` reports them beside a drift: they show
it, the test on all the rows decides it (a window of 30-90 rows that moves in one direction cannot tell ``Fv`` from
``Fc``, and its estimates scatter by tens of per cent).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.lsq import finite_or_none, robust_covariance

WINDOWS = 10
"""Number of windows of equal duration the per-window estimates are shown on (a 30 s log: 3 s each)."""

MIN_WINDOW_ROWS_PER_COLUMN = 8
"""A window is estimated only with at least this many rows per column of the model."""

MIN_WINDOWS = 5
"""Fewest windows the per-window estimates are shown on when the rows are few (:func:`estimable_windows`)."""


@dataclass(frozen=True)
class WindowEstimates:
    """Per-window estimates of every parameter of the model.

    Attributes
    ----------
    t : ndarray (K,)
        Middle of each window's rows (s).
    start, end : float
        Time of the first and last row of the log.
    names : tuple of str
        The model's parameters.
    theta, std : ndarray (K, p)
        Estimates and autocorrelation-aware standard deviations (NaN where a column is not identifiable in the window).
    rows : ndarray (K,)
        Rows per window.
    """

    t: np.ndarray
    start: float
    end: float
    names: tuple[str, ...]
    theta: np.ndarray
    std: np.ndarray
    rows: np.ndarray

    def series(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(t, estimate, std)`` of one parameter over the windows where it is estimated."""
        j = self.names.index(name)
        ok = np.isfinite(self.theta[:, j]) & np.isfinite(self.std[:, j]) & (self.std[:, j] > 0)
        return self.t[ok], self.theta[ok, j], self.std[ok, j]

    def to_dict(self) -> dict[str, Any]:
        return {
            "t": [float(x) for x in self.t],
            "rows": [int(r) for r in self.rows],
            "estimates": {n: [finite_or_none(float(v)) for v in self.theta[:, j]] for j, n in enumerate(self.names)},
            "std": {n: [finite_or_none(float(v)) for v in self.std[:, j]] for j, n in enumerate(self.names)},
        }


def _independent(W: np.ndarray) -> np.ndarray:
    """The columns kept in a window, in order: each one that adds to the rank of those before it.

    An effect's column can be zero in a window (a payload change not reached yet) or the same as a rigid one there
    (after the change, ``qdd``): it is left out of that window, and the rigid parameter carries it.
    """
    keep = np.zeros(W.shape[1], dtype=bool)
    for j in range(W.shape[1]):
        keep[j] = True
        if np.linalg.matrix_rank(W[:, keep]) < int(keep.sum()):
            keep[j] = False
    return keep


def window_estimates(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], n_windows: int = WINDOWS) -> WindowEstimates:
    """Every parameter estimated on each of ``n_windows`` windows of equal duration (rows ``t`` sorted in time)."""
    t = np.asarray(t, dtype=np.float64)
    W = np.asarray(W, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    p = W.shape[1]
    start, end = (float(t[0]), float(t[-1])) if len(t) else (0.0, 0.0)
    edges = np.linspace(start, end, n_windows + 1)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n_windows - 1)
    mids, thetas, stds, counts = [], [], [], []
    for k in range(n_windows):
        sel = which == k
        n = int(sel.sum())
        theta = np.full(p, np.nan)
        std = np.full(p, np.nan)
        if n >= MIN_WINDOW_ROWS_PER_COLUMN * p:
            Wk, yk = W[sel], y[sel]
            active = _independent(Wk)
            sol, *_ = np.linalg.lstsq(Wk[:, active], yk, rcond=None)
            theta[active] = sol
            std[active] = np.sqrt(np.clip(np.diag(robust_covariance(Wk[:, active], yk - Wk[:, active] @ sol)), 0.0, None))
        mids.append(float(np.mean(t[sel])) if n else 0.5 * (edges[k] + edges[k + 1]))
        thetas.append(theta)
        stds.append(std)
        counts.append(n)
    return WindowEstimates(
        np.array(mids), start, end, tuple(names), np.array(thetas).reshape(n_windows, p), np.array(stds).reshape(n_windows, p), np.array(counts)
    )


def estimable_windows(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], most: int = WINDOWS) -> WindowEstimates:
    """:func:`window_estimates` on ``most`` windows, or on the most windows below it of which :data:`MIN_WINDOWS` are estimated.

    The rows come at the decimated rate (a tenth of the log's), so over the same time a 500 Hz log has half the rows
    of a 1 kHz one: a 10 s dwell-and-move log at 500 Hz keeps some 290, and its ten windows of 22-38 rows (fewer than
    :data:`MIN_WINDOW_ROWS_PER_COLUMN` per column) left the test unrun. Its windows are made longer instead, as few
    fewer as it takes (never below :data:`MIN_WINDOWS`); a log whose ``most`` windows are estimated keeps them.
    """
    need = MIN_WINDOW_ROWS_PER_COLUMN * np.shape(W)[1]
    win = window_estimates(t, W, y, names, most)
    for n in range(most - 1, MIN_WINDOWS - 1, -1):
        if np.count_nonzero(win.rows >= need) >= min(MIN_WINDOWS, most):
            break
        win = window_estimates(t, W, y, names, n)
    return win
