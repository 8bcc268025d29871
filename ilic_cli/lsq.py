"""Least squares with standard deviations (paper eqs. 5-10).

:func:`solve_batch` solves a stack of independent systems at once (one per
IDIM-ILIC window) through the SVD, so rank deficiency (an unexcited
parameter) is detected rather than producing NaN: the parameters in the
unidentifiable directions get an infinite standard deviation. :func:`robust_std`: the autocorrelation-robust
(Newey-West) standard deviations beside eq. 9's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

SigmaConvention = Literal["eq8", "sample_std"]


@dataclass(frozen=True)
class LSResult:
    """One least-squares estimate.

    Attributes
    ----------
    names : tuple of str
        Parameter names, in column order.
    theta, std, rel_std_pct : ndarray
        Estimate, standard deviation (eq. 9) and relative standard deviation
        in percent (eq. 10); ``inf`` where a parameter is not identifiable.
    sigma_rho : float
        Estimated standard deviation of the error (eq. 8, or the sample std).
    error_norm : float
        ``||Y - W theta||``.
    relative_error_pct : float
        ``100 ||Y - W theta|| / ||Y||``.
    condition_number : float
        2-norm condition number of ``W`` (``inf`` when rank-deficient).
    rows, rank : int
        Number of equations and numerical rank of ``W``.
    """

    names: tuple[str, ...]
    theta: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray
    sigma_rho: float
    error_norm: float
    relative_error_pct: float
    condition_number: float
    rows: int
    rank: int
    cov: np.ndarray | None = field(default=None, compare=False, repr=False)
    """Covariance of ``theta`` (``sigma_rho^2 (W'W)^-1``; the IV form for :func:`solve_iv`; ``inf`` along an unidentifiable
    direction); ``None`` where it was not computed (:func:`evaluate`)."""

    @property
    def full_rank(self) -> bool:
        return self.rank == len(self.names)

    def parameters(self) -> dict[str, dict[str, float | None]]:
        """``name -> {value, std, rel_std_pct}`` with ``None`` for non-finite values."""
        return {
            n: {"value": finite_or_none(v), "std": finite_or_none(s), "rel_std_pct": finite_or_none(r)}
            for n, v, s, r in zip(self.names, self.theta, self.std, self.rel_std_pct, strict=True)
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": self.parameters(),
            "relative_error_pct": finite_or_none(self.relative_error_pct),
            "error_norm": finite_or_none(self.error_norm),
            "error_std": finite_or_none(self.sigma_rho),
            "condition_number": finite_or_none(self.condition_number),
            "rows": self.rows,
            "rank": self.rank,
        }


def finite_or_none(x: float) -> float | None:
    """``x`` as a float, ``None`` when it is not finite (JSON has no inf or NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


RANK_EPS = 16 * np.finfo(np.float64).eps
"""The one rank rule: a singular value at or below ``RANK_EPS * max(r, b) * s_max`` is zero."""


def rank_tolerance(s_max: np.ndarray | float, rows: int, cols: int) -> np.ndarray | float:
    """Singular values at or below this are zero (:data:`RANK_EPS`)."""
    return s_max * max(rows, cols) * RANK_EPS


def pinv(W: np.ndarray) -> np.ndarray:
    """Moore-Penrose pseudo-inverse of ``W`` under the rank rule of :func:`rank_tolerance`."""
    W = np.asarray(W, dtype=np.float64)
    return np.linalg.pinv(W, rcond=max(W.shape) * RANK_EPS)


def column_basis(W: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of ``W`` (left singular vectors, rank rule of :func:`rank_tolerance`)."""
    W = np.asarray(W, dtype=np.float64)
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    if s.size == 0:
        return U
    return U[:, s > rank_tolerance(s[0], *W.shape)]


def lstsq(W: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares estimate (minimum-norm when rank-deficient, same rank rule) and residual sum of squares.

    The light form of :func:`solve` (no standard deviations), for the many
    small fits of diagnosis.
    """
    theta = np.linalg.lstsq(W, y, rcond=max(np.shape(W)) * RANK_EPS)[0]
    e = y - W @ theta
    return theta, float(np.sum(e * e))


def noise_corrected_lstsq(W: np.ndarray, y: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, float]:
    """Least squares corrected for noise in the regressor's columns, and the residual sum of squares at that estimate.

    ``theta = (W'W - Phi)^-1 W'y`` with ``Phi = mean_k N_k'N_k`` the covariance the columns' noise adds to ``W'W``
    (``noise``: realisations ``N_k`` of that noise, shape ``(K, rows, columns)``): plain least squares divides by
    ``W'W``, which that noise inflates, and so shrinks the coefficient of a noisy column towards zero (errors in the
    variables; bias-compensated least squares: T. Söderström, *Errors-in-Variables Methods in System Identification*,
    Springer, 2018). Plain least squares (:func:`lstsq`) where ``W'W - Phi`` is not positive definite: the noise is
    then not resolved from the signal.
    """
    W = np.asarray(W, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    N = np.asarray(noise, dtype=np.float64)
    A = W.T @ W - np.einsum("krb,krc->bc", N, N) / len(N)
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return lstsq(W, y)
    theta = np.linalg.solve(L.T, np.linalg.solve(L, W.T @ y))
    e = y - W @ theta
    return theta, float(np.sum(e * e))


def relative_error_pct(y: np.ndarray, y_hat: np.ndarray) -> float:
    """The one relative error: ``100 ||y - y_hat|| / ||y||`` (``inf`` for a zero ``y``)."""
    return norm_pct(float(np.linalg.norm(np.asarray(y) - np.asarray(y_hat))), float(np.linalg.norm(y)))


def norm_pct(error_norm: float, y_norm: float) -> float:
    """:func:`relative_error_pct` from norms already taken: ``100 error_norm / y_norm`` (``inf`` for a zero ``y_norm``),
    for the output-error fits, which keep the measured force's norm and take each residual's."""
    return float(100.0 * error_norm / y_norm) if y_norm > 0 else float("inf")


def relative_std_pct(theta: np.ndarray, std: np.ndarray) -> np.ndarray:
    """Relative standard deviation in percent (eq. 10): ``100 std / |theta|``, ``inf`` where ``theta`` is 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(theta != 0, 100.0 * std / np.abs(theta), np.inf)


def newey_west_lags(n: int) -> int:
    """The lags of a Newey-West long-run covariance of ``n`` samples: ``floor(4 (n/100)^(2/9))``, at most ``n - 1``."""
    return min(int(4.0 * (n / 100.0) ** (2.0 / 9.0)), max(n - 1, 0))


def bartlett_sum(g: np.ndarray, lags: int) -> np.ndarray:
    """``g'g`` plus the autocovariances of the columns of ``g`` over ``lags`` lags with Bartlett weights ``1 - l/(lags+1)``,
    not normalised: the Newey-West (HAC) long-run covariance is this over the number of rows."""
    S = g.T @ g
    for lag in range(1, lags + 1):
        G = g[lag:].T @ g[:-lag]
        S += (1.0 - lag / (lags + 1.0)) * (G + G.T)
    return S


def most_correlated(names: tuple[str, ...], cov: np.ndarray) -> tuple[str, str, float] | None:
    """The two estimates whose correlation (from ``cov``) is largest in size, with it; ``None`` with fewer than two that vary.

    Their errors lean together: the rows determine a combination of the two better than either alone. DATA_EMPS.mat's are Fv
    and Fc at -0.90; the robot corpus's dwell-and-move logs, whose moves run at one cruise speed, the same pair at -0.96 to
    -0.97, along which their errors under a force disturbance lie (corpus s3025: Fv -8.1 %, Fc +7.3 %)."""
    s = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    varies = np.isfinite(s) & (s > 0)  # an unidentifiable estimate's infinite variance, or none: no correlation
    best: tuple[str, str, float] | None = None
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if not (varies[i] and varies[j] and np.isfinite(cov[i, j])):
                continue
            r = float(cov[i, j] / (s[i] * s[j]))
            if best is None or abs(r) > abs(best[2]):
                best = (names[i], names[j], r)
    return best


def residual_sigma(e: np.ndarray, b: int, sigma: SigmaConvention) -> tuple[float, float]:
    """``||e||`` and the error's standard deviation by ``sigma``'s convention (:func:`solve_batch`) for ``b`` parameters."""
    err = float(np.linalg.norm(e))
    return err, float(np.std(e, ddof=1)) if sigma == "sample_std" else err / np.sqrt(max(len(e) - b, 1))


def _result(
    names: tuple[str, ...], y: np.ndarray, theta: np.ndarray, std: np.ndarray, sig: float, err: float, cond: float, rank: int, cov: np.ndarray | None
) -> LSResult:
    """The one place an :class:`LSResult`'s derived fields are made: eq. (10)'s ``rel_std_pct`` and the relative error ``100 err / ||y||``."""
    ny = float(np.linalg.norm(y))
    return LSResult(
        names=tuple(names),
        theta=theta,
        std=std,
        rel_std_pct=relative_std_pct(theta, std),
        sigma_rho=sig,
        error_norm=err,
        relative_error_pct=float(100.0 * err / ny) if ny > 0 else float("inf"),  # = relative_error_pct(y, y - e)
        condition_number=cond,
        rows=len(y),
        rank=rank,
        cov=cov,
    )


def solve_batch(W: np.ndarray, y: np.ndarray, names: tuple[str, ...], *, sigma: SigmaConvention = "eq8") -> list[LSResult]:
    """Solve ``y[k] = W[k] @ theta[k]`` for every ``k`` in the stack.

    Parameters
    ----------
    W : ndarray, shape (K, r, b)
        Observation matrices.
    y : ndarray, shape (K, r)
        Measurement vectors.
    names : tuple of str
        Parameter names (length ``b``).
    sigma : {"eq8", "sample_std"}
        ``eq8``: ``||Y - W theta||^2 / (r - b)`` (paper eq. 8);
        ``sample_std``: the sample variance of the error with ``r - 1``
        degrees of freedom, as the published EMPS procedure computes it.
    """
    W = np.asarray(W, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    K, r, b = W.shape
    U, s, Vt = np.linalg.svd(W, full_matrices=False)
    ok = s > rank_tolerance(s[:, :1], r, b)
    s_inv = np.where(ok, 1.0 / np.where(ok, s, 1.0), 0.0)
    uty = np.einsum("kri,kr->ki", U, y)
    theta = np.einsum("kij,ki->kj", Vt, uty * s_inv)
    e = y - np.einsum("krb,kb->kr", W, theta)
    err_norm = np.linalg.norm(e, axis=1)
    if sigma == "sample_std":
        sig = np.std(e, axis=1, ddof=1)
    else:
        sig = err_norm / np.sqrt(max(r - b, 1))
    # diag((W'W)^-1) = sum_i V[j,i]^2 / s_i^2 ; unidentifiable directions -> inf
    var_unit = np.einsum("kij,ki->kj", Vt**2, s_inv**2)
    cov_unit = np.einsum("kij,ki,kil->kjl", Vt, s_inv**2, Vt)  # (W'W)^+ = V diag(1/s^2) V'
    rank = ok.sum(axis=1)
    results = []
    for k in range(K):
        std = sig[k] * np.sqrt(var_unit[k])
        cov = sig[k] ** 2 * cov_unit[k]
        if rank[k] < b:
            # a parameter touching a null direction of W is not identifiable
            null = ~ok[k]
            touched = (np.abs(Vt[k][null]) > 1e-8).any(axis=0)
            std = np.where(touched, np.inf, std)
            cov = np.where(touched[:, None] | touched[None, :], np.inf, cov)
        cond = float(s[k, 0] / s[k, -1]) if rank[k] == b else float("inf")
        results.append(_result(names, y[k], theta[k], std, float(sig[k]), float(err_norm[k]), cond, int(rank[k]), cov))
    return results


def solve(W: np.ndarray, y: np.ndarray, names: tuple[str, ...], *, sigma: SigmaConvention = "eq8") -> LSResult:
    """Solve one system ``y = W @ theta`` (see :func:`solve_batch`)."""
    return solve_batch(W[None], y[None], names, sigma=sigma)[0]


def evaluate(W: np.ndarray, y: np.ndarray, theta: np.ndarray, names: tuple[str, ...], *, sigma: SigmaConvention = "sample_std") -> LSResult:
    """Apply fixed parameters ``theta`` to ``(W, y)``: errors of a cross-test validation, or of an estimate made otherwise.

    Standard deviations use the sample-std convention of the benchmark, or ``sigma`` (:func:`solve_batch`'s).
    """
    theta = np.asarray(theta, dtype=np.float64)
    err, sig = residual_sigma(y - W @ theta, len(theta), sigma)
    s = np.linalg.svd(W, compute_uv=False)
    std = sig * np.sqrt(np.diag(pinv(W.T @ W)))
    rank = int((s > rank_tolerance(s[0], *W.shape)).sum())
    return _result(names, y, theta, std, sig, err, float(s[0] / s[-1]), rank, None)


def solve_tall(W: np.ndarray, y: np.ndarray, names: tuple[str, ...], *, sigma: SigmaConvention = "eq8") -> LSResult:
    """:func:`solve` of a tall system through the R of a Householder QR of ``[W y]``: the SVD of ``R`` (b x b) only.

    ``W = Q R`` has ``R``'s singular values and right vectors, and ``Q' y`` is the QR's last column, so the estimate,
    rank, condition number and eq. (9) standard deviations are those of the SVD of ``W`` (rounding apart), without
    forming its (rows x b) left vectors; ``sigma`` from the residual ``y - W theta`` as :func:`solve`.
    A rank-deficient ``W`` goes to :func:`solve` (its null directions' infinite deviations).
    """
    rows, b = W.shape
    if rows <= 2 * b:
        return solve(W, y, names, sigma=sigma)
    R: np.ndarray = np.linalg.qr(np.column_stack([W, y]), mode="r")  # type: ignore[assignment]
    U, s, Vt = np.linalg.svd(R[:b, :b])
    if not s[-1] > rank_tolerance(s[0], rows, b):
        return solve(W, y, names, sigma=sigma)
    theta = Vt.T @ ((U.T @ R[:b, b]) / s)
    err, sig = residual_sigma(y - W @ theta, b, sigma)
    cov = sig**2 * (Vt.T / s**2) @ Vt
    std = sig * np.sqrt(((Vt / s[:, None]) ** 2).sum(axis=0))
    return _result(names, y, theta, std, sig, err, float(s[0] / s[-1]), b, cov)


def solve_iv(Z: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], *, sigma: SigmaConvention = "eq8") -> LSResult:
    """Instrumental-variable estimate ``theta = (Z' W)^-1 Z' y`` with its covariance.

    The covariance is ``sigma^2 (Z' W)^-1 Z' Z (W' Z)^-1`` (Janot, Vandanjon,
    Gautier, IEEE TCST 22(1), 2014), ``sigma`` from the residual ``y - W
    theta`` by the convention of :func:`solve_batch`. With ``Z = W`` this is
    :func:`solve`'s estimate and eq. (9). A singular ``Z' W`` (instruments
    uncorrelated with a column) gives an infinite standard deviation and
    rank below ``b``.
    """
    Z, W, y = (np.asarray(a, dtype=np.float64) for a in (Z, W, y))
    r, b = W.shape
    A = Z.T @ W
    s = np.linalg.svd(A, compute_uv=False)
    rank = int((s > rank_tolerance(s[0], b, b)).sum()) if len(s) else 0
    if rank < b:
        theta: np.ndarray = pinv(A) @ (Z.T @ y)
        std = np.full(b, np.inf)
        cov = np.full((b, b), np.inf)
    else:
        theta = np.linalg.solve(A, Z.T @ y)
    err, sig = residual_sigma(y - W @ theta, b, sigma)
    if rank == b:
        A_inv = np.linalg.inv(A)
        cov = sig**2 * (A_inv @ (Z.T @ Z) @ A_inv.T)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return _result(names, y, theta, std, sig, err, float(s[0] / s[-1]) if rank == b else float("inf"), rank, cov)


ROBUST_RULE = (
    "eq. 9 assumes a white residual; the robust standard deviations are Newey-West's (the sandwich covariance with the residual's "
    "autocovariance over floor(4 (n/100)^(2/9)) lags of the n rows, Bartlett weights): beside eq. 9's, which the published tables use"
)
"""The autocorrelation-robust standard deviation, in words (the reports state it)."""

NOT_WHITE_WIDENING = 1.5
"""A report says the residual is not white, with the robust standard deviations, when one exceeds eq. 9's by this factor
(half again: a statement about the numbers, not a test). Measured: DATA_EMPS.mat 2.6 (lag-1 autocorrelation 0.67); the robot
corpus's 1-2 kHz clean logs 0.56-2.0 with sensor noise or a current loop (median 1.0), 1.6-2.1 with a 10 Hz force disturbance,
where 8 seeds of one log (lin12 S-curve, 2 kHz) spread as the robust one says (Fc: 2.4 %; robust 2.8 %; eq. 9 1.6 %)."""


@dataclass(frozen=True)
class RobustStd:
    """Newey-West standard deviations of an IDIM-LS estimate (:data:`ROBUST_RULE`)."""

    std: np.ndarray
    lags: int
    lag1: float
    """Lag-1 autocorrelation of the residual (0 for a white one)."""

    def widening(self, eq9: np.ndarray) -> float:
        """The largest ratio of the robust standard deviation to eq. 9's over the identifiable parameters (1 when none)."""
        ok = np.isfinite(eq9) & (eq9 > 0) & np.isfinite(self.std)
        return float(np.max(self.std[ok] / eq9[ok])) if ok.any() else 1.0

    def to_dict(self, names: tuple[str, ...], eq9: np.ndarray) -> dict[str, Any]:
        widening = self.widening(eq9)
        return {
            "std": {n: finite_or_none(v) for n, v in zip(names, self.std, strict=True)},
            "lags": self.lags,
            "residual_lag1_autocorrelation": finite_or_none(self.lag1),
            "widening": finite_or_none(widening),
            "residual_white": bool(widening <= NOT_WHITE_WIDENING),
            "rule": ROBUST_RULE,
        }


def robust_covariance(W: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Newey-West (HAC) covariance of the least-squares estimate on ``W`` whose residual is ``e`` (:data:`ROBUST_RULE`).

    ``(W'W)^-1 S (W'W)^-1 n/(n-b)`` with ``S`` the residual-weighted columns' autocovariance summed over
    :func:`newey_west_lags` lags with weights ``1 - l/(L+1)`` (:func:`bartlett_sum`); a white residual gives eq. 9's covariance
    (to sampling error). The one covariance of an inverse model's least-squares estimate under an autocorrelated residual:
    ``identify``'s robust standard deviations and the diagnosis's stated ones.
    """
    n, b = W.shape
    A = pinv(W.T @ W)
    cov: np.ndarray = A @ bartlett_sum(W * e[:, None], newey_west_lags(n)) @ A * n / max(n - b, 1)
    return cov


def robust_std(W: np.ndarray, e: np.ndarray) -> RobustStd:
    """Newey-West (HAC) standard deviations of the least-squares estimate on ``W`` whose residual is ``e`` (:func:`robust_covariance`)."""
    n = W.shape[0]
    std = np.sqrt(np.maximum(np.diag(robust_covariance(W, e)), 0.0))
    c = e - e.mean()
    lag1 = float(c[1:] @ c[:-1] / (c @ c)) if n > 1 and c @ c > 0 else 0.0
    return RobustStd(std=std, lags=newey_west_lags(n), lag1=lag1)
