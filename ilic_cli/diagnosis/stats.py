"""Statistics on the decimated IDIM system: least squares, prewhitening, F-tests, blocked folds.

Pure functions on arrays. The decimated IDIM residual is autocorrelated
(the anti-alias filter, and any structure the model leaves out), so the
ordinary F-test would be far too confident. :func:`nested_f_test`
therefore prewhitens: it fits an autoregressive model AR(p) to the residual of
the larger model (order by BIC), filters the force and every column with it
(feasible GLS, Cochrane-Orcutt) and compares the residual sums of squares of
the whitened systems with the F distribution.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.lsq import bartlett_sum, column_basis, lstsq, newey_west_lags, pinv


def lag1_autocorrelation(e: np.ndarray) -> float:
    """Lag-1 autocorrelation coefficient of ``e`` (mean removed)."""
    e = np.asarray(e, dtype=np.float64) - np.mean(e)
    den = float(e @ e)
    return float(e[1:] @ e[:-1] / den) if den > 0 else 0.0


def variance_inflation(rho: float) -> float:
    """Factor by which a positive lag-1 autocorrelation ``rho`` of a residual inflates the variance of an estimate from it,
    against white noise: ``(1 + r)/(1 - r)``, ``r`` = ``rho`` clipped to [0, 0.99] (a negative one is not credited)."""
    r = min(max(rho, 0.0), 0.99)
    return (1.0 + r) / (1.0 - r)


def effective_size(n: int, rho: float) -> float:
    """Effective number of independent samples of an AR(1) series: ``n (1 - rho)/(1 + rho)``."""
    rho = min(max(rho, -0.99), 0.99)
    return max(2.0, n * (1.0 - rho) / (1.0 + rho))


def ar_fit(e: np.ndarray, max_order: int = 10) -> np.ndarray:
    """AR coefficients ``a`` (``e[t] = sum a_i e[t-i] + w[t]``) with the order chosen by BIC.

    Every order is fitted by least squares on the same rows (those with
    ``max_order`` past values), from one Gram matrix.
    """
    e = np.asarray(e, dtype=np.float64) - np.mean(e)
    n = len(e)
    pmax = min(max_order, max((n - 1) // 4, 0))
    if pmax < 1:
        return np.zeros(0)
    X = np.stack([e[pmax - i : n - i] for i in range(1, pmax + 1)], axis=1)
    z = e[pmax:]
    m = len(z)
    G = X.T @ X
    b = X.T @ z
    zz = float(z @ z)
    best_bic, best = m * np.log(max(zz / m, 1e-300)), np.zeros(0)
    for p in range(1, pmax + 1):
        try:
            a = np.linalg.solve(G[:p, :p], b[:p])
        except np.linalg.LinAlgError:
            break
        rss = max(zz - float(b[:p] @ a), 1e-300)
        bic = m * np.log(rss / m) + p * np.log(m)
        if bic < best_bic:
            best_bic, best = bic, a
    return best


def whiten(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Apply the AR whitening filter ``x[t] - sum a_i x[t-i]`` along axis 0 (first ``p`` rows dropped)."""
    p = len(a)
    if p == 0:
        return np.asarray(x)
    out = x[p:].copy()
    for i, ai in enumerate(a, start=1):
        out -= ai * x[p - i : len(x) - i]
    return out


@dataclass(frozen=True)
class FTest:
    """A nested-model F-test on prewhitened data.

    Attributes
    ----------
    F, df1, df2, p_value : float
        Statistic, degrees of freedom and p-value of one comparison.
    trials : int
        Comparisons this one stands for (grid points x candidates): the
        Bonferroni factor.
    p_adjusted : float
        ``min(1, p_value * trials)``.
    ar_order : int
        Order of the whitening filter.
    rho : float
        Lag-1 autocorrelation of the (unwhitened) residual of the larger model.
    delta_bic : float
        BIC of the larger minus the smaller whitened model (negative favours it).
    """

    F: float
    df1: int
    df2: int
    p_value: float
    trials: int
    p_adjusted: float
    ar_order: int
    rho: float
    delta_bic: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "test": "nested-model F-test on AR-prewhitened decimated IDIM data, Bonferroni-corrected",
            "F": self.F,
            "df1": self.df1,
            "df2": self.df2,
            "p_value": self.p_value,
            "bonferroni_trials": self.trials,
            "p_adjusted": self.p_adjusted,
            "whitening_ar_order": self.ar_order,
            "residual_lag1_autocorrelation": self.rho,
            "delta_bic": self.delta_bic,
        }


