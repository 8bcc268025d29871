"""The closed-loop refit of the effects the replay kept (issue #11 item 3): DIDIM with their columns, their nonlinear parameters searched.

The inverse model (:mod:`ilic_cli.diagnosis.select`) fits an effect on the
filtered kinematics of the measured position. On closed-loop data that is
biased: the command answers the position noise and the disturbance the
filtered kinematics carry, so an effect whose column correlates with them
comes out off (measured on the corpus: a drive lag 30-66 % too long, a
Stribeck level 46 % and 163 % off on the EMPS reference). The closed-loop
output error has no such bias: the recorded reference is replayed through the
log's controller and the plant of the estimate, and the simulated force is
compared with the recorded one (DIDIM, :mod:`ilic_cli.closed_loop_id`).

Once the replay has decided which effects are findings
(:mod:`ilic_cli.diagnosis.decide`), the final model (rigid columns, the
effects' columns) is refitted so:

1. **DIDIM at the inverse model's nonlinear values**
   (:func:`ilic_cli.closed_loop_id.closed_loop_identify`). When it does not
   lower the closed-loop output error below the inverse model's, nothing is
   refitted: DIDIM's step takes the regressor of the simulated states for the
   sensitivity of the simulated force, which the loop's answer to an effect
   near or above its bandwidth does not follow (measured: DATA_EMPS with
   asymmetric friction and ripple, 4.99 % -> 5.05 %; 8 of the corpus's 29 logs
   with a finding).
2. **Each nonlinear parameter** (Stribeck ``vs``, ripple period ``L``,
   resonance ``f_res`` then its damping ratio, payload change time, delay), in
   the order the effects were kept, is searched on the closed-loop output
   error, a bounded scalar search within :data:`SEARCH_STEPS` steps of the
   effect's own grid around the inverse model's value (the damping ratio
   within its bounds). At each value the linear parameters are one DIDIM
   Gauss-Newton step from the current estimate (one replay per value; the
   profile is the step's predicted output error). Measured on the Stribeck
   EMPS-reference log: the same optimum as DIDIM iterated to convergence at
   each value (vs = 12 mm/s, 3 replays per value), at a third of the cost.
   An optimum on the edge of the range searched, or one that does not lower
   the error, keeps the inverse model's value and says so.
   With more than one value, the round of searches is repeated while it
   lowers the error by more than :data:`ROUND_GAIN` (the values couple:
   :func:`_search_all`).
3. **DIDIM at the values found**, kept when its output error is below that of
   step 1 (else step 1's estimate, at the inverse model's values).

When DIDIM does not lower the output error (step 1), the output error itself
is minimised (:data:`OE_METHOD`, :func:`output_error_gauss_newton`): the
linear parameters and every searched value of the kept effects at once, by
Levenberg-Marquardt with the closed loop's own sensitivities, taken by finite
differences of replays (one replay per parameter and step). Measured on the
corpus's Stribeck + flexibility reseed s303@s2303, where DIDIM's step raises
the error (0.845 % -> 0.998 %): 0.704 % in 1 iteration and 22 replays, the
Stribeck level 3.40 N for 3.53 (the folds' 2.32 N), ``vs`` 8.35 mm/s for 8,
the resonance 35.04 Hz for 35.00 and its damping ratio 0.155 for 0.150. It is
kept when it lowers the output error by :data:`ROUND_GAIN` of it, no value
ends on the edge of its search range, and the diagnosis's ``confirm`` (the
output error replayed with the recording's sensor noise) does not refuse it
(on ``DATA_EMPS.mat`` its first step is predicted to gain less than 1 %, and
no step is tried: 9 replays; on the corpus's trapezoids it lowers the
noise-free error, 1.64 % -> 1.39 % on a clean one with the current loop, by
fitting what the noise drives at the dwells, and the noisy replay refuses
it, 0.869 % -> 1.3 %). Otherwise the values the inverse model is known to bias
(:data:`SEARCH_STEPS`: Stribeck ``vs``, a delay) are still searched on the
closed loop, the linear parameters then the inverse model's fit at each value
(one replay per value; :data:`INVERSE_METHOD`), and that estimate is kept when
it lowers the output error.

The estimate is **accepted** only when every effect stays a valid plant of
the physics it is named (a load fraction in (0, 1), a Stribeck level above 0
and above ``-Fc``, ...) and DIDIM did not fail; otherwise the inverse model's
estimates are kept and the reason is given. The standard deviations are
those of the final DIDIM step's regressor, with the residual's
autocorrelation accounted for as in the inverse model's
(:func:`ilic_cli.diagnosis.stats.gls_covariance`); a searched value's, from
the curvature of the profile.

Pure numerics on run logs in memory: no file I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from ilic_cli.closed_loop_id import ClosedLoopResult, closed_loop_identify, plant_of
from ilic_cli.diagnosis.segments import SegmentFit
from ilic_cli.diagnosis.select import SEARCH_STEPS, Step, at_edge, extended, search_range
from ilic_cli.diagnosis.stats import gls_covariance, lag1_autocorrelation
from ilic_cli.effects import Fit
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.idim_ls import LSSettings, lsq_rows
from ilic_cli.lsq import finite_or_none, lstsq
from ilic_cli.parallel import ordered_map
from ilic_cli.prepare import PreparedLog
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import replay

METHOD = "DIDIM closed-loop refit"
"""The method the findings and the model file name when the refit is accepted."""

OE_METHOD = "closed-loop output-error fit by Levenberg-Marquardt"
"""How the refit is estimated when DIDIM's step does not lower the output error (:func:`output_error_gauss_newton`)."""

