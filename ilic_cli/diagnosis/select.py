"""Forward selection of catalogue effects on the IDIM least-squares problem.

Starting from the rigid model, every effect of the catalogue not yet in the
model is fitted (nonlinear parameter: grid, then 1-D refinement; the rest by
least squares on the decimated IDIM system, whose solver is unchanged) and
tested against the current model with a prewhitened nested F-test,
Bonferroni-corrected for the number of candidates and of grid points. The
most significant candidate is accepted only when it also lowers the error on
held-out data (blocked cross-validation over time, and the validation log
when one is given); the search stops when no candidate passes both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.baseline import reversal_samples
from ilic_cli.diagnosis.stats import FTest, batched_rss, blocked_folds, diebold_mariano, heldout_errors, lag1_autocorrelation, nested_f_test, shifted_rss
from ilic_cli.effects import EFFECTS, Effect, applicable, catalogue_ids
from ilic_cli.filtering import kept_indices
from ilic_cli.idim_ls import IDIMData, valid_rows
from ilic_cli.lsq import lstsq, relative_error_pct
from ilic_cli.regressor import Kinematics, Model

EXACT_GRID_MAX = 64
"""Grids up to this size are scanned with exactly decimated columns; larger
ones are screened on columns built from the decimated kinematics, and their
best minima re-evaluated exactly."""


@dataclass(frozen=True)
class SelectSettings:
    """Settings of the forward selection.

    Attributes
    ----------
    alpha : float
        Family-wise level of each step's F-test (after Bonferroni).
    alpha_heldout : float
        Level of the one-sided Diebold-Mariano test that the held-out
        errors drop.
    folds : int
        Contiguous cross-validation blocks over time.
    guard : int
        Decimated rows left out of training on each side of a test block.
    max_effects : int
        At most this many effects are added.
    effects : tuple of str
        Catalogue ids that may be added.
    """

    alpha: float = 0.001
    alpha_heldout: float = 0.01
    folds: int = 5
    guard: int = 10
    max_effects: int = 4
    effects: tuple[str, ...] = field(default_factory=catalogue_ids)

    def to_dict(self) -> dict[str, Any]:
        return {
            "alpha": self.alpha,
            "alpha_heldout": self.alpha_heldout,
            "folds": self.folds,
            "guard_rows": self.guard,
            "max_effects": self.max_effects,
            "effects": list(self.effects),
        }


@dataclass(frozen=True)
class Step:
    """An effect in the model with its nonlinear parameter fixed.

    ``level``: the effect's linear coefficients (its columns' order), held at
    these values instead of fitted: a closed-loop estimate the inverse model
    cannot make (:mod:`ilic_cli.diagnosis.dwell`); its columns' force is then
    taken off the fitted force (:func:`system`). ``level_std``: their standard
    deviations, when known; ``value_std``: the nonlinear value's, when it was
    estimated with the level.
    """

    effect: Effect
    value: Any = None
    level: tuple[float, ...] | None = None
    level_std: tuple[float, ...] | None = None
    value_std: float | None = None


def moving_rows(data: IDIMData) -> np.ndarray:
    """Decimated rows used by the diagnosis (boolean mask over ``data``'s rows).

    ``data``'s rows are already those every fit uses (:func:`ilic_cli.usable.with_rest`: no standstill, no
    saturated drive, the one definition ``identify`` uses too). Left out here, for the diagnosis's timing:
    mirroring the samples the procedure drops at the start, the rows within as many samples of either end of
    the trimmed record, where the zero-phase filters have their edge transients; and the rows whose decimation
    span touches a velocity reversal, where the Coulomb switch is timed only through the filtered velocity
    (:mod:`ilic_cli.diagnosis.baseline`). A run without dwells (the EMPS recordings) loses only those edge and
    reversal rows.
    """
    n = len(data.kin.qd)
    r = data.settings.decimation
    kept = kept_indices(n, r)
    edge = data.settings.trim
    moving = (kept >= edge) & (kept < n - edge) & valid_rows(~reversal_samples(data.kin.qd), r)
    return moving if data.rows is None else moving[data.rows]


def shifted_force(data: IDIMData, delay_s: float, *, remember: bool = True) -> np.ndarray:
    """Decimated force ``tau(t + delay)``: the plant's ``delay`` (logged force = applied force ``delay`` earlier)."""
    t = data.kin.t
    assert t is not None
    full = lambda: np.interp(t + delay_s, t, data.tau)  # noqa: E731
    return data.decimate_once(("shift", delay_s), full) if remember else data.decimate(full())