def normal_sf(z: Any) -> Any:
    """Upper tail ``P(Z > z)`` of the standard normal (``scipy.special``: ``scipy.stats`` costs ~0.6 s to import)."""
    from scipy.special import ndtr  # deferred: scipy.special is slow to import (ilic --help stays fast)

    return ndtr(-np.asarray(z, dtype=float))


def normal_isf(p: Any) -> Any:
    """``z`` with ``P(Z > z) = p`` for the standard normal."""
    from scipy.special import ndtri  # deferred: scipy.special is slow to import (ilic --help stays fast)

    return -ndtri(np.asarray(p, dtype=float))


def f_sf(F: Any, df1: float, df2: float) -> Any:
    """Upper tail of Fisher's F distribution with ``(df1, df2)`` degrees of freedom."""
    from scipy.special import fdtrc  # deferred: scipy.special is slow to import (ilic --help stays fast)

    return fdtrc(df1, df2, np.asarray(F, dtype=float))


def chi2_sf(x: Any, dof: float) -> Any:
    """Upper tail of the chi-square distribution with ``dof`` degrees of freedom."""
    from scipy.special import chdtrc  # deferred: scipy.special is slow to import (ilic --help stays fast)

    return chdtrc(dof, np.asarray(x, dtype=float))


def nested_f_test(W0: np.ndarray, y0: np.ndarray, W1: np.ndarray, y1: np.ndarray, q: int, trials: int = 1, max_order: int = 10) -> FTest:
    """Test the larger model ``(W1, y1)`` against the smaller ``(W0, y0)``.

    ``q`` is the number of parameters the larger model adds (linear columns,
    plus one for a nonlinear parameter identified under the null). The AR
    whitening filter is fitted to the larger model's residual and applied to
    both systems.
    """
    theta1, _ = lstsq(W1, y1)
    e1 = y1 - W1 @ theta1
    a = ar_fit(e1, max_order)
    _, rss0 = lstsq(whiten(W0, a), whiten(y0, a))
    _, rss1 = lstsq(whiten(W1, a), whiten(y1, a))
    n = len(y1) - len(a)
    k0 = W0.shape[1]
    df1 = max(q, 1)
    df2 = max(n - k0 - df1, 1)
    F = max((rss0 - rss1) / df1, 0.0) / (rss1 / df2) if rss1 > 0 else float("inf")
    p = float(f_sf(F, df1, df2))
    dbic = n * np.log(rss1 / rss0) + df1 * np.log(n) if rss0 > 0 and rss1 > 0 else float("-inf")
    return FTest(float(F), df1, df2, p, trials, min(1.0, p * trials), len(a), lag1_autocorrelation(e1), float(dbic))


def gls_covariance(W: np.ndarray, y: np.ndarray, theta: np.ndarray, max_order: int = 10) -> np.ndarray:
    """Covariance of ``theta`` accounting for AR residuals (whitened-system covariance).

    A drift's trends (:func:`ilic_cli.diagnosis.drift.estimated`) only: their columns are slow (seconds), where the AR model
    of the residual carries its power; over 60 seeds of AR(1) force noise the stated σ is the estimates' spread (0.98-1.0 of
    it for a warm-up, 0.86-0.92 for a wear), where the Newey-West sandwich of every other least-squares estimate
    (:func:`ilic_cli.lsq.robust_covariance`) stated 0.85-0.88 of it, and 0.72 of this one on the robot corpus's 200 kg
    warm-up under the 10 Hz disturbance (s351, 28 % off).
    """
    e = y - W @ theta
    a = ar_fit(e, max_order)
    Ww = whiten(W, a)
    ew = whiten(e, a)
    dof = max(len(ew) - W.shape[1], 1)
    s2 = float(ew @ ew) / dof
    return s2 * pinv(Ww.T @ Ww)


