"""Parameters that change over time: friction that drifts, tested on every row, shown per window (issue 29, item 5).

Pure functions on arrays. A friction coefficient (``Fv``, ``Fc`` and their
one-sided forms) that changes over the run is a column of the IDIM system
times a shape in time, added to the model:

* ``exponential``: ``x(t) = a + b exp(-(t - t0)/tau)``, a warm-up (``tau`` searched on :func:`tau_grid`, then refined);
* ``linear``: ``x(t) = a + r (t - t0)``, a wear;

``t0`` the log's first sample (the plant's drift starts there, as a payload's change time does).

The trend is tested on all the rows at once, as a catalogue effect's columns are: the nested F-test of the
model with the trend's column against the model without it, on the AR-prewhitened system
(:func:`ilic_cli.diagnosis.stats.nested_f_test`, one degree of freedom more for the searched time constant),
Bonferroni over the coefficients and the shapes' grid (:func:`trials`). The trends are added one at a time,
the most significant first, each tested given those before it (forward selection): a drift of ``Fv`` alone also
moves ``Fc``'s trend column, which is then not significant beyond ``Fv``'s. Before, the test compared ten
per-window estimates with a constant: with 30-90 rows a window, a window that moves in one direction only
cannot tell ``Fv`` from ``Fc`` and its estimates scatter by tens of per cent, so a 40 % wear of ``Fc`` on a
10 s log was not significant (p = 1; the robot corpus named 5 of 12 drift logs, 12 of 12 on all rows).

The exponential shape is named when it fits better than the straight line by the whitened system's BIC (its
time constant is a parameter more) and its time constant is shorter than the log; else the drift is linear.

A trend is a finding when it passes at :data:`ALPHA`, moves the coefficient by at least :data:`MIN_CHANGE` of
its level over the log, keeps a Coulomb level at or above zero (as the plant does), and its columns lower the held-out error of
blocked cross-validation over time, as a catalogue effect's do (Diebold-Mariano at the selection's level).

The per-window estimates (every parameter estimated on each of :data:`WINDOWS` windows of equal duration,
IDIM-ILIC's picture of a non-stationary axis) are reported beside the finding: they show the drift, they do
not decide it. A step in the mass (``payload_change``) moves the windows' ``M``, and is the catalogue's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.diagnosis.drift_alike import Alike, alike
from ilic_cli.diagnosis.drift_windows import WINDOWS, WindowEstimates, estimable_windows
from ilic_cli.diagnosis.select import Evaluation, SelectSettings
from ilic_cli.diagnosis.stats import FTest, blocked_folds, gls_covariance, heldout_errors, heldout_fall_p, nested_f_test
from ilic_cli.effects import Estimate
from ilic_cli.lm import minimise
from ilic_cli.lsq import finite_or_none, lstsq, relative_error_pct

ALPHA = 1e-3
"""Level of the test of a trend on the rows (after Bonferroni over the coefficients and the shapes' grid: :func:`trials`)."""

TAUS = 12
"""Time constants of a warm-up searched (:func:`tau_grid`) before the best is refined; each counts as a trial of the test."""

MIN_CHANGE = 0.05
"""Smallest change of a coefficient over the log, relative to its level at the start, that is a finding."""

HELDOUT_ALPHA = 0.01
"""Level of the held-out check: the trend's columns must lower the blocked cross-validation error (Diebold-Mariano). Stricter
than a catalogue effect's proposal (:attr:`~ilic_cli.diagnosis.select.SelectSettings.alpha_heldout`, 0.05): the drift is sought
first, on the rigid model, and its columns are given to every candidate after it, so a trend that is another effect's trace
takes that effect's place (corpus rev0.5 s931, an asymmetric friction on an 8 kHz S-curve: at 0.05 a drift of Fv was named
instead, and the replay, which carries the drift, could not tell)."""

DRIFTING = ("Fv", "Fc", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg")
"""The friction coefficients whose drift is sought (those of the model)."""

SHAPES = ("exponential", "linear")
"""The shapes of a drift."""


@dataclass(frozen=True)
class Trend:
    """The trend of one coefficient in its best shape, and its test on the rows against a constant level.

    ``start``/``end``: the trend's value at the log's first sample and at its last row; ``change``: ``end - start``;
    ``asymptote``: the exponential's ``a`` (its level once warm), else ``None``; ``tau``: its time
    constant (s), else ``None``; ``rate``: the straight line's slope (per s), else ``None``;
    ``shape_delta_bic``: the exponential's whitened BIC minus the line's (negative favours the exponential).
    """

    parameter: str
    shape: str
    start: float
    end: float
    asymptote: float | None
    tau: float | None
    rate: float | None
    test: FTest
    shape_delta_bic: float | None
    rows: int
    std: dict[str, float] = field(default_factory=dict)
    """Standard deviations of ``start``, ``full_change``, ``relative_change`` and ``tau`` or ``rate`` (:func:`estimated`, keys
    ``start``, ``change``, ...); empty: none."""

    @property
    def change(self) -> float:
        return self.end - self.start

    @property
    def full_change(self) -> float:
        """The warm-up's whole change for an exponential (the plant's ``dFv``/``dFc``), the change over the log for a line."""
        return (self.asymptote - self.start) if self.asymptote is not None else self.change

    @property
    def relative_change(self) -> float:
        """:attr:`full_change` relative to the level at the start."""
        return self.full_change / abs(self.start) if self.start != 0 else math.inf

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
            "test": {**_finite(self.test.to_dict()), "rows": "every row, with the trends found before it in the model"},
            "exponential_vs_linear_delta_bic": None if self.shape_delta_bic is None else finite_or_none(self.shape_delta_bic),
            "rows": self.rows,
        }


def _finite(d: dict[str, Any]) -> dict[str, Any]:
    return {k: finite_or_none(v) if isinstance(v, float) else v for k, v in d.items()}


@dataclass(frozen=True)
class DriftResult:
    """What the rows say of parameters that change over time, and the per-window estimates that show it.

    ``trends``: every drifting coefficient's best trend alone; ``findings``: the trends kept by the forward selection
    that are material, estimated together, strongest first; ``reason``: why there is no finding (empty when there is one).
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
    alike: Alike | None = None
    """The coefficient whose trend the rows cannot tell from the finding's (:func:`ilic_cli.diagnosis.drift_alike.alike`)."""

    @property
    def found(self) -> bool:
        return bool(self.findings)

    @property
    def shape(self) -> str | None:
        return self.findings[0].shape if self.findings else None

    def estimates(self, joint: str = "prismatic") -> dict[str, Estimate]:
        """The finding's reported values, per drifting coefficient: its level at the start, its change (:attr:`Trend.full_change`,
        the plant's) and that change relative to the start, and the time constant or rate; in the coefficient's units on ``joint``."""
        out: dict[str, Estimate] = {}
        for tr in self.findings:
            u = parameters.unit(tr.parameter, joint)
            out[f"{tr.parameter}_start"] = Estimate(tr.start, tr.std.get("start"), u)
            out[f"{tr.parameter}_change"] = Estimate(tr.full_change, tr.std.get("change"), u)
            out[f"{tr.parameter}_relative_change"] = Estimate(tr.relative_change, tr.std.get("relative_change"), "")
            if tr.tau is not None:
                out[f"{tr.parameter}_tau"] = Estimate(tr.tau, tr.std.get("tau"), "s")
            if tr.rate is not None:
                out[f"{tr.parameter}_rate"] = Estimate(tr.rate, tr.std.get("rate"), parameters.per_second(u))
        return out

    def plant_effect(self) -> dict[str, float] | None:
        """The ``friction_drift`` effect's plant parameters (``None`` without a finding).

        A warm-up sets ``dFv``/``dFc`` and the shared ``tau``, a wear ``Fv_rate``/``Fc_rate`` (the plant has both at once).
        The one-sided coefficients map to the symmetric change (the plant drifts both sides alike).
        """
        if not self.findings:
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
            "alike": None if self.alike is None else self.alike.to_dict(),
            "relative_error_after_pct": self.relative_error_after_pct,
            "heldout_relative_error_pct": None
            if self.heldout_before_pct is None
            else {"before": self.heldout_before_pct, "after": self.heldout_after_pct, "p_value": self.heldout_p_value},
            "settings": {
                "windows": WINDOWS if self.windows is None else len(self.windows.rows),
                "alpha": ALPHA,
                "time_constants_searched": TAUS,
                "min_change": MIN_CHANGE,
                "heldout_alpha": HELDOUT_ALPHA,
            },
        }