def effect_columns(data: IDIMData, effect: Effect, value: Any = None, *, remember: bool = True) -> np.ndarray:
    """Decimated columns of ``effect`` at ``value`` on ``data``.

    ``remember``: decimate each (effect, value) once on this data (the steps of
    the model and the linear effects, asked for at every step and fold); the
    values tried while refining a nonlinear parameter are not kept.
    """
    full = lambda: effect.matrix(data.kin, value, data.fs_hz)  # noqa: E731
    return data.decimate_once((effect.id, value), full) if remember else data.decimate(full())


def extended(base: Model, steps: list[Step] | tuple[Step, ...], fs_hz: float) -> Model:
    """The regressor of ``base`` plus the columns of ``steps`` (a time shift adds none, nor a step whose level is held)."""
    columns = [c for s in steps if s.level is None for c in s.effect.regressor_columns(s.value, fs_hz)]
    return base.extend(*columns, name=base.name + "".join(f"+{s.effect.id}" for s in steps)) if columns else base


def system(data: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...], rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The decimated system ``(W, y, names)`` of :func:`extended` ``(base, steps)`` on ``data``.

    ``data`` must have been prepared with ``base`` (its ``W`` holds the base
    columns, decimated once); each step's columns are decimated once on
    ``data`` (:func:`effect_columns`) and join them in the order of the
    extended model. ``rows`` (default :func:`moving_rows`) selects the rows.
    A step whose ``level`` is held adds no column: its force is taken off ``y``.
    """
    model = extended(base, steps, data.fs_hz)
    y = data.y
    cols = [data.W]
    for s in steps:
        if s.effect.shift:
            y = shifted_force(data, float(s.value or 0.0))
    for s in steps:
        if s.level is not None:
            y = y - effect_columns(data, s.effect, s.value) @ np.asarray(s.level, dtype=np.float64)
        elif not s.effect.shift:
            cols.append(effect_columns(data, s.effect, s.value))
    keep = moving_rows(data) if rows is None else rows
    W = np.hstack(cols)
    assert W.shape[1] == len(model.names)
    return W[keep], y[keep], model.names


@dataclass(frozen=True)
class SystemFit:
    """The least-squares fit of :func:`system` ``(data, base, steps, rows)``: the system and its estimate."""

    names: tuple[str, ...]
    theta: np.ndarray
    W: np.ndarray
    y: np.ndarray


def fit_system(data: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...], rows: np.ndarray | None = None, train: np.ndarray | None = None) -> SystemFit:
    """Fit ``base + steps`` on ``data``'s ``rows`` (default :func:`moving_rows`) by least squares, on ``train`` of them when given.

    The one inverse-model fit of the diagnosis (the IDIM estimate, eq. (8) of the
    paper, with the effect columns beside the rigid ones); ``W`` and ``y`` are
    the whole selected system, ``train`` or not.
    """
    W, y, names = system(data, base, steps, rows)
    sel = slice(None) if train is None else train
    theta, _ = lstsq(W[sel], y[sel])
    return SystemFit(names, theta, W, y)


@dataclass(frozen=True)
class Evaluation:
    """One candidate effect tried at one step of the selection."""

    effect: str
    value: Any
    value_std: float | None
    test: FTest
    relative_error_pct: float = float("nan")
    heldout_before_pct: float | None = None
    heldout_after_pct: float | None = None
    heldout_p_value: float | None = None
    validation_before_pct: float | None = None
    validation_after_pct: float | None = None
    accepted: bool = False
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "nonlinear_value": list(self.value) if isinstance(self.value, tuple) else self.value,
            "nonlinear_std": self.value_std,
            **self.test.to_dict(),
            "relative_error_pct": self.relative_error_pct,
            "heldout_relative_error_pct": {"before": self.heldout_before_pct, "after": self.heldout_after_pct},
            "heldout_test": None
            if self.heldout_p_value is None
            else {"test": "Diebold-Mariano, one-sided, Newey-West variance", "p_value": self.heldout_p_value},
            "validation_relative_error_pct": None
            if self.validation_before_pct is None
            else {"before": self.validation_before_pct, "after": self.validation_after_pct},
            "accepted": self.accepted,
            "reason": self.reason,
        }


HELDOUT_UNCONFIRMED = "does not lower the held-out error significantly"
"""The reason of a candidate whose F-test passed but whose held-out test did not confirm it."""


@dataclass
class SelectionResult:
    """Accepted steps in order, and every evaluation made on the way."""

    rows: np.ndarray | None = None
    steps: list[Step] = field(default_factory=list)
    accepted: list[Evaluation] = field(default_factory=list)
    tried: list[list[Evaluation]] = field(default_factory=list)

    def last_at(self, effect_id: str) -> tuple[int, int] | None:
        """Where in ``tried`` the last evaluation of ``effect_id`` is (round, position); ``None`` when it was never tried."""
        return next(((k, i) for k in reversed(range(len(self.tried))) for i, ev in enumerate(self.tried[k]) if ev.effect == effect_id), None)

    def last_word(self, effect_id: str) -> Evaluation | None:
        """The last evaluation of ``effect_id`` (``None`` when it was never tried)."""
        at = self.last_at(effect_id)
        return None if at is None else self.tried[at[0]][at[1]]

    def unconfirmed(self, effect_id: str) -> bool:
        """Whether the last evaluation of ``effect_id`` passed its F-test but not its held-out test (:data:`HELDOUT_UNCONFIRMED`)."""
        ev = self.last_word(effect_id)
        return ev is not None and ev.reason == HELDOUT_UNCONFIRMED


class Searcher:
    """Scans the nonlinear parameter of effects on one IDIM data set, with cached grid columns."""

    def __init__(self, data: IDIMData, fs_hz: float, rows: np.ndarray) -> None:
        self.data = data
        self.fs = fs_hz
        self.keep = rows
        k = data.kin
        dec = data.decimate
        self.kin_dec = Kinematics(qd=dec(k.qd), qdd=dec(k.qdd), q=None if k.q is None else dec(k.q), t=data.t_dec)
        self._cache: dict[str, tuple[np.ndarray, np.ndarray, bool]] = {}

    def grid(self, effect: Effect) -> tuple[np.ndarray, np.ndarray, bool]:
        """``(values, X, exact)``: X is ``(n, G, m)`` columns or, for a shift, ``(n, G)`` forces."""
        if effect.id in self._cache:
            return self._cache[effect.id]
        assert effect.scan is not None
        values = effect.scan.grid(self.data.kin, self.fs)
        if effect.shift:
            t = self.data.kin.t
            assert t is not None
            Y = np.stack([np.interp(t + v, t, self.data.tau) for v in values], axis=1)
            out = (values, self.data.decimate(Y)[self.keep], True)
        elif len(values) <= EXACT_GRID_MAX:
            full = np.concatenate([effect.matrix(self.data.kin, v, self.fs) for v in values], axis=1)
            m = full.shape[1] // len(values)
            out = (values, self.data.decimate(full)[self.keep].reshape(-1, len(values), m), True)
        else:
            X = np.stack([effect.matrix(self.kin_dec, v, self.fs)[self.keep] for v in values], axis=1)
            out = (values, X, False)
        self._cache[effect.id] = out
        return out

    def exact(self, effect: Effect, value: Any) -> np.ndarray:
        """Exactly decimated columns (or shifted force) for one value."""
        if effect.shift:
            return shifted_force(self.data, value, remember=False)[self.keep]
        return effect_columns(self.data, effect, value, remember=False)[self.keep]

    def exact_linear(self, effect: Effect) -> np.ndarray:
        """Decimated columns of an effect without a nonlinear parameter."""
        return effect_columns(self.data, effect)[self.keep]

    def rss(self, effect: Effect, W0: np.ndarray, y: np.ndarray, value: Any, rows: np.ndarray | slice = slice(None)) -> float:
        x = self.exact(effect, value)
        if effect.shift:
            return lstsq(W0[rows], x[rows])[1]
        return lstsq(np.hstack([W0, x])[rows], y[rows])[1]

    def scan(self, effect: Effect, W0: np.ndarray, y: np.ndarray, rows: np.ndarray | slice = slice(None), n_best: int = 3) -> float:
        """Best grid value of ``effect`` added to ``(W0, y)`` on ``rows``."""
        values, X, exact = self.grid(effect)
        if effect.shift:
            r = shifted_rss(W0[rows], X[rows])
        else:
            r = batched_rss(W0[rows], y[rows], X[rows])
        if exact:
            return float(values[int(np.argmin(r))])
        # local minima, best first, re-evaluated with exact columns
        interior = np.r_[True, r[1:] < r[:-1]] & np.r_[r[:-1] < r[1:], True]
        idx = np.flatnonzero(interior)
        if idx.size == 0:  # the minimum lies on a plateau (values whose columns coincide on these rows)
            idx = np.array([int(np.argmin(r))])
        idx = idx[np.argsort(r[idx])][:n_best]
        exact_rss = [self.rss(effect, W0, y, float(values[i]), rows) for i in idx]
        return float(values[idx[int(np.argmin(exact_rss))]])

    def refine(self, effect: Effect, W0: np.ndarray, y: np.ndarray, value: float, rows: np.ndarray | None = None) -> tuple[Any, float | None]:
        """1-D refinement between the neighbouring grid points; ``(value, std)`` from the RSS curvature.

        An effect with a secondary parameter gets it refined next (within its
        bounds), then the first again; its value is the pair. With ``rows``
        (a training set) only the value is refined (std ``None``).
        """
        assert effect.scan is not None
        sec = effect.scan.secondary
        sel = slice(None) if rows is None else rows
        values = self.grid(effect)[0]
        i = int(np.argmin(np.abs(values - value)))
        lo, hi = float(values[max(i - 1, 0)]), float(values[min(i + 1, len(values) - 1)])
        if lo == hi:
            return value, None
        use_log = effect.scan.log and lo > 0
        other = None if sec is None else sec[4]
        pack = (lambda v: v) if sec is None else (lambda v: (v, other))  # noqa: E731
        best = minimise(lambda v: self.rss(effect, W0, y, pack(v), sel), lo, hi, use_log)
        if sec is not None:
            other = minimise(lambda z: self.rss(effect, W0, y, (best, z), sel), sec[2], sec[3], True)
            best = minimise(lambda v: self.rss(effect, W0, y, (v, other), sel), lo, hi, use_log)
        if rows is not None:
            return pack(best), None
        # curvature of the profile RSS at the optimum, in the parameter's own unit
        h = 1e-3 * abs(best) if best != 0 else 1e-3 * (hi - lo)
        if effect.shift:
            h = max(h, 0.05 / self.fs)
        r0 = self.rss(effect, W0, y, pack(best))
        rp, rm = self.rss(effect, W0, y, pack(best + h)), self.rss(effect, W0, y, pack(best - h))
        curv = (rp - 2 * r0 + rm) / h**2
        n = len(y)
        k = W0.shape[1] + len(effect.columns) + 1
        x = self.exact(effect, pack(best))
        W1 = W0 if effect.shift else np.hstack([W0, x])
        y1 = x if effect.shift else y
        theta, _ = lstsq(W1, y1)
        rho = lag1_autocorrelation(y1 - W1 @ theta)
        inflation = (1 + max(rho, 0.0)) / (1 - min(max(rho, 0.0), 0.99))
        std = math.sqrt(2.0 * r0 / max(n - k, 1) * inflation / curv) if curv > 0 else None
        return pack(best), std


EDGE_STEPS = 0.5
"""A nonlinear estimate within this many grid steps of either end of its grid is on the edge of the search."""

SECONDARY_EDGE = 0.02
"""A secondary parameter within this share (on a log scale) of either bound is on the edge (e.g. damping 0.4998 of 0.5)."""


def at_edge(effect: Effect, grid: np.ndarray, value: Any) -> str | None:
    """Why ``value`` lies on the edge of ``effect``'s search (the grid's ends, the secondary parameter's bounds), else ``None``.

    The optimum of a search is only an estimate when the search brackets it:
    on an edge, the data would have gone on beyond the range searched.
    """
    assert effect.scan is not None
    scan = effect.scan
    first = float(value[0]) if isinstance(value, tuple) else float(value)
    if len(grid) >= 2:
        f = np.log if scan.log and grid[0] > 0 else (lambda x: x)  # noqa: E731
        lo_step, hi_step = f(grid[1]) - f(grid[0]), f(grid[-1]) - f(grid[-2])
        if f(first) <= f(grid[0]) + EDGE_STEPS * lo_step:
            return f"{scan.name} = {first:.4g} {scan.unit} at the lower end of the range searched ({grid[0]:.4g} to {grid[-1]:.4g})".replace("  ", " ")
        if f(first) >= f(grid[-1]) - EDGE_STEPS * hi_step:
            return f"{scan.name} = {first:.4g} {scan.unit} at the upper end of the range searched ({grid[0]:.4g} to {grid[-1]:.4g})".replace("  ", " ")
    if scan.secondary is not None and isinstance(value, tuple):
        name, _, low, high, _ = scan.secondary
        span = np.log(high) - np.log(low)
        second = float(value[1])
        if np.log(second) <= np.log(low) + SECONDARY_EDGE * span or np.log(second) >= np.log(high) - SECONDARY_EDGE * span:
            return f"{name} = {second:.4g} at a bound of the range searched ({low:g} to {high:g})"
    return None


SEARCH_STEPS: dict[str, int] = {"stribeck": 10, "delay": 4}
"""The effects whose nonlinear value the inverse model biases on closed-loop data, and the half-width of its closed-loop search.