def blocked_folds(n: int, k: int = 5, guard: int = 10) -> list[tuple[np.ndarray, np.ndarray]]:
    """``k`` contiguous test blocks over time; training leaves out ``guard`` rows each side of the block."""
    edges = np.linspace(0, n, k + 1).astype(int)
    out = []
    idx = np.arange(n)
    for i in range(k):
        a, b = edges[i], edges[i + 1]
        test = idx[a:b]
        train = idx[(idx < a - guard) | (idx >= b + guard)]
        out.append((train, test))
    return out


def folds_either_side(t_rows: np.ndarray, change_s: float | None, k: int = 5, guard: int = 10) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`blocked_folds` of the rows at times ``t_rows`` laid on each side of the time ``change_s`` apart: fold ``i`` holds out
    block ``i`` of the rows before it and block ``i`` of the rows from it, so every fold trains on both sides of a change there
    (a payload's, :func:`ilic_cli.diagnosis.system.change_time`).

    Blocked over the whole log, a change near a block's edge leaves one fold's training rows without it: the change's size
    is then fitted to a few rows' noise and that block's prediction explodes (corpus s710, a payload change at 80 % of the
    rows: the last fold kept 1 of the 111 rows after it, held-out error 3.7 % -> 130 %). Without a change, or with fewer
    than ``k`` rows on a side: :func:`blocked_folds` over all rows.
    """
    n = len(t_rows)
    split = n if change_s is None else int(np.searchsorted(t_rows, change_s))
    if split < k or n - split < k:
        return blocked_folds(n, k, guard)
    idx = np.arange(n)
    out = []
    for (_, test_a), (_, test_b) in zip(blocked_folds(split, k, guard), blocked_folds(n - split, k, guard), strict=True):
        near = np.zeros(n, dtype=bool)
        for lo, hi in ((test_a[0], test_a[-1]), (split + test_b[0], split + test_b[-1])):
            near[max(lo - guard, 0) : hi + guard + 1] = True
        out.append((idx[~near], np.r_[test_a, split + test_b]))
    return out


def contiguous_runs(idx: np.ndarray) -> list[np.ndarray]:
    """The runs of consecutive indices in the sorted ``idx`` (a fold's held-out spans)."""
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def batched_rss(W0: np.ndarray, y: np.ndarray, X: np.ndarray) -> np.ndarray:
    """RSS of ``y ~ [W0, X[:, g]]`` for every ``g``; ``X`` has shape ``(n, G, m)``.

    Partials ``W0`` out once (Frisch-Waugh-Lovell, through an orthonormal
    basis ``U`` of its columns under the rank rule of :mod:`ilic_cli.lsq`):
    the ``m x m`` normal matrix of each ``g`` is ``X_g'X_g - (U'X_g)'(U'X_g)``
    and its right-hand side ``X_g' r0``, all from one matrix product over
    the ``n`` rows; the small systems are then solved at once.
    """
    n, G, m = X.shape
    U = column_basis(W0)
    r0 = y - U @ (U.T @ y)
    X2 = X.reshape(n, G * m)
    C = (U.T @ X2).reshape(-1, G, m)
    b = (r0 @ X2).reshape(G, m)
    A = np.empty((G, m, m))
    for i in range(m):
        for j in range(i, m):
            A[:, i, j] = A[:, j, i] = np.einsum("ng,ng->g", X[:, :, i], X[:, :, j]) - np.einsum("rg,rg->g", C[:, :, i], C[:, :, j])
    A = A + np.eye(m)[None] * (1e-12 * np.trace(A, axis1=1, axis2=2)[:, None, None] / m + 1e-300)
    sol = np.linalg.solve(A, b[..., None])[..., 0]
    return float(r0 @ r0) - np.einsum("gm,gm->g", b, sol)


def shifted_rss(W0: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """RSS of ``Y[:, g] ~ W0`` for every column ``g`` of ``Y``."""
    R = Y - W0 @ (pinv(W0) @ Y)
    return np.einsum("ng,ng->g", R, R)


def heldout_errors(W: np.ndarray, y: np.ndarray, folds: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Held-out errors of every row: each block predicted by the model fitted on its training rows."""
    e = np.full(len(y), np.nan)
    for train, test in folds:
        theta, _ = lstsq(W[train], y[train])
        e[test] = y[test] - W[test] @ theta
    return e


LOSSES = ("squared", "absolute")
"""The losses of the held-out test (:func:`heldout_fall_p`)."""


def _differentials(e_before: np.ndarray, e_after: np.ndarray, losses: tuple[str, ...]) -> np.ndarray:
    """The loss differentials (one column per loss: ``e_before^2 - e_after^2``, ``|e_before| - |e_after|``) on the finite samples."""
    cols = [e_before**2 - e_after**2 if loss == "squared" else np.abs(e_before) - np.abs(e_after) for loss in losses]
    d = np.stack(cols, axis=1)
    return d[np.isfinite(d).all(axis=1)]


def _long_run_covariance(d: np.ndarray) -> np.ndarray:
    """Newey-West (Bartlett) long-run covariance of the columns of ``d`` about their means (:func:`ilic_cli.lsq.bartlett_sum`
    over :func:`ilic_cli.lsq.newey_west_lags`)."""
    n = len(d)
    return bartlett_sum(d - d.mean(axis=0), newey_west_lags(n)) / n


def diebold_mariano(e_before: np.ndarray, e_after: np.ndarray, loss: str = "squared") -> float:
    """One-sided p-value that the second model predicts better (Diebold-Mariano).

    The loss differential ``d = e_before^2 - e_after^2`` (``loss="absolute"``: ``|e_before| - |e_after|``) is
    autocorrelated: its mean's variance is the Newey-West (Bartlett) long-run variance with
    ``floor(4 (n/100)^(2/9))`` lags.
    """
    d = _differentials(e_before, e_after, (loss,))
    n = len(d)
    if n < 3:
        return 1.0
    lrv = float(_long_run_covariance(d)[0, 0])
    mean = float(d[:, 0].mean())
    if lrv <= 0:
        return 0.0 if mean > 0 else 1.0
    return float(normal_sf(mean / np.sqrt(lrv / n)))


HELDOUT_FALL_TEST = "Diebold-Mariano, one-sided, Newey-West variance, the larger of the squared- and absolute-loss statistics against its own null"
""":func:`heldout_fall_p`, in words (what the inverse model's held-out test and the replay's state, each with what it compares)."""


def heldout_fall_p(e_before: np.ndarray, e_after: np.ndarray) -> float:
    """The held-out test: one-sided p-value that ``e_after`` is smaller than ``e_before``, sample by sample.

    The larger of the two Diebold-Mariano statistics, with the squared and with the absolute loss, against its own
    null distribution: the two ``z`` are jointly normal with the correlation ``rho`` of their long-run covariance, so
    ``P(max > a) = 1 - Phi_2(a, a; rho) = Q(a) + 2 T(a, sqrt((1 - rho)/(1 + rho)))`` (Owen's ``T``): one test at the
    level asked, between one loss's p (``rho = 1``) and twice it (``rho = -1``).

    The squared loss has the power where the fall is in a few large errors (an effect that acts at breakaways), the
    absolute loss where a few large errors set the squared differential's long-run variance: corpus s440, gravity left
    out of a chirp's replay, held-out force error 18.6 % -> 2.76 %, lower in every block, squared p = 0.019, absolute
    p = 2.4e-6; s722, a flexibility on the inverse model, 0.299 -> 0.148, squared p = 0.026, absolute p = 2.8e-5.
    """
    from scipy.special import owens_t  # deferred: scipy.special is slow to import (ilic --help stays fast)

    d = _differentials(e_before, e_after, LOSSES)
    n = len(d)
    if n < 3:
        return 1.0
    S = _long_run_covariance(d)
    if not (S[0, 0] > 0 and S[1, 1] > 0):
        return min(diebold_mariano(e_before, e_after, loss) for loss in LOSSES)  # a loss without variance: its own rule
    z = d.mean(axis=0) / np.sqrt(np.diag(S) / n)
    rho = float(np.clip(S[0, 1] / np.sqrt(S[0, 0] * S[1, 1]), -1.0, 1.0))
    top = float(z.max())
    return float(min(1.0, normal_sf(top) + 2.0 * owens_t(top, np.sqrt((1.0 - rho) / (1.0 + rho)) if rho > -1.0 else np.inf)))
