"""Stribeck friction's identification strategy (``dwell_segments``): proposed by the closed loop at a reference's dwells, refitted on
open-loop segments driven by the recorded force.

At a trapezoid's dwells the inverse model's filtered kinematics do not resolve the stick and break-away: it fits
friction below Coulomb (outside the effect's physics), or a level above it that is no estimate; the closed loop sees
it (:mod:`ilic_cli.diagnosis.dwell`). So:

- which rows: a reference that dwells (:func:`ilic_cli.diagnosis.dwell.dwells`; in place of the inverse model's proposal,
  :func:`ilic_cli.diagnosis.propose.closed_loop_proposal`), or a log whose inverse model found the effect by its F-test
  and not by its held-out test (:meth:`ilic_cli.diagnosis.select.SelectionResult.unconfirmed`);
- which scan: the candidate at the middle of the grids, its level held (:meth:`DwellSegments.propose`); on each fold's
  training blocks ``Fs`` and ``vs`` searched by noisy closed-loop replays (:meth:`DwellSegments.scan`), the folds'
  medians judged by the replay (:meth:`DwellSegments.judged`);
- which refit: the open-loop segments' output error (:func:`segment_refit`, :mod:`ilic_cli.diagnosis.segments`), whose
  estimate replaces the search's when it explains the recording to its noise, and which refutes the friction when
  its level is not above zero.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

import ilic_cli.diagnosis.dwell as dwell
import ilic_cli.diagnosis.segments as segments
from ilic_cli.diagnosis.fits import Refit, plant_problem
from ilic_cli.diagnosis.model_values import model_parameters
from ilic_cli.diagnosis.search import at_edge
from ilic_cli.diagnosis.sensor import measurement_std, position_noise
from ilic_cli.diagnosis.system import Step, SystemFit, fit_system, system
from ilic_cli.diagnosis.verdicts import RefitOutcome
from ilic_cli.effects import Effect, applicable, unit_on
from ilic_cli.errors import IlicError
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.jointlog import position_unit
from ilic_cli.lsq import solve
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import tau_sensor
from plant.closed_loop import simulate_segments
from plant.dynamics import plant_model
from plant.replay import measured_state

NOT_REFITTED = (
    "not refitted on the closed loop: the Stribeck level and vs found at the dwells are closed-loop estimates already, of the creep "
    "the sensor noise drives there, which the refit's noise-free replays do not have "
    "(the other parameters: the inverse model's, with that friction taken off the force)"
)
"""Why a Stribeck friction found at the dwells keeps its closed-loop search's estimate (when the open-loop segments' fit is not used)."""


class DwellSegments:
    """The ``dwell_segments`` strategy (:class:`~ilic_cli.diagnosis.strategies.base.IdentificationStrategy`)."""

    name = "dwell_segments"
    method = dwell.METHOD
    spread = dwell.SPREAD
    not_refitted = NOT_REFITTED

    def applies(self, log: RunLog, min_s: float, min_count: int) -> bool:
        """Whether the log's reference dwells at least ``min_count`` times ``min_s`` (:func:`ilic_cli.diagnosis.dwell.dwells`)."""
        return dwell.dwells(np.asarray(log["q_ref"]), log.fs_hz, min_s, min_count)

    def propose(self, effect: Effect, data: IDIMData, base: Model, rows: np.ndarray) -> Step | None:
        """The candidate at the middle of its grids, its level a share of the rigid Coulomb level (:func:`ilic_cli.diagnosis.dwell.proposal`)."""
        assert effect.scan is not None
        fit = fit_system(data, base, [], rows)  # the rigid Coulomb level: the scale of the levels searched (each fold's own, there)
        fc = dwell.coulomb_N(fit.names, fit.theta)
        if fc is None or not applicable(effect, fit.names):
            return None
        return dwell.proposal(effect.scan.grid(data.kin, data.fs_hz), fc, effect)

    def scan(self, step: Step, rigid: SystemFit, grid: np.ndarray, training_error: Callable[[Step | None], float]) -> Step | None:
        """``Fs`` and ``vs`` searched on a fold's training error (:func:`ilic_cli.diagnosis.dwell.search`), the levels from its rigid Coulomb level."""
        fc = dwell.coulomb_N(rigid.names, rigid.theta) or 0.0
        vs, impulse = dwell.grids(grid, fc)
        return dwell.search(step, vs, impulse, lambda st: training_error(st), training_error(None))

    def judged(self, found: list[Step | None], joint: str) -> tuple[Step | None, str]:
        """The folds' medians, and a sentence (:func:`ilic_cli.diagnosis.dwell.judged`)."""
        return dwell.judged(found, joint)

    def fold_values(self, found: list[Step | None]) -> list[Any]:
        """Each fold's ``(vs, Fs)`` (:func:`ilic_cli.diagnosis.dwell.fold_values`)."""
        return dwell.fold_values(found)

    def refit(
        self,
        log: RunLog,
        data: IDIMData,
        base: Model,
        rows: np.ndarray,
        ls: LSSettings,
        known: list[Step],
        kept: list[Step],
        hold: float,
        *,
        segment_s: float = segments.SEGMENT_S,
        level_z: float = segments.LEVEL_Z,
    ) -> tuple[Refit, str | None]:
        """The open-loop segments' refit (:func:`segment_refit`)."""
        return segment_refit(log, data, base, rows, ls, known, kept, hold, segment_s=segment_s, level_z=level_z)