In steps of the effect's own grid around the inverse model's value (default :data:`DEFAULT_STEPS`); used by
:mod:`ilic_cli.diagnosis.decide` (per fold) and :mod:`ilic_cli.diagnosis.refit`.

Origin (corpus, inverse model against truth): Stribeck ``vs`` off by a factor up to 2.6
(0.0211 for 0.008 m/s; the grid steps by a factor 1.126, so 10 steps reach a factor 3.3);
drive lags 0.3-0.7 ms too long (grid step 0.5 ms). Ripple periods and resonances were within
about a grid step; a payload's change time up to 4 steps off (11.64 s for 11.18 s), which 3 steps
bring to 11.32 s. A wider range lets the search wander into the aliases of a periodic ripple."""

DEFAULT_STEPS = 3
"""Half-width of the search for the effects not in :data:`SEARCH_STEPS` (grid steps)."""


def search_range(effect: Effect, grid: np.ndarray, value: float) -> np.ndarray:
    """The part of ``effect``'s grid the closed loop searches: :data:`SEARCH_STEPS` steps either side of ``value``."""
    k = SEARCH_STEPS.get(effect.id, DEFAULT_STEPS)
    i = int(np.argmin(np.abs(grid - value)))
    return grid[max(i - k, 0) : i + k + 1]


