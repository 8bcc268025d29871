"""The closed-loop refit of the effects the replay kept (issue #11 item 3): DIDIM with their columns, their nonlinear parameters searched.

The inverse model (:mod:`ilic_cli.diagnosis.select`) fits an effect on the filtered kinematics of the measured position. On
closed-loop data that is biased: the command answers the position noise and the disturbance the filtered kinematics carry,
so an effect whose column correlates with them comes out off (measured on the corpus: a drive lag 30-66 % too long, a
Stribeck level 46 % and 163 % off on the EMPS reference). The closed-loop output error has no such bias: the recorded
reference is replayed through the log's controller and the plant of the estimate, and the simulated force is compared with
the recorded one (DIDIM, :mod:`ilic_cli.closed_loop_id`).

Once the replay has decided which effects are findings (:mod:`ilic_cli.diagnosis.decide`), the final model (rigid columns,
the effects' columns) is refitted so:

1. **DIDIM at the inverse model's nonlinear values** (:func:`ilic_cli.closed_loop_id.closed_loop_identify`). When it does
   not lower the closed-loop output error below the inverse model's, nothing is refitted: DIDIM's step takes the regressor
   of the simulated states for the sensitivity of the simulated force, which the loop's answer to an effect near or above
   its bandwidth does not follow (measured: DATA_EMPS with asymmetric friction and ripple, 4.99 % -> 5.05 %; 8 of the
   corpus's 29 logs with a finding).
2. **Each nonlinear parameter** (Stribeck ``vs``, ripple period ``L``, resonance ``f_res`` then its damping ratio, payload
   change time, delay), in the order the effects were kept, is searched on the closed-loop output error, a bounded scalar
   search within :data:`SEARCH_STEPS` steps of the effect's own grid around the inverse model's value (the damping ratio
   within its bounds). At each value the linear parameters are one DIDIM Gauss-Newton step from the current estimate (one
   replay per value; the profile is the step's predicted output error). Measured on the Stribeck EMPS-reference log: the
   same optimum as DIDIM iterated to convergence at each value (vs = 12 mm/s, 3 replays per value), at a third of the cost.
   An optimum on the edge of the range searched, or one that does not lower the error, keeps the inverse model's value and
   says so. With more than one value, the round of searches is repeated while it lowers the error by more than
   :data:`ROUND_GAIN` (the values couple: :func:`search_all`).
3. **DIDIM at the values found**, kept when its output error is below that of step 1 (else step 1's estimate, at the inverse
   model's values).
4. **Every value and linear parameter at once** (:data:`OE_METHOD`, from where steps 2 and 3 ended) when two values or more
   were searched: coupled values lie along a curved valley of the output error that the one-at-a-time searches descend
   slowly, or not at all when each search's profile, one DIDIM step a value, misleads it (:func:`_polished`). Kept on the
   terms of the output-error fit below, else step 3's estimate stands.

When DIDIM does not lower the output error (step 1), or fails there while the inverse model's estimate replays (an iterate
outside the plant), the output error itself is minimised (:data:`OE_METHOD`, :func:`output_error_gauss_newton`): the linear
parameters and every searched value of the kept effects at once, by Levenberg-Marquardt with the closed loop's own
sensitivities, taken by finite differences of replays (one replay per parameter and step). Measured on the corpus's
Stribeck + flexibility reseed s303@s2303, where DIDIM's step raises the error (0.845 % -> 0.998 %): 0.704 % in 1 iteration and 22
replays, the Stribeck level 3.40 N for 3.53 (the folds' 2.32 N), ``vs`` 8.35 mm/s for 8, the resonance 35.04 Hz for 35.00
and its damping ratio 0.155 for 0.150. It is kept when it lowers the output error by :data:`ROUND_GAIN` of it, no value ends
on the edge of its search range, and the diagnosis's ``confirm`` (the output error replayed with the recording's sensor
noise) does not refuse it (on ``DATA_EMPS.mat`` its first step is predicted to gain less than 1 %, and no step is tried: 9
replays; on the corpus's trapezoids it lowers the noise-free error, 1.64 % -> 1.39 % on a clean one with the current loop,
by fitting what the noise drives at the dwells, and the noisy replay refuses it, 0.869 % -> 1.3 %). Otherwise the values the
inverse model is known to bias (:data:`SEARCH_STEPS`: Stribeck ``vs``, a delay, a resonance) are still searched on the
closed loop, the linear parameters then the inverse model's fit at each value (one replay per value;
:data:`INVERSE_METHOD`), and that estimate is kept when it lowers the output error.

The estimate is **accepted** only when every effect stays a valid plant of the physics it is named (a load fraction in
(0, 1), a Stribeck level above 0 and above ``-Fc``, ...); otherwise the inverse model's estimates are kept and the reason is
given. The standard deviations are those of the final DIDIM step's least squares, with the residual's autocorrelation
accounted for as in the inverse model's (:func:`ilic_cli.lsq.robust_covariance`, the Newey-West sandwich); a searched
value's, from the curvature of the profile.

Pure numerics on run logs in memory: no file I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from ilic_cli.closed_loop_id import ClosedLoopResult, closed_loop_identify, plant_of
from ilic_cli.diagnosis.fits import INVERSE_METHOD, METHOD, OE_METHOD, InverseFit, Point, Refit, ValueSearch, count, estimate, plant_problem
from ilic_cli.diagnosis.oe_fit import output_error_refit
from ilic_cli.diagnosis.refit_search import MAX_ROUNDS, ROUND_GAIN, search_all
from ilic_cli.diagnosis.search import SEARCH_STEPS
from ilic_cli.diagnosis.stats import lag1_autocorrelation
from ilic_cli.diagnosis.system import Step, extended
from ilic_cli.diagnosis.verdicts import RefitOutcome
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.idim_ls import LSSettings, lsq_rows
from ilic_cli.lsq import lstsq, norm_pct, robust_covariance
from ilic_cli.prepare import PreparedLog
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog, joint_type
from ilic_cli.simulation.replay import replay


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
    round_gain: float = ROUND_GAIN,
    max_rounds: int = MAX_ROUNDS,
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
    round_gain, max_rounds : float, int
        The share of the output error an output-error fit, or a round of the value searches, must gain, and the most rounds
        (:data:`~ilic_cli.diagnosis.refit_search.ROUND_GAIN`, :data:`~ilic_cli.diagnosis.refit_search.MAX_ROUNDS`).

    Returns
    -------
    Refit
        Accepted, or the reason the inverse model's estimates stand.
    """
    steps = [*known, *kept]
    names0 = extended(base, steps, prepared.fs_hz).names
    loop = ReplayLoop(log, prepared, base, ls, simulate or (lambda params, effects: replay(log, params, effects)), hold_s)
    loop.round_gain, loop.max_rounds = round_gain, max_rounds
    if problem := plant_problem(steps, names0, theta0, joint=loop.joint):
        return Refit(False, f"no closed-loop refit: the inverse model's estimate is no plant ({problem})", list(kept), names0, outcome=RefitOutcome.NO_PLANT)
    # 1. DIDIM at the inverse model's nonlinear values: the closed loop must do better than the inverse model at all
    run0 = loop.didim(steps, np.asarray(theta0, dtype=np.float64))
    if isinstance(run0, str):
        failed = Refit(False, f"the closed-loop refit failed ({run0})", list(kept), names0, outcome=RefitOutcome.FAILED)
        if (r := loop.residual_of(steps, names0, theta0)) is None:
            failed.reason += ": the inverse model's estimates are kept"
            return failed
        # an iterate left the plant: the inverse model's estimate still replays, and the output-error fit and the value search start
        # from it, as where DIDIM does not lower the output error (--beyond lin2 chirp at 400 Hz, s5039: the flexibility's load 14 %
        # high as the inverse model's, DIDIM's iterates outside the plant in both bands; the output-error fit's within 1 %)
        failed.error_inverse_pct = failed.error_pct = norm_pct(float(np.linalg.norm(r)), loop.y_norm)
        return _without_didim(loop, failed, known, steps, theta0, grids, inverse_fit, confirm)
    res0, sims0 = run0
    error_inverse = norm_pct(res0.iterations[0].error_norm, loop.y_norm)
    error0 = norm_pct(res0.result.error_norm, loop.y_norm)
    out = Refit(False, "", list(kept), names0, error_inverse_pct=error_inverse, error_pct=error0, didim=res0, simulated=sims0[0])
    if not error0 < error_inverse:
        out.reason = (
            f"DIDIM does not lower the closed-loop output error ({error_inverse:.3g} % -> {error0:.3g} %; its step takes the regressor of the "
            "simulated states for the sensitivity of the simulated force, which the loop's answer to these effects does not follow)"
        )
        return _without_didim(loop, out, known, steps, theta0, grids, inverse_fit, confirm)
    return _with_didim(loop, out, known, steps, grids, run0, confirm)