def tau_grid(duration: float, n: int = TAUS) -> np.ndarray:
    """Time constants searched for a warm-up: from a tenth of the log (shorter, the warm-up is over in its first rows,
    a step the rows hardly tell from an offset) to twice the log (longer, it is a straight line over the log)."""
    return np.geomspace(duration / 10.0, 2.0 * duration, n)


def trials(n_coefficients: int, n_taus: int = TAUS) -> int:
    """The Bonferroni factor of the trend's test: per coefficient, the line and each time constant of the grid."""
    return n_coefficients * (1 + n_taus)


@dataclass(frozen=True)
class Candidate:
    """One coefficient's trend column in its best shape, tested given the model ``W_now`` it would join."""

    parameter: str
    shape: str
    tau: float | None
    column: np.ndarray
    test: FTest
    shape_delta_bic: float


def _warm_up_tau(t: np.ndarray, W_now: np.ndarray, y: np.ndarray, col: np.ndarray, origin: float, duration: float) -> float:
    """The time constant whose exponential column fits best: the grid's best, refined between its neighbours."""
    grid = tau_grid(duration)

    def rss(tau: float) -> float:
        return lstsq(np.c_[W_now, col * np.exp(-(t - origin) / tau)], y)[1]

    i = int(np.argmin([rss(tau) for tau in grid]))
    return minimise(rss, float(grid[max(i - 1, 0)]), float(grid[min(i + 1, len(grid) - 1)]), use_log=True, rel_tol=1e-3)