def minimise(f: Any, lo: float, hi: float, use_log: bool, rel_tol: float = 1e-4) -> float:
    """Bounded 1-D minimisation of ``f`` on ``[lo, hi]`` (on a log scale when ``use_log``), to ``rel_tol`` of the range on that scale."""
    from scipy.optimize import minimize_scalar  # deferred: scipy.optimize is slow to import

    fwd = math.log if use_log else (lambda v: v)
    inv = math.exp if use_log else (lambda u: u)
    a, b = fwd(lo), fwd(hi)
    res = minimize_scalar(lambda u: f(inv(u)), bounds=(a, b), method="bounded", options={"xatol": rel_tol * abs(b - a) + 1e-12})
    return float(inv(res.x))


def parsimonious_first(
    evals: list[tuple[Evaluation, Effect, np.ndarray, np.ndarray]], W: np.ndarray, y: np.ndarray, alpha: float
) -> list[tuple[Evaluation, Effect, np.ndarray, np.ndarray]]:
    """Put a linear candidate with fewer columns ahead of the best-fitting one when the latter adds nothing beyond it.

    Two linear effects can span nearly the same force over the range a log covers: gravity on a
    revolute joint, ``g (MX cos q - MY sin q)``, is a straight line in ``q`` plus a little curvature
    over a swing of less than a radian, which a spring (``k q``) also is. The two-column effect then
    always fits at least as well. When its columns, added to the model with the simpler effect, do
    not pass the nested F-test at ``alpha``, the data cannot tell them apart, and the simpler effect
    is proposed first (parsimony); where the swing shows the curvature the larger one stays first.
    """
    ok = [i for i, (ev, eff, _, _) in enumerate(evals) if not ev.reason and ev.test.p_adjusted < alpha]
    if not ok:
        return evals
    top_ev, top, W_top, _ = evals[ok[0]]
    if top.nonlinear or top.shift:
        return evals
    extra = W_top[:, W.shape[1] :]
    for i in ok[1:]:
        ev, eff, W_s, y_s = evals[i]
        if eff.nonlinear or eff.shift or len(eff.columns) >= len(top.columns):
            continue
        if nested_f_test(W_s, y, np.hstack([W_s, extra]), y, extra.shape[1]).p_value >= alpha:
            return [evals[i], *evals[:i], *evals[i + 1 :]]
    return evals


