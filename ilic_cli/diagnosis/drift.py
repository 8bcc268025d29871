"""Parameters that change over time: friction that drifts, read from per-window estimates (issue 29, item 5).

Pure functions on arrays. The IDIM system of the whole log (its decimated
rows, their times) is cut into :data:`WINDOWS` windows of equal duration, and
every parameter of the model is estimated on each window alone (windowed
IDIM-LS on the measured regressor, with an autocorrelation-aware standard
deviation). A friction coefficient (``Fv``, ``Fc`` and their one-sided forms)
that changes over the run shows as a trend across the windows:

* ``exponential``: ``x(t) = a + b exp(-(t - t0)/tau)``, a warm-up (``tau`` searched);
* ``linear``: ``x(t) = a + r (t - t0)``, a wear.

The test of significance compares each trend with a constant level by an
F-test whose noise is the windows' own scatter around the trend (not their
nominal standard deviations, which a model error the same in every window
would make too small), weighted by those standard deviations; Bonferroni over
the coefficients and the two shapes. A trend is a finding when the test passes
at :data:`ALPHA`, the trend moves the coefficient by at least
:data:`MIN_CHANGE` of its level over the log, and it keeps the coefficient at
or above zero (friction; a trend through zero is an outlying window, as on a
window of the EMPS reference that hardly moves). The exponential shape is named
when it fits significantly better than the straight line (:data:`SHAPE_ALPHA`)
and its time constant is shorter than the log; else the drift is linear.

The trend's columns (the coefficient's column times its shape in time) must
then lower the held-out error of blocked cross-validation over time, as a
catalogue effect's do (Diebold-Mariano at the selection's level).

A step in the mass (``payload_change``) moves each window's ``M``, not its
friction: every parameter is free in every window, so it is no drift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.diagnosis.select import Evaluation, SelectSettings
from ilic_cli.diagnosis.stats import FTest, blocked_folds, diebold_mariano, f_sf, gls_covariance, heldout_errors
from ilic_cli.effects import Estimate
from ilic_cli.lsq import finite_or_none, relative_error_pct

WINDOWS = 10
"""Number of windows of equal duration (a 30 s log: 3 s each)."""

MIN_WINDOW_ROWS_PER_COLUMN = 8
"""A window is estimated only with at least this many rows per column of the model."""

MIN_WINDOWS = 5
"""Fewest windows a trend is fitted on (:func:`fit_trend`)."""

ALPHA = 1e-3
"""Level of the test of a trend across the windows (after Bonferroni over coefficients and shapes)."""

SHAPE_ALPHA = 0.01
"""Level at which the exponential trend must beat the straight line to be named exponential."""

MIN_CHANGE = 0.05
"""Smallest change of a coefficient over the log, relative to its level at the start, that is a finding."""

HELDOUT_ALPHA = SelectSettings().alpha_heldout
"""Level of the held-out check: the trend's columns must lower the blocked cross-validation error (Diebold-Mariano), as a catalogue effect's."""

DRIFTING = ("Fv", "Fc", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg")
"""The friction coefficients whose drift is sought (those of the model)."""

SHAPES = ("exponential", "linear")
"""The shapes of a drift."""


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


@dataclass(frozen=True)
class Trend:
    """The trend of one coefficient across the windows, in its best shape, and its test against a constant level.

    ``start``/``end``: the trend's value at the log's first and last row; ``change``: ``end - start``;
    ``asymptote``: the exponential's ``a`` (its level once warm), else ``None``; ``tau``: its time
    constant (s), else ``None``; ``rate``: the straight line's slope (per s), else ``None``.
    """

    parameter: str
    shape: str
    start: float
    end: float
    asymptote: float | None
    tau: float | None
    rate: float | None
    test: FTest
    shape_p_value: float | None
    windows: int

    @property
    def change(self) -> float:
        return self.end - self.start

    @property
    def relative_change(self) -> float:
        """The change over the log relative to the level at the start (the warm-up's whole change for an exponential)."""
        full = (self.asymptote - self.start) if self.asymptote is not None else self.change
        return full / abs(self.start) if self.start != 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameter": self.parameter,
            "shape": self.shape,
            "start": finite_or_none(self.start),
            "end": finite_or_none(self.end),
            "asymptote": None if self.asymptote is None else finite_or_none(self.asymptote),
            "relative_change": finite_or_none(self.relative_change),
            "time_constant_s": self.tau,
            "rate_per_s": self.rate,
            "test": {**_finite(self.test.to_dict()), "noise": "the windows' scatter around the trend"},
            "exponential_vs_linear_p_value": self.shape_p_value,
            "windows": self.windows,
        }