def candidate(
    t: np.ndarray, W_now: np.ndarray, y: np.ndarray, col: np.ndarray, parameter: str, origin: float, n_trials: int, tau: float | None = None
) -> Candidate:
    """The trend of the coefficient of column ``col`` added to ``W_now``: a line and a warm-up (``tau`` given, or searched),
    the shape of the lower whitened BIC (the exponential only if its time constant is shorter than the log), tested."""
    duration = max(float(t[-1]) - origin, 1e-9)
    x_lin = col * (t - origin)
    tau = _warm_up_tau(t, W_now, y, col, origin, duration) if tau is None else tau
    x_exp = col * np.exp(-(t - origin) / tau)
    lin = nested_f_test(W_now, y, np.c_[W_now, x_lin], y, 1, n_trials)
    exp = nested_f_test(W_now, y, np.c_[W_now, x_exp], y, 2, n_trials)
    dbic = exp.delta_bic - lin.delta_bic
    if dbic < 0 and tau < duration:
        return Candidate(parameter, "exponential", float(tau), x_exp, exp, float(dbic))
    return Candidate(parameter, "linear", None, x_lin, lin, float(dbic))


def select_trends(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], origin: float, alpha: float) -> tuple[list[Candidate], list[Candidate]]:
    """Forward selection of the trends: each round, every coefficient left is tried given the trends kept, and the most
    significant is kept while it passes ``alpha`` (after Bonferroni). A second warm-up shares the first's time constant
    (one temperature). ``(kept, first round)``: the first round is every coefficient's trend alone."""
    drifting = [n for n in names if n in DRIFTING]
    n_trials = trials(len(drifting))
    kept: list[Candidate] = []
    first: list[Candidate] = []
    W_now = W
    while len(kept) < len(drifting):
        tau = next((c.tau for c in kept if c.tau is not None), None)
        tried = [candidate(t, W_now, y, W[:, names.index(n)], n, origin, n_trials, tau) for n in drifting if n not in {c.parameter for c in kept}]
        first = first or tried
        best = min(tried, key=lambda c: c.test.p_value)
        if best.test.p_adjusted >= alpha:
            break
        kept.append(best)
        W_now = np.c_[W_now, best.column]
    return kept, first