INVERSE_METHOD = "closed-loop value search with IDIM-LS"
"""The method named when DIDIM does not lower the output error but the closed-loop search of the nonlinear values does
(the linear parameters are then the inverse model's at the values found)."""

InverseFit = Callable[[list[Step]], tuple[tuple[str, ...], np.ndarray, np.ndarray]]
"""``steps -> (names, theta, cov)``: the inverse model's fit (and covariance) of ``base + steps``."""

XATOL_STEPS = 0.05
"""Tolerance of the bounded search on the value, in grid steps (on the grid's own scale)."""

CURVATURE_STEPS = 0.25
"""Step of the finite difference that gives a searched value's standard deviation from the profile's curvature (grid steps)."""


@dataclass(frozen=True)
class ValueSearch:
    """The closed-loop search of one nonlinear parameter.

    Attributes
    ----------
    effect, parameter, unit : str
        The effect, the parameter searched and its unit.
    inverse : float
        The inverse model's value (the centre of the range).
    optimum : float
        The search's optimum.
    value : float
        The value kept: the optimum, or ``inverse`` when the optimum is on the
        edge or does not lower the error.
    std : float or None
        Standard deviation of ``value`` from the curvature of the profile (``None`` when not kept or not convex).
    bounds : (float, float)
        The range searched.
    error_inverse_pct, error_pct : float
        Predicted closed-loop output error (%, decimated force) at ``inverse`` and at ``optimum``.
    evaluations : int
        Replays made.
    accepted : bool
        ``value`` is the optimum.
    reason : str
        Why it was kept or not.
    primary : bool
        The effect's first nonlinear parameter (the one the grid is of), not its secondary one.
    """

    effect: str
    parameter: str
    unit: str
    inverse: float
    optimum: float
    value: float
    std: float | None
    bounds: tuple[float, float]
    error_inverse_pct: float
    error_pct: float
    evaluations: int
    accepted: bool
    reason: str
    primary: bool = True

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "parameter": self.parameter,
            "unit": self.unit,
            "inverse_model": finite_or_none(self.inverse),
            "optimum": finite_or_none(self.optimum),
            "value": finite_or_none(self.value),
            "std": None if self.std is None else finite_or_none(self.std),
            "range_searched": [finite_or_none(b) for b in self.bounds],
            "closed_loop_error_pct": {"inverse_model": finite_or_none(self.error_inverse_pct), "optimum": finite_or_none(self.error_pct)},
            "replays": self.evaluations,
            "accepted": self.accepted,
            "reason": self.reason,
        }


@dataclass
class Refit:
    """The closed-loop refit of the final model, or why the inverse model's estimates are kept.

    Attributes
    ----------
    accepted : bool
        The closed-loop estimates replace the inverse model's.
    reason : str
        What was done, or why not.
    steps : list of Step
        The kept effects (not a model file's) with their nonlinear values (closed-loop when accepted).
    names : tuple of str
        Column names of the refitted model.
    theta, cov : ndarray
        DIDIM's estimate and covariance (``None`` when DIDIM did not run to the end).
    value_std : dict
        Effect id -> standard deviation of its (primary) nonlinear value from the closed-loop search.
    searches : list of ValueSearch
        One per nonlinear parameter searched.
    error_inverse_pct, error_pct : float or None
        Closed-loop output error (%, the decimated force, DIDIM's criterion) of the inverse model's estimate and of the refit.
    didim : ClosedLoopResult or None
        The final DIDIM run (iterations, stop reason); ``None`` for :data:`INVERSE_METHOD`.
    simulated : RunLog or None
        The replay of the refitted model (the final DIDIM iteration's).
    method : str
        :data:`METHOD`, or :data:`INVERSE_METHOD` when DIDIM was not kept but the search of the nonlinear values was,
        or :data:`ilic_cli.diagnosis.segments.METHOD` for Stribeck friction found at the dwells.
    segments : SegmentFit or None
        The open-loop segments' fit (:mod:`ilic_cli.diagnosis.segments`), when one was made.
    """

    accepted: bool
    reason: str
    steps: list[Step]
    names: tuple[str, ...]
    theta: np.ndarray | None = None
    cov: np.ndarray | None = None
    value_std: dict[str, float | None] = field(default_factory=dict)
    searches: list[ValueSearch] = field(default_factory=list)
    error_inverse_pct: float | None = None
    error_pct: float | None = None
    didim: ClosedLoopResult | None = None
    simulated: RunLog | None = field(default=None, repr=False)
    method: str = METHOD
    segments: SegmentFit | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "accepted": self.accepted,
            "reason": self.reason,
            "open_loop_segments": None if self.segments is None else self.segments.to_dict(),
            "closed_loop_error_pct": {
                "inverse_model": None if self.error_inverse_pct is None else finite_or_none(self.error_inverse_pct),
                "closed_loop": None if self.error_pct is None else finite_or_none(self.error_pct),
            },
            "searches": [s.to_dict() for s in self.searches],
            "didim": None
            if self.didim is None
            else {
                "iterations": self.didim.n_iterations,
                "converged": self.didim.converged,
                "stop_reason": self.didim.stop_reason,
                "parameters": self.didim.result.parameters(),
            },
        }


class _Point(NamedTuple):
    """One evaluation of the closed-loop profile: a DIDIM step from an estimate at one value."""

    error: float
    """Predicted output error after the step (%, decimated force)."""
    theta: np.ndarray
    """The estimate after the step."""
    at_anchor: float
    """Output error of the estimate the step started from (%)."""
    rho: float
    """Lag-1 autocorrelation of the predicted residual."""
    anchor: np.ndarray
    """The estimate the step started from."""