class ReplayLoop:
    """The replays of one recording for the refit, and the closed-loop output error they give (DIDIM's criterion)."""

    def __init__(
        self, log: RunLog, prepared: PreparedLog, base: Model, ls: LSSettings, sim_of: Callable[[dict[str, float], dict[str, Any]], RunLog], hold_s: float
    ) -> None:
        self.log, self.prepared, self.base, self.ls, self.sim_of, self.hold_s = log, prepared, base, ls, sim_of, hold_s
        self.t, self.tau, self.fs = log.t, np.asarray(log["tau"], dtype=np.float64), prepared.fs_hz
        self.recorded = lsq_rows(self.t, log["q"], self.tau, self.fs, base, ls, valid=prepared.valid)
        self.y = self.recorded.y
        self.y_norm = float(np.linalg.norm(self.y))
        self.replays = [0]
        self.joint = joint_type(log.units.get("q"))  # the units the searches' reasons write their values in
        self.round_gain, self.max_rounds = ROUND_GAIN, MAX_ROUNDS
        """The gain an output-error fit or a round of the value searches must make, and the most rounds (:data:`ROUND_GAIN`)."""
        """Replays made so far (a list: the searches count theirs in it)."""

    @staticmethod
    def values_of(model_steps: list[Step]) -> dict[str, Any]:
        return {s.effect.id: s.value for s in model_steps}

    def point(self, model_steps: list[Step], anchor: np.ndarray, sim: RunLog) -> Point:
        """One DIDIM step from ``anchor``, whose replay is ``sim``."""
        names = extended(self.base, model_steps, self.fs).names
        d = lsq_rows(self.t, sim["q"], self.tau, self.fs, extended(self.base, model_steps, self.fs), self.ls, valid=self.prepared.valid)
        r = self.y - d.decimate(np.asarray(sim["tau"], dtype=np.float64)[self.ls.trim :])
        delta, rss = lstsq(d.W, r)
        at_anchor = norm_pct(float(np.linalg.norm(r)), self.y_norm)
        if plant_problem(model_steps, names, anchor + delta, joint=self.joint):
            return Point(math.inf, anchor, at_anchor, 0.0, anchor)
        return Point(norm_pct(math.sqrt(rss), self.y_norm), anchor + delta, at_anchor, lag1_autocorrelation(r - d.W @ delta), anchor)

    def replayed(self, model_steps: list[Step], names: tuple[str, ...], theta: np.ndarray, plant: Mapping[str, Any] | None = None) -> RunLog | None:
        """The replay of the estimate (one replay; ``plant``: effects of the plant beside the model's), ``None`` when it is no plant
        or does not simulate the whole log."""
        if plant_problem(model_steps, names, theta, joint=self.joint):
            return None
        try:
            params, effects = plant_of(names, theta, self.values_of(model_steps), self.hold_s)
            sim = self.sim_of(params, {**effects, **(plant or {})})
        except IlicError:
            return None
        self.replays[0] += 1
        return sim if len(sim) == len(self.log) else None

    def residual_of(self, model_steps: list[Step], names: tuple[str, ...], theta: np.ndarray, plant: Mapping[str, Any] | None = None) -> np.ndarray | None:
        """The recorded minus the replayed force of the estimate (decimated; one replay), ``None`` when it does not replay."""
        sim = self.replayed(model_steps, names, theta, plant)
        return None if sim is None else self.residual(sim)

    def residual(self, sim: RunLog) -> np.ndarray:
        """The recorded minus ``sim``'s force, decimated as the rows (the closed-loop output error's residual)."""
        return self.y - self.recorded.decimate(np.asarray(sim["tau"], dtype=np.float64)[self.ls.trim :])

    def profile(self, model_steps: list[Step], anchor: np.ndarray) -> Point:
        """One DIDIM step from ``anchor`` with ``model_steps`` (one replay); infinite errors when either estimate is no plant."""
        sim = self.replayed(model_steps, extended(self.base, model_steps, self.fs).names, anchor)
        return Point(math.inf, anchor, math.inf, 0.0, anchor) if sim is None else self.point(model_steps, anchor, sim)

    def didim(self, model_steps: list[Step], theta: np.ndarray) -> tuple[ClosedLoopResult, list[RunLog]] | str:
        """DIDIM of the model with ``model_steps`` from ``theta``, and its replays (first and last); or why it failed."""
        sims: list[RunLog] = []
        expected = [s.effect.id for s in model_steps if s.effect.plant]

        def checked(params: dict[str, float], effects: dict[str, Any]) -> RunLog:
            if len(effects) != len(expected):  # one plant entry per effect (a drive lag may be realised as the current loop)
                raise ParameterError("effects", expected, "plants of the effects named (an iterate left one outside its physics)")
            sim = self.sim_of(params, effects)
            self.replays[0] += 1
            sims[1:] = [sim]  # the first and the last
            return sim

        model = extended(self.base, model_steps, self.fs)
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a diverging iteration ends below, not in warnings
                res = closed_loop_identify(
                    "didim",
                    self.log,
                    model,
                    theta,
                    effects=self.values_of(model_steps),
                    ls_settings=self.ls,
                    prepared=self.prepared,
                    simulate=checked,
                    hold_s=self.hold_s,
                )
        except IlicError as exc:
            return exc.problem
        if not (np.all(np.isfinite(res.result.theta)) and math.isfinite(res.result.error_norm)):
            return "DIDIM diverged"
        if problem := plant_problem(model_steps, model.names, res.result.theta, joint=self.joint):
            return f"its estimate is no plant of the effects named ({problem})"
        return res, sims