def _finite(d: dict[str, Any]) -> dict[str, Any]:
    return {k: finite_or_none(v) if isinstance(v, float) else v for k, v in d.items()}


@dataclass(frozen=True)
class DriftResult:
    """What the windows say of parameters that change over time.

    ``trends``: every drifting coefficient's best trend; ``findings``: those that pass the test and
    are material, strongest first; ``reason``: why there is no finding (empty when there is one).
    """

    windows: WindowEstimates | None
    trends: list[Trend] = field(default_factory=list)
    findings: list[Trend] = field(default_factory=list)
    reason: str = ""
    heldout_before_pct: float | None = None
    heldout_after_pct: float | None = None
    heldout_p_value: float | None = None
    relative_error_after_pct: float | None = None
    """The relative error (%) of the whole fit with the trends' columns (in sample)."""

    @property
    def found(self) -> bool:
        return bool(self.findings)

    @property
    def shape(self) -> str | None:
        return self.findings[0].shape if self.findings else None

    def estimates(self) -> dict[str, Estimate]:
        """The finding's reported values: per drifting coefficient its relative change, and the time constant or rate."""
        out: dict[str, Estimate] = {}
        for tr in self.findings:
            out[f"{tr.parameter}_start"] = Estimate(tr.start, None, "")
            out[f"{tr.parameter}_relative_change"] = Estimate(tr.relative_change, None, "")
            if tr.tau is not None:
                out[f"{tr.parameter}_tau"] = Estimate(tr.tau, None, "s")
            if tr.rate is not None:
                out[f"{tr.parameter}_rate"] = Estimate(tr.rate, None, "1/s")
        return out

    def plant_effect(self) -> dict[str, float] | None:
        """The ``friction_drift`` effect's plant parameters (``None`` without a finding, or with both shapes at once).

        The one-sided coefficients map to the symmetric change (the plant drifts both sides alike).
        """
        if not self.findings or len({tr.shape for tr in self.findings}) > 1:
            return None
        out = {"dFv": 0.0, "dFc": 0.0, "tau": 1.0, "Fv_rate": 0.0, "Fc_rate": 0.0}
        for tr in self.findings:
            kind = "Fv" if tr.parameter.startswith("Fv") else "Fc"
            if tr.shape == "exponential":
                assert tr.asymptote is not None and tr.tau is not None
                out[f"d{kind}"] = tr.asymptote - tr.start
                out["tau"] = tr.tau
            else:
                assert tr.rate is not None
                out[f"{kind}_rate"] = tr.rate
        return out

    def start_levels(self) -> dict[str, float]:
        """The drifting coefficients' levels at the log's start (the plant's base friction under :meth:`plant_effect`)."""
        return {tr.parameter: tr.start for tr in self.findings}

    def sentence(self) -> str:
        parts = []
        for tr in self.findings:
            what = f"{tr.parameter} {tr.relative_change * 100:+.3g} % ({tr.start:.4g} -> {tr.asymptote if tr.asymptote is not None else tr.end:.4g})"
            how = f"exponential, time constant {tr.tau:.3g} s" if tr.shape == "exponential" else f"linear, {tr.rate:+.3g} per s"
            parts.append(f"{what}, {how}")
        return "; ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        return {
            "found": self.found,
            "shape": self.shape,
            "findings": [t.to_dict() for t in self.findings],
            "trends": [t.to_dict() for t in self.trends],
            "windows": None if self.windows is None else self.windows.to_dict(),
            "reason": self.reason,
            "relative_error_after_pct": self.relative_error_after_pct,
            "heldout_relative_error_pct": None
            if self.heldout_before_pct is None
            else {"before": self.heldout_before_pct, "after": self.heldout_after_pct, "p_value": self.heldout_p_value},
            "settings": {
                "windows": WINDOWS if self.windows is None else len(self.windows.rows),
                "alpha": ALPHA,
                "shape_alpha": SHAPE_ALPHA,
                "min_change": MIN_CHANGE,
                "heldout_alpha": HELDOUT_ALPHA,
            },
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
            std[active] = np.sqrt(np.clip(np.diag(gls_covariance(Wk[:, active], yk, sol)), 0.0, None))
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