def _estimate(fit: Refit) -> np.ndarray:
    """The estimate of a refit that has one (the output-error refit always sets it)."""
    assert fit.theta is not None
    return fit.theta


def plant_problem(steps: list[Step] | tuple[Step, ...], names: tuple[str, ...], theta: np.ndarray) -> str | None:
    """Why the estimate ``theta`` of the model with ``steps`` is not a plant of the effects it names, else ``None``.

    Each effect must give plant parameters (:meth:`~ilic_cli.effects.Effect.fit_to_plant`) that pass
    their checks (:meth:`~ilic_cli.effects.Effect.values`), and must not be outside its physics
    (:attr:`~ilic_cli.effects.Effect.impossible`, e.g. a Stribeck level below Coulomb).
    """
    col = 0
    start = {n: i for i, n in enumerate(names)}
    for st in steps:
        e = st.effect
        cols = [start[c] for c in e.column_names if c in start]
        col += len(cols)
        if e.impossible is not None and cols:
            why = e.impossible(np.asarray(theta)[cols], st.value)
            if why:
                return f"{e.id}: {why}"
        if not e.plant:
            continue
        _, plant, note = e.fit_to_plant(Fit(names, np.asarray(theta), np.zeros((len(theta), len(theta))), st.value))
        if plant is None:
            return f"{e.id}: {note or 'no plant form'}"
        try:
            e.values(plant)
        except ParameterError as exc:
            return f"{e.id}: {exc.problem}"
    return None


def _scale(log_scale: bool) -> tuple[Callable[[float], float], Callable[[float], float]]:
    return (math.log, math.exp) if log_scale else (lambda v: v, lambda u: u)