def _without_didim(
    loop: ReplayLoop,
    out: Refit,
    known: list[Step],
    steps: list[Step],
    theta0: np.ndarray,
    grids: Mapping[str, np.ndarray],
    inverse_fit: InverseFit | None,
    confirm: Callable[[Refit], str | None] | None,
) -> Refit:
    """DIDIM does not lower the output error, or failed where the inverse model's estimate replays: the output-error fit (1b), else
    the closed-loop search of the values the inverse model biases with its linear parameters at each value (:data:`INVERSE_METHOD`),
    else the inverse model's estimates stand (``out``)."""
    assert out.error_inverse_pct is not None
    error_inverse, names0, y_norm = out.error_inverse_pct, out.names, loop.y_norm
    # 1b. every parameter at once on the output error itself, its sensitivities by finite differences of replays
    theta_0 = np.asarray(theta0, dtype=np.float64)
    oe = _output_error_fit(loop, known, steps, names0, theta_0, grids, error_inverse, confirm)
    if isinstance(oe, str):
        out.reason += f"; {oe}"
    else:
        oe.reason = f"{out.reason}; {oe.reason}"
        oe.error_inverse_pct = error_inverse
        return oe
    biased = {k: g for k, g in grids.items() if k in SEARCH_STEPS}  # the values the inverse model is known to bias; the others are within a grid step
    if inverse_fit is None or not biased:
        out.reason += ": the inverse model's estimates are kept"
        return out

    def profile_inverse(model_steps: list[Step], anchor: np.ndarray) -> Point:
        """The inverse model's fit at ``model_steps``' values, replayed (one replay); ``anchor`` is not used."""
        names, theta, _ = inverse_fit(model_steps)
        r = loop.residual_of(model_steps, names, theta)
        if r is None:
            return Point(math.inf, theta, math.inf, 0.0, theta)
        e = norm_pct(float(np.linalg.norm(r)), y_norm)
        return Point(e, theta, e, lag1_autocorrelation(r), theta)

    start0 = profile_inverse(steps, theta_0)
    searches, found_steps, end = search_all(
        known, steps, biased, start0, profile_inverse, loop.replays, len(loop.y), round_gain=loop.round_gain, joint=loop.joint
    )
    out.searches = searches
    if not any(s.accepted for s in searches) or not end.error < start0.error:
        out.reason += "; no closed-loop search of its nonlinear values lowers the output error: the inverse model's estimates are kept"
        return out
    names, theta, cov = inverse_fit(found_steps)
    final = loop.replayed(found_steps, names, theta)  # the search's last point, replayed for the comparison and the plots
    if final is None:
        out.reason += "; the estimate at the values found does not replay: the inverse model's estimates are kept"
        return out
    out.accepted, out.steps, out.names, out.theta, out.cov, out.method = True, found_steps[len(known) :], names, theta, cov, INVERSE_METHOD
    out.outcome = RefitOutcome.VALUE_SEARCH
    out.simulated, out.error_pct, out.didim = final, end.error, None
    out.value_std = {s.effect: s.std for s in searches if s.accepted and s.primary}
    searched = ", ".join(f"{s.parameter} of {s.effect}" for s in searches if s.accepted)
    out.reason += (
        f"; {searched} searched on the closed loop instead, the linear parameters IDIM-LS's at each value: "
        f"closed-loop output error {error_inverse:.3g} % -> {end.error:.3g} %"
    )
    return _confirmed(out, confirm)