def estimated(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], chosen: list[Candidate], origin: float) -> list[Trend]:
    """The trends of ``chosen`` estimated together with every parameter of the model, on all the rows."""
    if not chosen:
        return []
    X = np.c_[W, np.column_stack([c.column for c in chosen])]
    theta, _ = lstsq(X, y)
    duration = float(t[-1]) - origin
    # the covariance of every coefficient and each warm-up's time constant: the time constant's column is the derivative of
    # b col exp(-s / tau) in tau at the optimum, b (the trend's column) s / tau^2 (the fit's linearisation), the residual's
    # autocorrelation accounted for
    d_tau = [float(theta[W.shape[1] + i]) * c.column * (t - origin) / c.tau**2 for i, c in enumerate(chosen) if c.tau is not None]
    J = np.c_[X, np.column_stack(d_tau)] if d_tau else X
    cov = gls_covariance(J, y, np.r_[theta, np.zeros(len(d_tau))])
    out = []
    k_tau = X.shape[1]
    for i, c in enumerate(chosen):
        ia, ib = names.index(c.parameter), W.shape[1] + i
        a, b = float(theta[ia]), float(theta[ib])
        C = cov[np.ix_([ia, ib], [ia, ib])]
        std_b = math.sqrt(max(float(C[1, 1]), 0.0))
        if c.tau is not None:
            shape: tuple[float, float, float | None, float | None, float | None] = (a + b, a + b * math.exp(-duration / c.tau), a, c.tau, None)
            # start a + b, relative change -b / |a + b|
            start_grad, rel_grad = np.array([1.0, 1.0]), np.array([b, -a]) * np.sign(a + b) / (a + b) ** 2
            # the warm-up's whole change is -b
            last = {"change": std_b, "tau": math.sqrt(max(float(cov[k_tau, k_tau]), 0.0))}
            k_tau += 1
        else:
            shape = (a, a + b * duration, None, None, b)
            # start a, relative change b duration / |a|
            start_grad, rel_grad = np.array([1.0, 0.0]), np.array([-b * duration, a * duration]) * np.sign(a) / a**2
            last = {"change": duration * std_b, "rate": std_b}
        std = {"start": math.sqrt(max(float(start_grad @ C @ start_grad), 0.0)), "relative_change": math.sqrt(max(float(rel_grad @ C @ rel_grad), 0.0)), **last}
        out.append(Trend(c.parameter, c.shape, *shape, c.test, c.shape_delta_bic, len(y), std))
    return out


def drift_columns(t: np.ndarray, W: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float) -> np.ndarray:
    """The regressor columns of the trends: each drifting coefficient's column times its shape in time
    (``exp(-(t - start)/tau)`` or ``t - start``)."""
    cols = []
    for tr in trends:
        shape = np.exp(-(t - start) / tr.tau) if tr.tau is not None else t - start
        cols.append(W[:, names.index(tr.parameter)] * shape)
    return np.column_stack(cols) if cols else np.zeros((len(t), 0))


@dataclass(frozen=True)
class GivenDrift:
    """A friction drift found on the rigid model and given to every later fit (:func:`ilic_cli.diagnosis.propose.drift_given`): its
    trends and their origin, the log's first sample."""

    trends: list[Trend]
    origin: float

    def columns(self, t: np.ndarray, W: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
        """The trends' columns on the rows of ``W`` at times ``t`` (:func:`drift_columns`)."""
        return drift_columns(t, W, names, self.trends, self.origin)

    def plant(self, rigid: dict[str, float], effects: dict[str, Any], coefficients: np.ndarray) -> tuple[dict[str, float], dict[str, Any]]:
        """The plant of a fit with the trends' columns (their ``coefficients``): each drifting coefficient at the log's start and the
        ``friction_drift`` effect (as :meth:`DriftResult.plant_effect`): an exponential's level ``a + b exp(-(t - t0)/tau)`` starts
        at ``a + b`` and changes by ``-b``; a line's starts at ``a`` at the rate of its coefficient."""
        rigid, drift = dict(rigid), {"dFv": 0.0, "dFc": 0.0, "tau": 1.0, "Fv_rate": 0.0, "Fc_rate": 0.0}
        for tr, c in zip(self.trends, coefficients, strict=True):
            kind = "Fv" if tr.parameter.startswith("Fv") else "Fc"
            if tr.tau is not None:
                if tr.parameter in rigid:
                    rigid[tr.parameter] += float(c)
                drift[f"d{kind}"], drift["tau"] = -float(c), tr.tau
            else:
                drift[f"{kind}_rate"] = float(c)
        return rigid, {**effects, "friction_drift": drift}


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
    return relative_error_pct(y, y - h0), relative_error_pct(y, y - h1), float(heldout_fall_p(h0, h1))


def fitted_with(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float) -> np.ndarray:
    """The force of the least-squares fit of ``y`` on ``W`` with the trends' columns."""
    W1 = np.c_[W, drift_columns(t, W, names, trends, start)]
    theta, *_ = np.linalg.lstsq(W1, y, rcond=None)
    return W1 @ theta


def relative_error_with(t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], trends: list[Trend], start: float) -> float:
    """The relative error (%) of the least-squares fit of ``W`` with the trends' columns (:func:`fitted_with`)."""
    return relative_error_pct(y, fitted_with(t, W, y, names, trends, start))