def closed_loop_refit(
    log: RunLog,
    prepared: PreparedLog,
    base: Model,
    known: list[Step],
    kept: list[Step],
    theta0: np.ndarray,
    grids: Mapping[str, np.ndarray],
    *,
    ls: LSSettings = LSSettings(),
    simulate: Callable[[dict[str, float], dict[str, Any]], RunLog] | None = None,
    inverse_fit: InverseFit | None = None,
    hold_s: float = 0.0,
    confirm: Callable[[Refit], str | None] | None = None,
) -> Refit:
    """Refit ``base + known + kept`` on the closed-loop output error: the kept effects' nonlinear values searched, then DIDIM.

    Parameters
    ----------
    log : RunLog
        The recording (``q_ref`` and its controller: the replay's).
    prepared : PreparedLog
        ``prepare_log(log)`` (its valid samples).
    base : Model
        Rigid structure.
    known : list of Step
        Effects of a model file: in the model, their values not searched.
    kept : list of Step
        The effects the replay kept, in order, with the inverse model's values.
    theta0 : ndarray
        The inverse model's estimate of :func:`~ilic_cli.diagnosis.select.extended` ``(base, known + kept)``.
    grids : dict
        Effect id -> the grid its nonlinear parameter was searched on by the inverse model.
    ls : LSSettings
        Filtering and decimation (as the inverse model).
    simulate : callable, optional
        ``(rigid parameters, effects) -> simulated log``; default the replay of ``log`` (:func:`ilic_cli.simulation.replay.replay`).
    inverse_fit : callable, optional
        The inverse model's fit of ``base + steps`` (:data:`InverseFit`). When DIDIM does not lower the
        output error, the nonlinear values are still searched on the closed loop, the linear parameters
        refitted by it at each value (:data:`INVERSE_METHOD`); without it, the inverse model's estimates stand.
    hold_s : float
        Half a sample period when the logged force is the held command (how an effect is realised in the plant,
        :meth:`ilic_cli.effects.Effect.plant_entries`).
    confirm : callable, optional
        The test an estimate must also pass to be kept (the diagnosis: its output error replayed with the
        recording's sensor noise must fall): ``refit -> None``, or why it is not kept. An output-error fit
        (step 1b) it refuses gives way to the value search of :data:`INVERSE_METHOD`.

    Returns
    -------
    Refit
        Accepted, or the reason the inverse model's estimates stand.
    """
    sim_of = simulate or (lambda params, effects: replay(log, params, effects))
    steps = [*known, *kept]
    names0 = extended(base, steps, prepared.fs_hz).names
    t, tau, fs = log.t, np.asarray(log["tau"], dtype=np.float64), prepared.fs_hz
    recorded = lsq_rows(t, log["q"], tau, fs, base, ls, valid=prepared.valid)
    y = recorded.y
    y_norm = float(np.linalg.norm(y))
    if problem := plant_problem(steps, names0, theta0):
        return Refit(False, f"no closed-loop refit: the inverse model's estimate is no plant ({problem})", list(kept), names0)
    replays = [0]

    def values_of(model_steps: list[Step]) -> dict[str, Any]:
        return {s.effect.id: s.value for s in model_steps}

    def point(model_steps: list[Step], anchor: np.ndarray, sim: RunLog) -> _Point:
        """One DIDIM step from ``anchor``, whose replay is ``sim``."""
        names = extended(base, model_steps, fs).names
        d = lsq_rows(t, sim["q"], tau, fs, extended(base, model_steps, fs), ls, valid=prepared.valid)
        r = y - d.decimate(np.asarray(sim["tau"], dtype=np.float64)[ls.trim :])
        delta, rss = lstsq(d.W, r)
        at_anchor = 100.0 * float(np.linalg.norm(r)) / y_norm
        if plant_problem(model_steps, names, anchor + delta):
            return _Point(math.inf, anchor, at_anchor, 0.0, anchor)
        return _Point(100.0 * math.sqrt(rss) / y_norm, anchor + delta, at_anchor, lag1_autocorrelation(r - d.W @ delta), anchor)

    def replayed(model_steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> RunLog | None:
        """The replay of the estimate (one replay), ``None`` when it is no plant or does not simulate the whole log."""
        if plant_problem(model_steps, names, theta):
            return None
        try:
            sim = sim_of(*plant_of(names, theta, values_of(model_steps), hold_s))
        except IlicError:
            return None
        replays[0] += 1
        return sim if len(sim) == len(log) else None

    def profile(model_steps: list[Step], anchor: np.ndarray) -> _Point:
        """One DIDIM step from ``anchor`` with ``model_steps`` (one replay); infinite errors when either estimate is no plant."""
        sim = replayed(model_steps, extended(base, model_steps, fs).names, anchor)
        return _Point(math.inf, anchor, math.inf, 0.0, anchor) if sim is None else point(model_steps, anchor, sim)

    def didim(model_steps: list[Step], theta: np.ndarray) -> tuple[ClosedLoopResult, list[RunLog]] | str:
        """DIDIM of the model with ``model_steps`` from ``theta``, and its replays (first and last); or why it failed."""
        sims: list[RunLog] = []
        expected = [s.effect.id for s in model_steps if s.effect.plant]

        def checked(params: dict[str, float], effects: dict[str, Any]) -> RunLog:
            if len(effects) != len(expected):  # one plant entry per effect (a drive lag may be realised as the current loop)
                raise ParameterError("effects", expected, "plants of the effects named (an iterate left one outside its physics)")
            sim = sim_of(params, effects)
            replays[0] += 1
            sims[1:] = [sim]  # the first and the last
            return sim

        model = extended(base, model_steps, fs)
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a diverging iteration ends below, not in warnings
                res = closed_loop_identify(
                    "didim", log, model, theta, effects=values_of(model_steps), ls_settings=ls, prepared=prepared, simulate=checked, hold_s=hold_s
                )
        except IlicError as exc:
            return exc.problem
        if not (np.all(np.isfinite(res.result.theta)) and math.isfinite(res.result.error_norm)):
            return "DIDIM diverged"
        if problem := plant_problem(model_steps, model.names, res.result.theta):
            return f"its estimate is no plant of the effects named ({problem})"
        return res, sims

    # 1. DIDIM at the inverse model's nonlinear values: the closed loop must do better than the inverse model at all
    run0 = didim(steps, np.asarray(theta0, dtype=np.float64))
    if isinstance(run0, str):
        return Refit(False, f"the closed-loop refit failed ({run0}): the inverse model's estimates are kept", list(kept), names0)
    res0, sims0 = run0
    error_inverse = 100.0 * res0.iterations[0].error_norm / y_norm
    error0 = 100.0 * res0.result.error_norm / y_norm
    out = Refit(False, "", list(kept), names0, error_inverse_pct=error_inverse, error_pct=error0, didim=res0, simulated=sims0[0])
    if not error0 < error_inverse:
        out.reason = (
            f"DIDIM does not lower the closed-loop output error ({error_inverse:.3g} % -> {error0:.3g} %; its step takes the regressor of the "
            "simulated states for the sensitivity of the simulated force, which the loop's answer to these effects does not follow)"
        )

        # 1b. every parameter at once on the output error itself, its sensitivities by finite differences of replays
        def residual_of(model_steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> np.ndarray | None:
            """The recorded minus the replayed force of the estimate (decimated; one replay), ``None`` when it does not replay."""
            sim = replayed(model_steps, names, theta)
            return None if sim is None else y - recorded.decimate(np.asarray(sim["tau"], dtype=np.float64)[ls.trim :])

        oe = _output_error_refit(
            known, steps, names0, np.asarray(theta0, dtype=np.float64), grids, lambda s, th: residual_of(s, names0, th), error_inverse, y_norm
        )
        if isinstance(oe, str):
            out.reason += f"; {oe}"
        elif (final := replayed([*known, *oe.steps], names0, _estimate(oe))) is None:
            out.reason += f"; the {OE_METHOD} estimate does not replay"
        elif (why := None if confirm is None else confirm(oe)) is not None:
            out.reason += f"; the {OE_METHOD} lowers it to {oe.error_pct:.3g} %, but {why}"
        else:
            oe.reason = f"{out.reason}; {oe.reason}"
            oe.error_inverse_pct, oe.simulated = error_inverse, final
            return oe
        biased = {k: g for k, g in grids.items() if k in SEARCH_STEPS}  # the values the inverse model is known to bias; the others are within a grid step
        if inverse_fit is None or not biased:
            out.reason += ": the inverse model's estimates are kept"
            return out

        def profile_inverse(model_steps: list[Step], anchor: np.ndarray) -> _Point:
            """The inverse model's fit at ``model_steps``' values, replayed (one replay); ``anchor`` is not used."""
            names, theta, _ = inverse_fit(model_steps)
            r = residual_of(model_steps, names, theta)
            if r is None:
                return _Point(math.inf, theta, math.inf, 0.0, theta)
            e = 100.0 * float(np.linalg.norm(r)) / y_norm
            return _Point(e, theta, e, lag1_autocorrelation(r), theta)

        start0 = profile_inverse(steps, np.asarray(theta0, dtype=np.float64))
        searches, found_steps, end = _search_all(known, steps, biased, start0, profile_inverse, replays, len(y))
        out.searches = searches
        if not any(s.accepted for s in searches) or not end.error < start0.error:
            out.reason += "; no closed-loop search of its nonlinear values lowers the output error: the inverse model's estimates are kept"
            return out
        names, theta, cov = inverse_fit(found_steps)
        final = replayed(found_steps, names, theta)  # the search's last point, replayed for the comparison and the plots
        if final is None:
            out.reason += "; the estimate at the values found does not replay: the inverse model's estimates are kept"
            return out
        out.accepted, out.steps, out.names, out.theta, out.cov, out.method = True, found_steps[len(known) :], names, theta, cov, INVERSE_METHOD
        out.simulated, out.error_pct, out.didim = final, end.error, None
        out.value_std = {s.effect: s.std for s in searches if s.accepted and s.primary}
        searched = ", ".join(f"{s.parameter} of {s.effect}" for s in searches if s.accepted)
        out.reason += (
            f"; {searched} searched on the closed loop instead, the linear parameters IDIM-LS's at each value: "
            f"closed-loop output error {error_inverse:.3g} % -> {end.error:.3g} %"
        )
        return _confirmed(out, confirm)
    # 2. each nonlinear value searched on the closed loop, from DIDIM's estimate (its last replay is at that estimate)
    inverse_steps = list(steps)
    searches, steps, start = _search_all(known, steps, grids, point(steps, res0.result.theta, sims0[-1]), profile, replays, len(y), restart=True)
    chosen, error, sim = inverse_steps, error0, sims0[-1]
    if any(s.accepted for s in searches):
        # 3. DIDIM at the values found; kept only when it does better than DIDIM at the inverse model's values
        run1 = didim(steps, start.theta)
        error1 = 100.0 * run1[0].result.error_norm / y_norm if not isinstance(run1, str) else math.inf
        if not isinstance(run1, str) and error1 < error0:
            chosen, error, sim, res0 = steps, error1, run1[1][-1], run1[0]
        else:
            why = run1 if isinstance(run1, str) else f"the output error is {error1:.3g} %, DIDIM at the inverse model's values {error0:.3g} %"
            searches = [
                replace(
                    s,
                    value=s.inverse,
                    std=None,
                    accepted=False,
                    reason=f"{s.reason}; DIDIM at the values found does not do better ({why}): the inverse model's value is kept",
                )
                if s.accepted
                else s
                for s in searches
            ]
    model = extended(base, chosen, fs)
    theta = res0.result.theta
    d = lsq_rows(t, sim["q"], tau, fs, model, ls, valid=prepared.valid)
    tau_s = d.decimate(np.asarray(sim["tau"], dtype=np.float64)[ls.trim :])
    out.accepted, out.steps, out.names, out.theta, out.didim, out.simulated = True, chosen[len(known) :], model.names, theta, res0, sim
    out.cov = gls_covariance(d.W, y - tau_s + d.W @ theta, theta)
    out.searches, out.error_pct = searches, error
    out.value_std = {s.effect: s.std for s in searches if s.accepted and s.primary}
    searched = ", ".join(f"{s.parameter} of {s.effect}" for s in searches if s.accepted)
    out.reason = (
        f"refitted on the closed loop ({METHOD}, {_count(res0.n_iterations, 'iteration')}{', ' + searched + ' searched' if searched else ''}): "
        f"closed-loop output error {error_inverse:.3g} % -> {error:.3g} %"
    )
    return _confirmed(out, confirm)


def _confirmed(refit: Refit, confirm: Callable[[Refit], str | None] | None) -> Refit:
    """``refit``, or not accepted with the reason when ``confirm`` refuses it (its replay is then not the model file's)."""
    why = None if confirm is None or not refit.accepted else confirm(refit)
    if why is None:
        return refit
    return replace(refit, accepted=False, reason=f"{refit.reason}; {why}: the inverse model's estimates are kept", simulated=None)


def _search_all(
    known: list[Step],
    steps: list[Step],
    grids: Mapping[str, np.ndarray],
    start: _Point,
    profile: Callable[[list[Step], np.ndarray], _Point],
    replays: list[int],
    n_rows: int,
    *,
    restart: bool = False,
) -> tuple[list[ValueSearch], list[Step], _Point]:
    """Each nonlinear parameter of ``steps`` (not ``known``'s) searched in turn on ``profile``: the searches, the steps at the values found, the last point.

    Each search goes on from the previous one's optimum; ``restart``: from a
    new profile point at its estimate (one replay: a DIDIM step from there),
    and the round of searches is repeated (a coordinate descent) while a
    round lowers the output error by more than :data:`ROUND_GAIN` of it, at
    most :data:`MAX_ROUNDS` rounds, when more than one parameter is searched:
    the values couple. Measured on the corpus's Stribeck + flexibility log
    with the current loop (s303): one round left the drive lag at 0.267 ms
    for the loop's 0.227 ms, the resonance 9.5 % and the Stribeck level 16 %
    off (output error 0.762 %); four rounds give 0.236 ms, 0.4 % and 3.6 %
    (0.708 %). One :class:`ValueSearch` per parameter is returned
    (:func:`_rounds`).
    """
    steps = list(steps)
    slots = _slots(known, steps, grids)
    rounds: list[list[ValueSearch]] = []
    point = start
    for _ in range(MAX_ROUNDS if restart and len(slots) > 1 else 1):
        searches: list[ValueSearch] = []
        begin = point.error
        for j, pname, unit, slot in slots:
            last = searches[-1] if searches else (rounds[-1][-1] if rounds else None)
            if restart and last is not None and last.accepted:
                point = profile(steps, point.theta)
            found, point = _search(steps, j, slot, pname, unit, grids[steps[j].effect.id], point, profile, replays, n_rows - len(point.theta))
            searches.append(found)
            if found.accepted:
                st = steps[j]
                steps[j] = Step(st.effect, _with_slot(st.value, slot, found.value))
        rounds.append(searches)
        if not any(f.accepted for f in searches) or not point.error < (1.0 - ROUND_GAIN) * begin:
            break
    return _rounds(rounds), steps, point


def _slots(known: list[Step], steps: list[Step], grids: Mapping[str, np.ndarray]) -> list[tuple[int, str, str, int]]:
    """The nonlinear values of ``steps`` (not ``known``'s) the closed loop searches: ``(index in steps, parameter, unit, slot)``.

    Slot 0 is an effect's value on its grid, slot 1 its secondary value (a resonance's damping ratio).
    """
    slots: list[tuple[int, str, str, int]] = []
    for j in range(len(known), len(steps)):
        scan = steps[j].effect.scan
        if scan is None or steps[j].effect.id not in grids:
            continue
        slots.append((j, scan.name, scan.unit, 0))
        if scan.secondary is not None and isinstance(steps[j].value, tuple):
            slots.append((j, scan.secondary[0], scan.secondary[1], 1))
    return slots


def _slot_value(value: Any, slot: int) -> float:
    return float(value[slot]) if isinstance(value, tuple) else float(value)


MAX_ROUNDS = 5
"""Most rounds of the coordinate search of the nonlinear values (:func:`_search_all`)."""

ROUND_GAIN = 0.01
"""A round of the coordinate search is repeated while it lowers the output error by more than this share of it."""


def _rounds(rounds: list[list[ValueSearch]]) -> list[ValueSearch]:
    """One search per parameter from the rounds of :func:`_search_all`: from the first round's value to the last value accepted.

    A parameter no round moved keeps its first search (and its reason). One
    that moved gets the value of its last accepted round, that round's
    standard deviation and error, the first round's value and error as the
    start, the union of the ranges searched and every replay.
    """
    if len(rounds) == 1:
        return rounds[0]
    out = []
    for per in zip(*rounds, strict=True):
        first, moved = per[0], [f for f in per if f.accepted]
        if not moved:
            out.append(replace(first, evaluations=sum(f.evaluations for f in per)))
            continue
        last = moved[-1]
        lo, hi = min(f.bounds[0] for f in per), max(f.bounds[1] for f in per)
        span = f"{lo:.4g} to {hi:.4g} {first.unit}".strip()
        why = (
            f"searched on the closed loop ({span}, {len(per)} rounds of the coordinate search, moved in {len(moved)}): "
            f"{first.parameter} {first.inverse:.4g} -> {last.value:.4g} {first.unit}, output error {first.error_inverse_pct:.4g} % -> {last.error_pct:.4g} %"
        ).replace(" ,", ",")
        n = sum(f.evaluations for f in per)
        out.append(replace(last, inverse=first.inverse, bounds=(lo, hi), error_inverse_pct=first.error_inverse_pct, evaluations=n, reason=why))
    return out


def _with_slot(value: Any, slot: int, new: float) -> Any:
    """``value`` with slot ``slot`` set to ``new``: a scalar value (slot 0) is ``new`` itself."""
    if not isinstance(value, tuple):
        return new
    v = list(value)
    v[slot] = new
    return tuple(v)


def _search(
    steps: list[Step],
    j: int,
    slot: int,
    pname: str,
    unit: str,
    grid: np.ndarray,
    start: _Point,
    profile: Callable[[list[Step], np.ndarray], _Point],
    replays: list[int],
    dof: int,
) -> tuple[ValueSearch, _Point]:
    """Bounded search of slot ``slot`` of ``steps[j]``'s value on the closed-loop output error; the search and the point to go on from.

    Every value is one DIDIM step from ``start``'s estimate (the previous parameter's optimum).
    """
    from scipy.optimize import minimize_scalar  # deferred: scipy.optimize is slow to import

    st = steps[j]
    scan = st.effect.scan
    assert scan is not None
    value = st.value
    v0 = _slot_value(value, slot)
    sub = _slot_range(st, slot, grid)
    lo, hi = float(sub[0]), float(sub[-1])
    if slot == 0:
        fwd, inv = _scale(scan.log and lo > 0)
        step_u = (fwd(hi) - fwd(lo)) / max(len(sub) - 1, 1)
    else:
        fwd, inv = _scale(True)
        step_u = (fwd(hi) - fwd(lo)) / 20.0
    at = {"start": replays[0]}
    memo: dict[float, _Point] = {}
    anchor = start.anchor
    err0 = start.error

    def with_value(v: float) -> list[Step]:
        new = list(steps)
        new[j] = Step(st.effect, _with_slot(value, slot, v))
        return new

    def f(u: float) -> float:
        v = inv(u)
        if v not in memo:
            memo[v] = profile(with_value(v), anchor)
        return memo[v].error

    memo[v0] = start
    if hi <= lo:
        return ValueSearch(st.effect.id, pname, unit, v0, v0, v0, None, (lo, hi), err0, err0, 0, False, "no range to search", slot == 0), start
    with np.errstate(invalid="ignore"):  # a value with no plant is an infinite error: the parabola step through it is nan, and falls back
        res = minimize_scalar(f, bounds=(fwd(lo), fwd(hi)), method="bounded", options={"xatol": XATOL_STEPS * step_u})
    best = inv(float(res.x))
    e_best = f(float(res.x))
    if slot == 0:
        edge = at_edge(st.effect, sub, best)
    else:  # the primary value is inside its grid (the inverse model's own edge rule): only the secondary can be on an edge
        edge = at_edge(st.effect, np.asarray(grid, dtype=np.float64), _with_slot(value, slot, best))
    span = f"{lo:.4g} to {hi:.4g} {unit}".strip()
    if not math.isfinite(e_best):
        why = "no value in the range searched gives a plant of the effect: the inverse model's value is kept"
        ok = False
    elif edge:
        why = f"the closed-loop optimum is on the edge of the range searched ({edge}): the inverse model's value is kept"
        ok = False
    elif not e_best < err0:
        why = f"the closed-loop search ({span}) does not lower the output error: the inverse model's value is kept"
        ok = False
    else:
        why = f"searched on the closed loop ({span}): {pname} {v0:.4g} -> {best:.4g} {unit}, output error {err0:.4g} % -> {e_best:.4g} %".replace(" ,", ",")
        ok = True
    std = None
    if ok:
        std = _std(f, inv, float(res.x), CURVATURE_STEPS * step_u, e_best, dof, memo[best].rho)
    n_replays = replays[0] - at["start"]
    found = ValueSearch(st.effect.id, pname, unit, v0, best, best if ok else v0, std, (lo, hi), err0, e_best, n_replays, ok, why, slot == 0)
    return found, memo[best] if ok else start


def _std(f: Callable[[float], float], inv: Callable[[float], float], u: float, h: float, e: float, dof: int, rho: float) -> float | None:
    """Standard deviation of the value at ``u`` from the curvature of the profile error, in the value's own unit.

    ``f`` is the output error in % of ``||y||``, so ``f**2`` is the residual sum of squares up to a
    constant that cancels: ``var = 2 (RSS / dof) / RSS''``, inflated for the lag-1 autocorrelation
    ``rho`` of the residual, as :meth:`ilic_cli.diagnosis.select.Searcher.refine` does on the inverse model's RSS.
    """
    ep, em = f(u + h), f(u - h)
    if not (math.isfinite(ep) and math.isfinite(em)):
        return None
    dv = 0.5 * (inv(u + h) - inv(u - h))
    curv = (ep**2 - 2.0 * e**2 + em**2) / dv**2
    if not curv > 0:
        return None
    r = min(max(rho, 0.0), 0.99)
    inflation = (1.0 + r) / (1.0 - r)
    return math.sqrt(2.0 * e**2 / max(dof, 1) * inflation / curv)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _slot_range(step: Step, slot: int, grid: np.ndarray) -> np.ndarray:
    """What the closed loop searches slot ``slot`` of ``step``'s value on: the part of the effect's ``grid`` around it
    (:func:`~ilic_cli.diagnosis.select.search_range`), or the secondary value's bounds."""
    scan = step.effect.scan
    assert scan is not None
    if slot == 0:
        return search_range(step.effect, np.asarray(grid, dtype=np.float64), _slot_value(step.value, 0))
    assert scan.secondary is not None
    return np.array([scan.secondary[2], scan.secondary[3]])


def _output_error_refit(
    known: list[Step],
    steps: list[Step],
    names: tuple[str, ...],
    theta0: np.ndarray,
    grids: Mapping[str, np.ndarray],
    residual_of: Callable[[list[Step], np.ndarray], np.ndarray | None],
    error_inverse: float,
    y_norm: float,
) -> Refit | str:
    """The refit by :func:`output_error_gauss_newton`: the linear parameters ``names`` and every searched value of the kept effects at once.

    The values enter as ratios to their start (``steps``'). The estimate is
    refused (the reason returned) when it lowers the output error by less
    than :data:`ROUND_GAIN` of ``error_inverse`` (%), or ends with a value on
    the edge of the range the closed loop searches it in
    (:func:`~ilic_cli.diagnosis.select.at_edge`). Its covariance is that of the
    final Jacobian, the residual's autocorrelation accounted for
    (:func:`~ilic_cli.diagnosis.stats.gls_covariance`).
    """
    slots = _slots(known, steps, grids)
    v0 = np.array([_slot_value(steps[j].value, k) for j, _, _, k in slots])
    n_lin = len(theta0)

    def steps_at(ratio: np.ndarray) -> list[Step]:
        new = list(steps)
        for (j, _, _, k), v in zip(slots, v0 * ratio, strict=True):
            new[j] = Step(new[j].effect, _with_slot(new[j].value, k, float(v)))
        return new

    fit = output_error_gauss_newton(lambda z: residual_of(steps_at(z[n_lin:]), z[:n_lin]), np.r_[theta0, np.ones(len(slots))], first_gain=ROUND_GAIN)
    error = 100.0 * float(np.linalg.norm(fit.residual)) / y_norm
    found = steps_at(fit.z[n_lin:])
    values = [_slot_value(found[j].value, k) for j, _, _, k in slots]
    if not error < (1.0 - ROUND_GAIN) * error_inverse:
        return f"the {OE_METHOD} gives {error:.3g} %, not {ROUND_GAIN:.0%} lower ({fit.stop})"
    ranges = [_slot_range(steps[j], k, grids[steps[j].effect.id]) for j, _, _, k in slots]
    for (j, _, _, k), sub in zip(slots, ranges, strict=True):
        if k == 0 and (edge := at_edge(found[j].effect, sub, found[j].value)):
            return f"the {OE_METHOD} ends with {edge}"
    cov = gls_covariance(fit.sensitivity, fit.residual + fit.sensitivity @ fit.z, fit.z)
    std = np.abs(v0) * np.sqrt(np.clip(np.diag(cov)[n_lin:], 0.0, None))
    searches = [
        ValueSearch(
            steps[j].effect.id,
            pname,
            unit,
            float(v0[i]),
            values[i],
            values[i],
            float(std[i]),
            (float(ranges[i][0]), float(ranges[i][-1])),
            error_inverse,
            error,
            fit.replays,
            True,
            f"fitted on the closed loop with the linear parameters: {pname} {v0[i]:.4g} -> {values[i]:.4g} {unit}".strip(),
            k == 0,
        )
        for i, (j, pname, unit, k) in enumerate(slots)
    ]
    return Refit(
        True,
        f"refitted instead by a {OE_METHOD}, its sensitivities by finite differences of replays "
        f"({_count(len(fit.history) - 1, 'iteration')}, {fit.replays} replays): closed-loop output error {error_inverse:.3g} % -> {error:.3g} %",
        found[len(known) :],
        names,
        theta=fit.z[:n_lin],
        cov=cov[:n_lin, :n_lin],
        value_std={s.effect: s.std for s in searches if s.primary},
        searches=searches,
        error_pct=error,
        method=OE_METHOD,
    )


class OutputErrorFit(NamedTuple):
    """The result of :func:`output_error_gauss_newton`."""

    z: np.ndarray
    """The parameters at the end."""
    residual: np.ndarray
    """The output residual there."""
    sensitivity: np.ndarray
    """``d(output)/dz`` by finite differences at the last point the Jacobian was taken (rows of ``residual``)."""
    history: list[float]
    """Residual norm at the start and after each step taken."""
    replays: int
    """Evaluations of the residual."""
    stop: str
    """Why it stopped."""


def output_error_gauss_newton(
    residual: Callable[[np.ndarray], np.ndarray | None],
    z0: np.ndarray,
    *,
    rel_step: float = 1e-2,
    max_iter: int = 8,
    tol: float = 1e-3,
    first_gain: float = 0.0,
) -> OutputErrorFit:
    """Levenberg-Marquardt on an output error whose sensitivities are taken by forward differences.

    ``residual(z)`` is the recorded minus the simulated output (``None``: no
    simulation at ``z``, an infinite error). Each iteration takes the Jacobian
    by one evaluation per parameter (step ``rel_step`` of ``max(|z_k|, 1e-3)``,
    evaluated side by side), then the damped Gauss-Newton step
    ``(J'J + lam diag(J'J)) dz = J'r``, the damping raised tenfold until the
    error falls (at most 5 tries) and lowered tenfold after. It stops when a
    step lowers the error by less than ``tol`` of it, or after ``max_iter``,
    and without trying a step when the undamped step's linear prediction
    lowers it by less than ``tol`` (less than ``first_gain`` on the first
    iteration: a fit that must gain that much to be kept need not be run on).
    This is the output-error criterion DIDIM minimises (Gautier, Janot,
    Vandanjon, IEEE TCST 21(2), 2013), with the closed loop's own sensitivity
    ``d tau_s / d z`` instead of DIDIM's regressor of the simulated states
    (:mod:`ilic_cli.closed_loop_id`). ``sensitivity`` is the last Jacobian
    taken, at the point before the last step.
    """
    z = np.asarray(z0, dtype=np.float64).copy()
    r = residual(z)
    evaluations = 1
    if r is None:
        return OutputErrorFit(z, np.full(1, np.inf), np.zeros((1, len(z))), [math.inf], evaluations, "the start does not simulate")
    e = float(np.linalg.norm(r))
    history = [e]
    J = np.zeros((len(r), len(z)))
    lam = 1e-3
    stop = f"{max_iter} iterations"
    for _ in range(max_iter):
        h = rel_step * np.maximum(np.abs(z), 1e-3)

        def shifted(k: int, z: np.ndarray = z, h: np.ndarray = h) -> np.ndarray | None:
            zk = z.copy()
            zk[k] += h[k]
            return residual(zk)

        cols = ordered_map(shifted, range(len(z)))
        evaluations += len(z)
        if any(c is None for c in cols):
            stop = "a parameter shifted for its sensitivity does not simulate"
            break
        J = np.column_stack([(r - c) / hk for c, hk in zip(cols, h, strict=True) if c is not None])
        predicted = float(np.linalg.norm(r - J @ np.linalg.lstsq(J, r, rcond=None)[0]))
        need = first_gain if len(history) == 1 else tol
        if not e > 0.0 or (e - predicted) / e < need:
            stop = f"its step is predicted to lower the error by less than {need:.2%}"
            break
        jtj, jtr = J.T @ J, J.T @ r
        damp = np.diag(np.diag(jtj))
        for _ in range(5):
            dz = np.linalg.lstsq(jtj + lam * damp, jtr, rcond=None)[0]
            rt = residual(z + dz)
            evaluations += 1
            et = math.inf if rt is None else float(np.linalg.norm(rt))
            if et < e:
                break
            lam *= 10.0
        else:
            stop = "no damping of its step lowers the error"
            break
        assert rt is not None
        z, r, gain, e = z + dz, rt, (e - et) / e, et
        lam = max(lam / 10.0, 1e-6)
        history.append(e)
        if gain < tol:
            stop = f"its step lowered the error by less than {tol:.2%}"
            break
    return OutputErrorFit(z, r, J, history, evaluations, stop)