def _with_didim(
    loop: ReplayLoop,
    out: Refit,
    known: list[Step],
    steps: list[Step],
    grids: Mapping[str, np.ndarray],
    run0: tuple[ClosedLoopResult, list[RunLog]],
    confirm: Callable[[Refit], str | None] | None,
) -> Refit:
    """DIDIM lowers the output error: each nonlinear value searched on the closed loop from its estimate (2), DIDIM again at the values
    found (3), kept when it does better than DIDIM at the inverse model's values; with two values or more, all at once from there (4)."""
    assert out.error_inverse_pct is not None and out.error_pct is not None
    error_inverse, error0 = out.error_inverse_pct, out.error_pct
    res0, sims0 = run0
    # 2. each nonlinear value searched on the closed loop, from DIDIM's estimate (its last replay is at that estimate)
    inverse_steps = list(steps)
    start_point = loop.point(steps, res0.result.theta, sims0[-1])
    searches, steps, start = search_all(
        known,
        steps,
        grids,
        start_point,
        loop.profile,
        loop.replays,
        len(loop.y),
        restart=True,
        max_rounds=loop.max_rounds,
        round_gain=loop.round_gain,
        joint=loop.joint,
    )
    chosen, error, sim = inverse_steps, error0, sims0[-1]
    if any(s.accepted for s in searches):
        # 3. DIDIM at the values found; kept only when it does better than DIDIM at the inverse model's values
        run1 = loop.didim(steps, start.theta)
        error1 = norm_pct(run1[0].result.error_norm, loop.y_norm) if not isinstance(run1, str) else math.inf
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
    if len(searches) >= 2 and (polished := _polished(loop, known, chosen, res0.result.theta, grids, error, searches, confirm)) is not None:
        polished.reason = f"{_didim_reason(res0, searches, error_inverse, error)}; {polished.reason}"
        polished.error_inverse_pct = error_inverse
        return polished
    model = extended(loop.base, chosen, loop.fs)
    theta = res0.result.theta
    d = lsq_rows(loop.t, sim["q"], loop.tau, loop.fs, model, loop.ls, valid=loop.prepared.valid)
    tau_s = d.decimate(np.asarray(sim["tau"], dtype=np.float64)[loop.ls.trim :])
    out.accepted, out.steps, out.names, out.theta, out.didim, out.simulated = True, chosen[len(known) :], model.names, theta, res0, sim
    out.outcome = RefitOutcome.DIDIM
    out.cov = robust_covariance(d.W, loop.y - tau_s)
    out.searches, out.error_pct = searches, error
    out.value_std = {s.effect: s.std for s in searches if s.accepted and s.primary}
    out.reason = _didim_reason(res0, searches, error_inverse, error)
    return _confirmed(out, confirm)