def _wls(X: np.ndarray, x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted least squares: coefficients and the weighted residual sum of squares."""
    sw = np.sqrt(w)
    c, *_ = np.linalg.lstsq(X * sw[:, None], x * sw, rcond=None)
    r = (x - X @ c) * sw
    return c, float(r @ r)


def tau_grid(duration: float, n_windows: int = WINDOWS) -> np.ndarray:
    """Time constants searched for a warm-up: from one window's duration (a shorter one is a single window's step,
    which the windows cannot tell from an outlier) to twice the log's."""
    return np.geomspace(duration / n_windows, 2.0 * duration, 40)


def fit_trend(parameter: str, t: np.ndarray, x: np.ndarray, s: np.ndarray, start: float, end: float, trials: int = 1, n_windows: int = WINDOWS) -> Trend | None:
    """The best trend of one coefficient's window estimates ``x`` (standard deviations ``s``) at times ``t``; ``None`` with too few windows.

    ``trials``: the Bonferroni factor of the test (coefficients x shapes).
    """
    k = len(t)
    if k < MIN_WINDOWS:
        return None
    w = 1.0 / np.square(s)
    tt = t - start
    one = np.ones(k)
    _, rss0 = _wls(one[:, None], x, w)
    lin, rss1 = _wls(np.c_[one, tt], x, w)
    best = None
    for tau in tau_grid(max(end - start, 1e-9), n_windows):
        c, rss = _wls(np.c_[one, np.exp(-tt / tau)], x, w)
        if best is None or rss < best[2]:
            best = (tau, c, rss)
    assert best is not None
    tau, cexp, rss2 = best
    duration = end - start

    def f_test(rss_small: float, rss_big: float, df1: int, df2: int) -> tuple[float, float]:
        if rss_big <= 0:
            return math.inf, 0.0
        F = max((rss_small - rss_big) / df1, 0.0) / (rss_big / df2)
        return F, float(f_sf(F, df1, df2))

    F_lin, p_lin = f_test(rss0, rss1, 1, k - 2)
    F_exp, p_exp = f_test(rss0, rss2, 2, k - 3)
    _, p_shape = f_test(rss1, rss2, 1, k - 3)
    exponential = p_shape < SHAPE_ALPHA and tau < duration
    if exponential:
        a, b = float(cexp[0]), float(cexp[1])
        F, df1, df2, p = F_exp, 2, k - 3, p_exp
        trend: tuple[float, float, float | None, float | None, float | None] = (a + b, a + b * math.exp(-duration / tau), a, float(tau), None)
    else:
        a, r = float(lin[0]), float(lin[1])
        F, df1, df2, p = F_lin, 1, k - 2, p_lin
        trend = (a, a + r * duration, None, None, r)
    test = FTest(float(F), df1, df2, float(p), trials, min(1.0, float(p) * trials), 0, math.nan, math.nan)
    return Trend(parameter, "exponential" if exponential else "linear", *trend, test, float(p_shape), k)


def drift_columns(t: np.ndarray, W: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float) -> np.ndarray:
    """The regressor columns of the trends: each drifting coefficient's column times its shape in time
    (``exp(-(t - start)/tau)`` or ``t - start``)."""
    cols = []
    for tr in trends:
        shape = np.exp(-(t - start) / tr.tau) if tr.tau is not None else t - start
        cols.append(W[:, names.index(tr.parameter)] * shape)
    return np.column_stack(cols) if cols else np.zeros((len(t), 0))


def heldout_check(
    t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float, folds: int | None = None, guard: int | None = None
) -> tuple[float, float, float]:
    """Held-out relative error (%) without and with the trends' columns over blocked folds in time, and the
    one-sided Diebold-Mariano p-value that they lower it (the selection's folds and guard by default)."""
    settings = SelectSettings()
    blocks = blocked_folds(len(y), folds or settings.folds, settings.guard if guard is None else guard)
    h0 = heldout_errors(W, y, blocks)
    W1 = np.c_[W, drift_columns(t, W, names, trends, start)]
    h1 = heldout_errors(W1, y, blocks)
    return relative_error_pct(y, y - h0), relative_error_pct(y, y - h1), float(diebold_mariano(h0, h1))