DWELL_SEGMENTS = DwellSegments()


def segment_refit(
    log: RunLog,
    data: IDIMData,
    base: Model,
    rows: np.ndarray,
    ls: LSSettings,
    known: list[Step],
    kept: list[Step],
    hold: float,
    *,
    segment_s: float = segments.SEGMENT_S,
    level_z: float = segments.LEVEL_Z,
) -> tuple[Refit, str | None]:
    """The Stribeck friction found at the dwells (the last of ``kept``, its level held), refitted on the open-loop segments.

    Every linear parameter of the model, the Stribeck level, and the nonlinear value of each kept effect searched on a
    log scale (Stribeck ``vs``, a ripple's period, ...; a pair of values, or one on a linear scale, is held) are fitted
    by :func:`ilic_cli.diagnosis.segments.fit_segments`, the recorded force driving the plant
    (:func:`plant.closed_loop.simulate_segments`); started from the inverse model's fit and the closed-loop search's
    level and ``vs``. The fit replaces those when its residual is the sensor's noise
    (:attr:`~ilic_cli.diagnosis.segments.SegmentFit.consistent`), the model it gives is a plant of the effects it
    names, and no value is on the edge of its effect's grid; else the search's estimate is kept, and the reason says
    which failed. Only a log whose force is the drive's held command is fitted so.

    Returns the refit and, when the fit's residual is the sensor's noise but its Stribeck level is not
    :data:`~ilic_cli.diagnosis.segments.LEVEL_Z` standard deviations above zero, why the recording refutes the
    friction the closed-loop search found (else ``None``).
    """
    st = kept[-1]
    assert st.level is not None
    W, y, names = system(data, base, [*known, *kept], rows)
    theta = solve(W, y, names, sigma=ls.sigma).theta
    if tau_sensor(log) != "command":
        why = NOT_REFITTED + "; the recorded force is not the drive's command, so no open-loop fit"
        return Refit(False, why, list(kept), names, outcome=RefitOutcome.AT_DWELLS), None
    fs = log.fs_hz
    model = [*kept[:-1], Step(st.effect, st.value)]
    free = [k for k, s in enumerate(model) if s.effect.scan is not None and s.effect.scan.log and isinstance(s.value, float)]
    names_fit = (*names, *st.effect.column_names)
    n_lin = len(names_fit)
    p0 = np.r_[theta, st.level, [np.log(float(model[k].value)) for k in free]]
    tau = np.asarray(log["tau"], dtype=np.float64)
    zero = np.zeros((n_lin, n_lin))

    def model_at(p: np.ndarray) -> list[Step]:
        values = dict(zip(free, np.exp(p[n_lin:]), strict=True))
        return [*known, *(Step(s.effect, float(values[k])) if k in values else s for k, s in enumerate(model))]

    q = np.asarray(log["q"], dtype=np.float64)
    noise = measurement_std(*position_noise(q, fs, ls))
    length = int(round(segment_s * fs))
    starts = segments.segment_starts(len(q), length, ls.trim)

    def simulate(p: np.ndarray, states: np.ndarray) -> np.ndarray:
        rigid, effects = model_parameters(model_at(p), names_fit, p[:n_lin], zero, hold)
        params, eff = plant_model(rigid, effects)
        return simulate_segments(params=params, effects=eff, command=tau, fs_hz=fs, starts=starts, length=length, x0=states, substeps=segments.SUBSTEPS)

    try:
        fit = segments.fit_segments(
            q,
            np.column_stack(measured_state(q, fs)),
            simulate,
            p0,
            np.r_[1e-3 * np.maximum(np.abs(p0[:n_lin]), 1.0), np.full(len(free), 0.01)],
            (*names_fit, *(f"log_{scan.name}" for k in free if (scan := model[k].effect.scan) is not None)),
            noise,
            starts=starts,
            length=length,
            max_step=np.r_[np.full(n_lin, np.inf), np.full(len(free), 0.5)],
        )
    except IlicError as exc:  # a sensitivity's step that gives no plant, a segment that diverges: the search's estimate stands
        return Refit(False, f"{NOT_REFITTED}; the {segments.METHOD} failed: {exc.problem}", list(kept), names, outcome=RefitOutcome.AT_DWELLS), None
    assert st.effect.scan is not None
    least = float(dwell.grids(st.effect.scan.grid(data.kin, fs), dwell.coulomb_N(names, theta) or 0.0)[1][0])
    return _segments_judged(fit, model_at(fit.values), st, kept, known, free, names, names_fit, data, fs, noise, (segment_s, level_z), least)