def _didim_reason(res: ClosedLoopResult, searches: list[ValueSearch], error_inverse: float, error: float) -> str:
    searched = ", ".join(f"{s.parameter} of {s.effect}" for s in searches if s.accepted)
    return (
        f"refitted on the closed loop ({METHOD}, {count(res.n_iterations, 'iteration')}{', ' + searched + ' searched' if searched else ''}): "
        f"closed-loop output error {error_inverse:.3g} % -> {error:.3g} %"
    )


def _output_error_fit(
    loop: ReplayLoop,
    known: list[Step],
    steps: list[Step],
    names: tuple[str, ...],
    theta: np.ndarray,
    grids: Mapping[str, np.ndarray],
    error_from: float,
    confirm: Callable[[Refit], str | None] | None,
    lead: str = "refitted instead by",
) -> Refit | str:
    """The output-error fit from ``steps`` and ``theta`` (:func:`output_error_refit`, starting at ``error_from`` %), its final
    replay kept as the estimate's (``simulated``) when it replays and ``confirm`` does not refuse it; else why not."""
    oe = output_error_refit(
        known,
        steps,
        names,
        theta,
        grids,
        lambda s, th, _: loop.residual_of(s, names, th),
        error_from,
        loop.y_norm,
        loop.round_gain,
        loop.joint,
        lead=lead,
    )
    if isinstance(oe, str):
        return oe
    if (final := loop.replayed([*known, *oe.steps], names, estimate(oe))) is None:
        return f"the {OE_METHOD} estimate does not replay"
    if confirm is not None and (why := confirm(oe)) is not None:
        return f"the {OE_METHOD} lowers it to {oe.error_pct:.3g} %, but {why}"
    oe.simulated = final
    return oe