def forward_select(
    data: IDIMData,
    base: Model,
    fs_hz: float,
    settings: SelectSettings = SelectSettings(),
    *,
    validation: IDIMData | None = None,
    known: list[Step] | None = None,
) -> SelectionResult:
    """Add catalogue effects to ``base`` one at a time while they are significant and predict better.

    Parameters
    ----------
    data : IDIMData
        The fitting log, prepared with ``base`` (:func:`ilic_cli.idim_ls.lsq_rows`).
    base : Model
        The starting regressor.
    fs_hz : float
        Sampling frequency of the log.
    settings : SelectSettings
        Level, folds, candidates.
    validation : IDIMData, optional
        Another log prepared with ``base``: a candidate must not raise the
        error of the fitted model there.
    known : list of Step, optional
        Effects already in the model (from a model file): kept, not tried.
    """
    rows = moving_rows(data)
    searcher = Searcher(data, fs_hz, rows)
    out = SelectionResult(rows=rows)
    known = list(known or [])
    W, y, names = system(data, base, known, rows)
    folds = blocked_folds(len(y), settings.folds, settings.guard)
    while len(out.steps) < settings.max_effects:
        in_model = {s.effect.id for s in [*known, *out.steps]}
        cands = [EFFECTS[i] for i in settings.effects if i in EFFECTS and EFFECTS[i].identifiable and i not in in_model and applicable(EFFECTS[i], names)]
        if not cands:
            break
        trials_base = len(cands)
        evals: list[tuple[Evaluation, Effect, np.ndarray, np.ndarray]] = []
        for eff in cands:
            value, vstd = None, None
            if eff.nonlinear:
                value = searcher.scan(eff, W, y)
                value, vstd = searcher.refine(eff, W, y, value)
            # Bonferroni over the candidates and, for a searched parameter, its grid points (a shift's too)
            trials = trials_base * (len(searcher.grid(eff)[0]) if eff.nonlinear else 1)
            if eff.shift:
                W1, y1, q = W, searcher.exact(eff, value), 1
            else:
                W1 = np.hstack([W, searcher.exact(eff, value) if eff.nonlinear else searcher.exact_linear(eff)])
                # a secondary nonlinear parameter is one more degree of freedom
                y1, q = y, len(eff.columns) + (1 if eff.scan is not None and eff.scan.secondary else 0)
            test = nested_f_test(W, y, W1, y1, q, trials)
            theta1, _ = lstsq(W1, y1)
            rel = relative_error_pct(y1, W1 @ theta1)
            why = eff.impossible(theta1[W.shape[1] :], value) if eff.impossible is not None else None
            if why:
                why = f"physically impossible: {why}"
            elif eff.nonlinear:
                edge = at_edge(eff, searcher.grid(eff)[0], value)
                why = f"at the edge of its search range: {edge}" if edge else None
            evals.append((Evaluation(eff.id, value, vstd, test, rel, reason=why or ""), eff, W1, y1))
        # the candidate explaining most of the mismatch first; significance and held-out error gate it
        evals.sort(key=lambda e: e[0].relative_error_pct)
        evals = parsimonious_first(evals, W, y, settings.alpha)
        tried: list[Evaluation] = []
        chosen = None
        for ev, eff, W1, y1 in evals:
            if ev.reason:  # impossible physics, or an estimate on the edge of its search range: never a finding
                tried.append(ev)
                continue
            if chosen is not None or ev.test.p_adjusted >= settings.alpha:
                reason = "not significant" if ev.test.p_adjusted >= settings.alpha else "another effect was accepted first"
                tried.append(_replace(ev, reason=reason))
                continue
            e_before = heldout_errors(W, y, folds)
            e_after = _heldout_candidate(searcher, eff, W, y, folds)
            before, after = relative_error_pct(y, y - e_before), relative_error_pct(y, y - e_after)
            p_cv = diebold_mariano(e_before, e_after)
            vb = va = None
            if validation is not None:
                vb = validation_error(data, validation, base, [*known, *out.steps])
                va = validation_error(data, validation, base, [*known, *out.steps, Step(eff, ev.value)])
            if not after < before or p_cv >= settings.alpha_heldout:
                ok, reason = False, HELDOUT_UNCONFIRMED
            elif va is not None and vb is not None and va > vb:
                ok, reason = False, "raises the error on the validation log"
            else:
                ok, reason = True, "significant, and lowers the held-out error"
            ev = _replace(
                ev,
                heldout_before_pct=before,
                heldout_after_pct=after,
                heldout_p_value=p_cv,
                validation_before_pct=vb,
                validation_after_pct=va,
                accepted=ok,
                reason=reason,
            )
            tried.append(ev)
            if ok:
                chosen = (ev, eff, W1, y1)
        out.tried.append(tried)
        if chosen is None:
            break
        ev, eff, W, y = chosen
        out.steps.append(Step(eff, ev.value))
        out.accepted.append(ev)
        names = names + eff.column_names
    return out


def _replace(ev: Evaluation, **kw: Any) -> Evaluation:
    return replace(ev, **kw)


def _heldout_candidate(searcher: Searcher, eff: Effect, W: np.ndarray, y: np.ndarray, folds: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Held-out errors of the model with ``eff``, its nonlinear parameter searched on each training set."""
    out = np.full(len(y), np.nan)
    for train, test in folds:
        if eff.nonlinear:
            v = searcher.scan(eff, W, y, rows=train)
            v, _ = searcher.refine(eff, W, y, v, rows=train)
            x = searcher.exact(eff, v)
        else:
            x = searcher.exact_linear(eff)
        if eff.shift:
            W1, y1 = W, x
        else:
            W1, y1 = np.hstack([W, x]), y
        theta, _ = lstsq(W1[train], y1[train])
        out[test] = y1[test] - W1[test] @ theta
    return out


def validation_error(data: IDIMData, validation: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...]) -> float:
    """Relative error (%) on ``validation`` of the model ``base + steps`` fitted on ``data``."""
    theta = fit_system(data, base, steps).theta
    Wv, yv, _ = system(validation, base, steps)
    return relative_error_pct(yv, Wv @ theta)