def _physical(tr: Trend) -> bool:
    """A Coulomb level's trend stays at or above zero over the log (and its warm-up's asymptote too), as the plant keeps it
    (:func:`ilic_cli.effects.drift_of`); a viscous coefficient's may cross it (the plant's law lets it)."""
    return not tr.parameter.startswith("Fc") or min(tr.start, tr.end, tr.asymptote if tr.asymptote is not None else tr.end) >= 0.0


def _stated(tr: Trend, min_change: float) -> bool:
    """A trend a finding may state: physical (:func:`_physical`), and moving its coefficient by at least ``min_change``."""
    return _physical(tr) and abs(tr.relative_change) >= min_change


def _why_not(trends: list[Trend], alone: list[Trend], alpha: float, min_change: float) -> str:
    """Why the significant trends (``trends``) or, without one, the trends alone (``alone``) are no finding."""
    unphysical = [tr for tr in trends if not _physical(tr)]
    if unphysical:
        tr = unphysical[0]
        return f"the trend of {tr.parameter} (p = {tr.test.p_adjusted:.2g}) takes it below zero ({tr.start:.3g} -> {tr.end:.3g}): no Coulomb friction"
    if trends:
        tr = trends[0]
        moved = f"{tr.relative_change * 100:+.2g} %"
        return f"a trend of {tr.parameter} is significant (p = {tr.test.p_adjusted:.2g}) but moves it by {moved}, below {min_change * 100:g} %"
    tr = min(alone, key=lambda x: x.test.p_value)
    return f"no trend on the rows is significant (smallest p = {tr.test.p_adjusted:.2g}, {tr.parameter}, against {alpha:g})"


def detect_drift(
    t: np.ndarray,
    W: np.ndarray,
    y: np.ndarray,
    names: tuple[str, ...],
    *,
    origin: float | None = None,
    n_windows: int = WINDOWS,
    alpha: float = ALPHA,
    min_change: float = MIN_CHANGE,
    nuisance: np.ndarray | None = None,
) -> DriftResult:
    """Friction drift in the IDIM system ``W theta = y`` (rows at times ``t``, sorted; ``origin``: the log's first sample,
    by default the first row), as :class:`DriftResult`. ``nuisance``: columns fitted beside the model in every test and
    estimate of a trend, never drifting themselves (static effects the model leaves out:
    :func:`ilic_cli.diagnosis.propose.static_linear`); the windows' estimates and the error reported are the model's own."""
    if not any(n in DRIFTING for n in names) or len(t) == 0:
        return DriftResult(None, reason="the model has no friction coefficient")
    origin = float(t[0]) if origin is None else float(origin)
    win = estimable_windows(t, W, y, names, n_windows)
    W_own, names_own = W, names
    if nuisance is not None and nuisance.shape[1]:
        W, names = np.c_[W, nuisance], (*names, *(f"static {i}" for i in range(nuisance.shape[1])))
    chosen, first = select_trends(t, W, y, names, origin, alpha)
    alone = [tr for c in first for tr in estimated(t, W, y, names, [c], origin)]
    trends = estimated(t, W, y, names, chosen, origin)
    kept = [c for c, tr in zip(chosen, trends, strict=True) if _stated(tr, min_change)]
    if not kept:
        return DriftResult(win, alone, [], _why_not(trends, alone, alpha, min_change))
    findings = estimated(t, W, y, names, kept, origin)
    before, after, p = heldout_check(t, W, y, names, findings, origin)
    if p >= HELDOUT_ALPHA:
        why = f"the trend of {findings[0].parameter} does not lower the held-out error significantly ({before:.3g} % -> {after:.3g} %, p = {p:.2g})"
        return DriftResult(win, alone, [], why, before, after, p)
    others = [
        (c.parameter, c.column, c.test.df1)
        for c, tr in zip(first, alone, strict=True)
        if c.parameter != kept[0].parameter and c.test.p_adjusted < alpha and _stated(tr, min_change)
    ]
    same = alike(W, y, (kept[0].column, kept[0].test.df1), others, trials(sum(n in DRIFTING for n in names)), alpha) if len(kept) == 1 else None
    return DriftResult(win, alone, findings, "", before, after, p, relative_error_with(t, W_own, y, names_own, findings, origin), same)


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
        reason=f"a {tr.shape} trend of {tr.parameter} on the {tr.rows} rows (F = {tr.test.F:.3g}, p = {tr.test.p_adjusted:.2g} after Bonferroni over "
        f"{tr.test.trials} trends, on the prewhitened system), and its columns lower the held-out error; not replayed"
        + ("" if result.alike is None else f"; {result.alike.words(tr.parameter)}"),
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