def _polished(
    loop: ReplayLoop,
    known: list[Step],
    steps: list[Step],
    theta: np.ndarray,
    grids: Mapping[str, np.ndarray],
    error: float,
    searches: list[ValueSearch],
    confirm: Callable[[Refit], str | None] | None,
) -> Refit | None:
    """The values where the coordinate search left them (those it kept, the inverse model's for the others), with the linear
    parameters, fitted at once on the output error (:func:`_output_error_fit`): kept when it lowers the output error by
    :data:`ROUND_GAIN` of it, replays, and ``confirm`` does not refuse it (``None`` otherwise).

    Coupled values lie along a curved valley of the output error that searches one value at a time descend slowly, and stop
    where a round gains less than :data:`ROUND_GAIN`: on the robot corpus's flexibilities behind a point-to-point move (the 200
    kg axis's S-curves under a current loop, s341), at a resonance 10 % low with a load fraction 20 % low (27.8 Hz and 0.64
    for 31 Hz and 0.8; output error 0.196 %); fitted at once, 31.04 Hz and 0.804 (0.186 %, 27 replays). Tried whether or not
    a search was kept: behind the 0.5 kg·m² joint's chirp under the current loop (``--reseed 1``, s3511) the searches moved the
    resonance to 34.3 Hz and its damping ratio to 0.066, DIDIM at those values did worse (0.871 % against 0.64 %), and both
    were kept at the inverse model's (32.6 Hz, the stiffness 30 % low); fitted at once from there, within 8 %."""
    names = extended(loop.base, steps, loop.fs).names
    oe = _output_error_fit(loop, known, steps, names, theta, grids, error, confirm, lead="then every value and linear parameter at once by")
    if isinstance(oe, str):
        return None
    before = {(s.effect, s.parameter): s for s in searches}
    oe.searches = [
        replace(s, inverse=before[s.effect, s.parameter].inverse, reason=f"{before[s.effect, s.parameter].reason}; then {s.reason}")
        if (s.effect, s.parameter) in before
        else s
        for s in oe.searches
    ]
    return oe


def _confirmed(refit: Refit, confirm: Callable[[Refit], str | None] | None) -> Refit:
    """``refit``, or not accepted with the reason when ``confirm`` refuses it (its replay is then not the model file's)."""
    why = None if confirm is None or not refit.accepted else confirm(refit)
    if why is None:
        return refit
    return replace(refit, accepted=False, reason=f"{refit.reason}; {why}: the inverse model's estimates are kept", simulated=None)