def _segments_judged(
    fit: segments.SegmentFit,
    final: list[Step],
    st: Step,
    kept: list[Step],
    known: list[Step],
    free: list[int],
    names: tuple[str, ...],
    names_fit: tuple[str, ...],
    data: IDIMData,
    fs: float,
    noise: float,
    tuning: tuple[float, float],
    least_impulse: float,
) -> tuple[Refit, str | None]:
    """The open-loop segments' fit of :func:`segment_refit` judged: kept, refuting the friction, or not used (and why).

    ``tuning``: the segments' length (s) and the level's least standard deviations above zero. ``least_impulse``: the least
    impulse ``Fs·vs`` the closed-loop search tries (:func:`ilic_cli.diagnosis.dwell.grids`), where it ends on a log without
    the friction. A fit that explains the recording to its noise refutes the friction when its level is not
    ``level_z`` standard deviations above zero, or its impulse is below that least one: the search would have read such a
    friction as none, so the replay judged another (measured, the independent corpus's 12 kg trapezoid at 250 Hz without
    any Stribeck friction, under the loop a period late: the folds' Fs of 4.95-5.43 N and vs of 4.4-4.9 mm/s judged, the
    segments' fit Fs 0.0104 N and vs 43 mm/s, an impulse 0.24 times the least; on the robot corpus's Stribeck logs the fit's
    impulse is 96 to 190 times it).
    """
    segment_s, level_z = tuning
    assert st.level is not None
    n_lin = len(names_fit)
    micro, force = position_unit(data.joint, "u"), unit_on("N", data.joint)
    what = (
        f"{fit.segments} segments of {segment_s:g} s driven by the recorded force, residual {1e6 * fit.rms_m:.3g} {micro} RMS "
        f"for a sensor noise of {1e6 * noise:.3g} {micro} (from {1e6 * fit.rms_start_m:.3g} {micro}), {fit.iterations} iterations"
    )
    theta_fit = fit.values[:n_lin]
    at = names_fit.index(st.effect.column_names[0])
    level, level_std = float(theta_fit[at]), float(fit.std[at])
    impulse = level * float(final[-1].value)  # Fs·vs: the last step of the model is the friction found at the dwells
    if fit.consistent and not (level > level_z * level_std and impulse >= least_impulse):
        why_not = (
            f"is not {level_z:g} standard deviations above zero"
            if not level > level_z * level_std
            else f"with its vs gives an impulse Fs·vs of {impulse:.3g} {force}·{position_unit(data.joint)}/s, below the least the closed-loop "
            f"search tries ({least_impulse:.3g}: what it reads as no friction)"
        )
        refuted = (
            f"refuted by the {segments.METHOD} ({what}): the residual is the sensor's noise, "
            f"and the level it gives Stribeck friction, {level:.3g} +- {level_std:.2g} {force}, "
            f"{why_not} (the closed-loop search's {st.level[0]:.3g} {force} is not the recording's)"
        )
        return Refit(False, refuted, list(kept), names, segments=fit, outcome=RefitOutcome.SEGMENTS_REFUTED), refuted
    problem = plant_problem(final[len(known) :], names_fit, theta_fit, joint=data.joint)
    edges = [e for k in free if (e := _edge_of(final[len(known) + k], data, fs))]
    why = (
        "it did not converge"
        if not fit.converged
        else f"its residual is more than {segments.NOISE_FACTOR:g} times the sensor's noise (the recorded force does not explain the motion alone)"
        if not fit.consistent
        else f"its model is no plant ({problem})"
        if problem
        else "; ".join(edges)
        if edges
        else None
    )
    if why is not None:
        why = f"{NOT_REFITTED}; the {segments.METHOD} ({what}) is not used: {why}"
        return Refit(False, why, list(kept), names, segments=fit, outcome=RefitOutcome.AT_DWELLS), None
    std = fit.std[n_lin:]
    return Refit(
        True,
        f"{what}: the residual is the sensor's noise, so the estimate is the recording's",
        final[len(known) :],
        names_fit,
        theta_fit,
        fit.cov[:n_lin, :n_lin],
        value_std={final[len(known) + k].effect.id: float(final[len(known) + k].value) * float(s) for k, s in zip(free, std, strict=True)},
        method=segments.METHOD,
        segments=fit,
        outcome=RefitOutcome.SEGMENTS,
    ), None


def _edge_of(step: Step, data: IDIMData, fs: float) -> str | None:
    """Why ``step``'s value is on the edge of its effect's grid (:func:`ilic_cli.diagnosis.search.at_edge`), else ``None``."""
    assert step.effect.scan is not None
    return at_edge(step.effect, step.effect.scan.grid(data.kin, fs), step.value, data.joint)