def relative_error_with(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float) -> float:
    """The relative error (%) of the least-squares fit of ``W`` with the trends' columns."""
    W1 = np.c_[W, drift_columns(t, W, names, trends, start)]
    theta, *_ = np.linalg.lstsq(W1, y, rcond=None)
    return relative_error_pct(y, W1 @ theta)


def _physical(tr: Trend) -> bool:
    """A friction coefficient's trend stays at or above zero over the log (and its warm-up's asymptote too)."""
    return min(tr.start, tr.end, tr.asymptote if tr.asymptote is not None else tr.end) >= 0.0


def detect_drift(
    t: np.ndarray,
    W: np.ndarray,
    y: np.ndarray,
    names: tuple[str, ...],
    *,
    n_windows: int = WINDOWS,
    alpha: float = ALPHA,
    min_change: float = MIN_CHANGE,
) -> DriftResult:
    """Friction drift in the IDIM system ``W theta = y`` (rows at times ``t``, sorted), as :class:`DriftResult`."""
    drifting = [n for n in names if n in DRIFTING]
    if not drifting or len(t) == 0:
        return DriftResult(None, reason="the model has no friction coefficient")
    win = estimable_windows(t, W, y, names, n_windows)
    n_windows = len(win.rows)
    trials = len(drifting) * len(SHAPES)
    trends = [tr for n in drifting if (tr := fit_trend(n, *win.series(n), win.start, win.end, trials, n_windows)) is not None]
    if not trends:
        return DriftResult(win, reason=f"fewer than {MIN_WINDOWS} of the {n_windows} windows have enough rows to estimate the friction")
    significant = [tr for tr in trends if tr.test.p_adjusted < alpha and _physical(tr)]
    unphysical = [tr for tr in trends if tr.test.p_adjusted < alpha and not _physical(tr)]
    material = sorted((tr for tr in significant if abs(tr.relative_change) >= min_change), key=lambda tr: tr.test.p_value)
    if material:
        before, after, p = heldout_check(t, W, y, names, material, win.start)
        if p < HELDOUT_ALPHA:
            return DriftResult(win, trends, material, "", before, after, p, relative_error_with(t, W, y, names, material, win.start))
        why = f"the trend of {material[0].parameter} does not lower the held-out error significantly ({before:.3g} % -> {after:.3g} %, p = {p:.2g})"
        return DriftResult(win, trends, [], why, before, after, p)
    if significant:
        tr = min(significant, key=lambda x: x.test.p_value)
        why = (
            f"a trend of {tr.parameter} is significant (p = {tr.test.p_adjusted:.2g}) "
            f"but moves it by {tr.relative_change * 100:+.2g} %, below {min_change * 100:g} %"
        )
    elif unphysical:
        tr = min(unphysical, key=lambda x: x.test.p_value)
        why = (
            f"the trend of {tr.parameter} (p = {tr.test.p_adjusted:.2g}) takes it below zero ({tr.start:.3g} -> {tr.end:.3g}): no friction, an outlying window"
        )
    else:
        tr = min(trends, key=lambda x: x.test.p_value)
        why = f"no trend across the windows is significant (smallest p = {tr.test.p_adjusted:.2g}, {tr.parameter}, against {alpha:g})"
    return DriftResult(win, trends, [], why)


def evaluation(result: DriftResult) -> Evaluation:
    """The evidence of a drift finding in the selection's terms (its strongest trend's test)."""
    tr = result.findings[0]
    return Evaluation(
        "friction_drift",
        tr.shape,
        None,
        tr.test,
        heldout_before_pct=result.heldout_before_pct,
        heldout_after_pct=result.heldout_after_pct,
        heldout_p_value=result.heldout_p_value,
        accepted=True,
        reason=f"a {tr.shape} trend of {tr.parameter} across {tr.windows} windows (F = {tr.test.F:.3g}, p = {tr.test.p_adjusted:.2g} after Bonferroni over "
        f"{tr.test.trials} trends, against the windows' scatter around it), and its columns lower the held-out error; not replayed",
    )


def with_drift(doc: dict[str, Any], result: DriftResult) -> dict[str, Any]:
    """The model file ``doc`` with the drift found: its friction at the log's start, and the ``friction_drift`` effect (unchanged without one)."""
    plant = result.plant_effect()
    if plant is None:
        return doc
    params = dict(doc["parameters"])
    for name, level in result.start_levels().items():
        if name in params:
            params[name] = level
    return {**doc, "parameters": params, "effects": {**doc.get("effects", {}), "friction_drift": plant}}
