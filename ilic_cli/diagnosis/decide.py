"""Stage 2 of the diagnosis, decide: which proposed effects are findings (:func:`decide`).

A proposed effect becomes a finding only when it is material (:mod:`ilic_cli.diagnosis.materiality`) and, when
the log can be replayed, the closed-loop replay agrees (:mod:`ilic_cli.diagnosis.heldout_replay`: refitted
without each of ``k`` contiguous time blocks, the recorded reference replayed through the log's controller and
the plant with and without it, the held-out simulated force error must fall significantly, the held-out
position error and the validation log's error must not rise). Each decision is a typed
:class:`~ilic_cli.diagnosis.verdicts.ReplayVerdict` (its :class:`~ilic_cli.diagnosis.verdicts.Verdict`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.compare import band_force_error
from ilic_cli.diagnosis.drift import GivenDrift
from ilic_cli.diagnosis.heldout_replay import REPLAY_SEED, HeldoutReplays, decision_sensor, noisy_output_error, replay_decide
from ilic_cli.diagnosis.materiality import MATERIAL_FORCE, MIN_DELAY_PERIODS, below_period, effect_force_rms, immaterial, materiality
from ilic_cli.diagnosis.model_values import model_parameters
from ilic_cli.diagnosis.null import MonteCarloNull
from ilic_cli.diagnosis.propose import Proposal, closed_loop_proposal, prepare_system
from ilic_cli.diagnosis.search import FOLD_XATOL_STEPS, fold_value
from ilic_cli.diagnosis.select import SelectionResult, still_proposed
from ilic_cli.diagnosis.settings import DiagnosisSettings, replay_alpha
from ilic_cli.diagnosis.system import Step, change_time, system
from ilic_cli.diagnosis.verdicts import DM_TEST, PROPOSED_BY_DRIFT, PROPOSED_BY_INVERSE, PlantOf, ReplayVerdict, Verdict, replay_verdict
from ilic_cli.effects import EFFECTS
from ilic_cli.prepare import prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.usable import with_rest

__all__ = [  # the stage, and the names of its parts importable from here as before the split
    "DM_TEST",
    "FOLD_XATOL_STEPS",
    "MATERIAL_FORCE",
    "MIN_DELAY_PERIODS",
    "PROPOSED_BY_DRIFT",
    "PROPOSED_BY_INVERSE",
    "REPLAY_SEED",
    "Decision",
    "PlantOf",
    "ReplayVerdict",
    "Verdict",
    "band_force_error",
    "below_period",
    "decide",
    "decision_sensor",
    "effect_force_rms",
    "fold_value",
    "immaterial",
    "materiality",
    "noisy_output_error",
    "replay_decide",
    "replay_drift",
    "without_last",
]

DRIFT = EFFECTS["friction_drift"].id
"""The catalogue's id of a friction drift, the effect :func:`replay_drift` judges."""


@dataclass
class Decision:
    """What the decision kept of the proposal.

    Attributes
    ----------
    kept : list of Step
        The proposed effects that are findings, in order (not the model file's).
    verdicts : list of ReplayVerdict
        One per proposed effect, in the order of the proposals.
    sensor : dict or None
        The sensor noise the replays carried (:func:`~ilic_cli.diagnosis.heldout_replay.decision_sensor`); ``None`` when none ran or they were noise-free.
    """

    kept: list[Step]
    verdicts: list[ReplayVerdict]
    sensor: dict[str, Any] | None

    def searched_on_folds(self) -> dict[str, tuple[Any, ...]]:
        """Effect id -> the values its replay searched on each fold's training blocks (:attr:`ReplayVerdict.searched`), for each
        effect the inverse model proposed and the replay kept."""
        return {v.effect: v.searched for v in self.verdicts if v.accepted and v.searched and v.proposed_by == PROPOSED_BY_INVERSE}


def decide(log: RunLog, prop: Proposal, settings: DiagnosisSettings, validate: RunLog | None, against: RunLog | None) -> Decision:
    """The proposed steps that are material and, when the log can be replayed, that the replay keeps.

    ``log`` is the recording as the replays run it (its loop timing read from it: :func:`ilic_cli.simulation.timing.recorded_loop`).
    Every evaluation the inverse model accepted gets the verdict as its decision (``prop.selection.tried`` is updated in place).
    """
    data, base, known, selection, rows = prop.data, prop.base, prop.known, prop.selection, prop.rows
    material: list[Step] = []
    sensor = None
    verdicts: list[ReplayVerdict] = []
    kept_so_far = list(known)
    replayable = settings.simulate and against is None and "q_ref" in log
    for st in selection.steps:
        # without a replay the inverse model's value is the estimate: a delay too short for a finding goes now
        why = materiality(data, base, kept_so_far, st, rows, settings.material_force)
        short = None if why or replayable else below_period(st, data.fs_hz, settings.min_delay_periods)
        if why or short:
            verdicts.append(ReplayVerdict.unjudged(st.effect.id, Verdict.NOT_MATERIAL if why else Verdict.BELOW_PERIOD, why or short or ""))
        else:
            material.append(st)
            kept_so_far.append(st)
    material_ids = {s.effect.id for s in material}
    immaterial = [s for s in selection.steps if s.effect.id not in material_ids]
    if replayable and (on_loop := closed_loop_proposal(log, data, base, known, immaterial, rows, settings, selection)) is not None:
        material = in_its_place(material, on_loop, [s.effect.id for s in selection.steps])  # at the dwells, the strategy values it
    if replayable and material:
        plant_of = proposal_plant(prop)
        v = (validate, settings.ls) if validate is not None and "q_ref" in validate else None
        ns = settings.null
        null = None
        if ns.kind == "montecarlo":
            null = MonteCarloNull(
                ns.replicates,
                ns.seed,
                settings.ls,
                lambda lg: prepare_system(with_rest(prepare_log(lg), settings.ls), base, settings.ls),
                settings.replay_noise,
            )
        if settings.replay_noise:
            sensor = decision_sensor(log, settings.ls, data, base, known, rows, plant_of, prop.drift)
        kept, judged = replay_decide(
            log,
            data,
            base,
            known,
            material,
            rows,
            plant_of,
            folds=settings.select.folds,
            alpha=replay_alpha(settings),
            validate=v,
            null=null,
            sensor_noise=settings.replay_noise,
            sensor=sensor,
            min_delay_periods=settings.min_delay_periods,
            fold_xatol_steps=settings.fold_xatol_steps,
            drift=prop.drift,
        )
        verdicts += judged
        kept, verdicts = proposed_again(prop, settings, kept[len(known) :], verdicts)
    else:
        kept = material
    _record(selection, material, verdicts)
    order = [s.effect.id for s in selection.steps] + [s.effect.id for s in material if s.level is not None]
    verdicts.sort(key=lambda v: order.index(v.effect))
    return Decision(kept, verdicts, sensor)


def in_its_place(material: list[Step], on_loop: Step, order: list[str]) -> list[Step]:
    """``material`` (steps of ``order``, the selection's effects, material or not) with the closed loop's proposal ``on_loop``
    where the inverse model proposed its effect, in place of that step; last when the inverse model did not propose it.

    The replay judges the steps in order, each on the plant of those before it (:func:`replay_decide`). Put last, a Stribeck
    friction the inverse model proposed first left the steps after it judged on a plant without it: on ``--beyond``'s
    3 kg·m² S-curve at 1.5 kHz with the current loop (Stribeck friction 4.8 Fc, s5059) a lag of -0.372 ms, the inverse
    model's second step, was kept for a held-out force error of 25.9 % -> 24.9 % beside the friction's 24.9 % -> 1.59 %;
    judged after the friction it is rejected (1.20 % -> 1.21 %), and only the friction is named.
    """
    rank = {eid: i for i, eid in enumerate(order)}
    place = rank.get(on_loop.effect.id, len(order))  # not proposed there: after every step
    out = [s for s in material if s.effect.id != on_loop.effect.id]
    at = next((i for i, s in enumerate(out) if rank[s.effect.id] > place), len(out))
    out.insert(at, on_loop)
    return out


def proposed_again(prop: Proposal, settings: DiagnosisSettings, kept: list[Step], verdicts: list[ReplayVerdict]) -> tuple[list[Step], list[ReplayVerdict]]:
    """``kept`` without the inverse model's proposals it no longer proposes once a closed-loop proposal is kept, and ``verdicts`` saying
    why (:data:`Verdict.NOT_PROPOSED_AGAIN`).

    The inverse model proposed each on the model of the effects accepted before it, without the one the closed loop proposes at
    the dwells (Stribeck friction, whose ``vs`` it biases): a breakaway's force, rising before the motion, is what a drive lag
    makes (corpus, Stribeck friction six times the Coulomb level on the 0.5 kg·m² joint's trapezoid, s9461: a lag of -0.67 ms
    proposed at p = 4.1e-11 beside the inverse model's Stribeck column at its ``vs``; the friction valued on the closed loop
    then kept). Each is tried again by the inverse model on the model of every other effect kept, the closed-loop one's level held
    (:func:`~ilic_cli.diagnosis.select.still_proposed`), by the same F-test at the same level, its candidates counted as at the
    step that proposed it; not significant there (or impossible, or on its search's edge), it is no finding.
    """
    if not any(s.level is not None for s in kept):
        return kept, verdicts
    out = list(kept)
    for st in kept:
        if st.level is not None:
            continue
        at = prop.selection.last_at(st.effect.id)
        assert at is not None  # the inverse model proposed it: it was tried
        n = len(prop.selection.tried[at[0]])
        others = [*prop.known, *(s for s in out if s is not st)]
        given = None
        if prop.drift is not None:
            W, _, names = system(prop.data, prop.base, others, prop.rows)
            given = prop.drift.columns(prop.data.t_dec[prop.rows], W, names)
        ev = still_proposed(prop.data, prop.base, prop.rows, others, st, n, given)
        if ev is None:
            continue
        loop = ", ".join(s.effect.id for s in out if s.level is not None)
        if not ev.outcome.never_a_finding and ev.test.p_adjusted < settings.select.alpha:
            # still proposed: its value stays the one the replay judged. Measured: the value the inverse model proposes on this
            # model is no better (a 700 Hz current loop's 0.227 ms lag beside Stribeck friction: s6460 -0.392 -> -0.231 ms, but
            # s210 -0.239 -> -0.080 ms and s460 -0.196 -> -0.088 ms: the held level's error moves it as much)
            continue
        out.remove(st)
        why = f"no longer proposed by the inverse model with {loop} (valued on the closed loop) in the model: {ev.reason or f'p = {ev.test.p_adjusted:.2g}'}"
        verdicts = [
            replace(v, accepted=False, reason=f"{v.reason}; {why}", verdict=Verdict.NOT_PROPOSED_AGAIN) if v.effect == st.effect.id and v.accepted else v
            for v in verdicts
        ]
    return out, verdicts


def proposal_plant(prop: Proposal) -> PlantOf:
    """The plant of a fit on ``prop``'s system (its hold in the plant): what every deciding replay simulates."""

    def plant_of(steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> tuple[dict[str, float], dict[str, Any]]:
        return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))), prop.hold)

    return plant_of


def replay_drift(
    log: RunLog, prop: Proposal, kept: list[Step], drift: GivenDrift, settings: DiagnosisSettings, sensor: dict[str, Any] | None
) -> tuple[ReplayVerdict, dict[str, Any] | None]:
    """The replay's word on a friction drift found on the model of the effects ``kept`` (issue 29 item 5: the replay checks it as any
    other effect): the held-out replays of that model without and with the drift's trends (each fold refitted with their columns,
    its plant's friction drifting: :func:`~ilic_cli.diagnosis.fold_plant.fitted_plant`), judged by the same test at the same
    level, with the same sensor noise as every candidate (``sensor``, the decision's; ``None``: estimated here, or none when the settings
    replay noise-free); and the sensor noise the replays carried."""
    plant_of = proposal_plant(prop)
    if sensor is None and settings.replay_noise:  # no candidate was replayed: the noise they would have carried
        sensor = decision_sensor(log, settings.ls, prop.data, prop.base, prop.known, prop.rows, plant_of, prop.drift)
    replays = HeldoutReplays(log, prop.data, prop.base, prop.rows, plant_of, settings.select.folds, sensor or {}, change_time(kept))
    without = replays.heldout(kept)
    replays.drift = drift
    within = replays.heldout(kept)
    if without is None or within is None:
        return ReplayVerdict.unjudged(DRIFT, Verdict.NO_PLANT, "the fitted model is not a valid plant: no replay", PROPOSED_BY_DRIFT), sensor
    # judged where the reference moves: a friction coefficient's drift acts in motion, and at rest the replay's stuck axis and the
    # recording's hold forces that two friction laws set apart (a Coulomb friction smoothed by tanh creeps at the dwells where the
    # plant's sticks: an independent simulator's warm-up of Fv on the 0.5 kg·m² joint, held-out 7.01 % -> 7.65 % over every sample)
    (fb, fa), (pb, pa), p, _ = replays.compared(without, within, moving=True)
    verdict, why = replay_verdict((fb, fa), (pb, pa), (None, None), p < replay_alpha(settings), f"p = {p:.2g}", None)
    why += " (where the reference moves)"
    return ReplayVerdict(DRIFT, fb, fa, pb, pa, p, None, None, verdict is Verdict.AGREES, why, proposed_by=PROPOSED_BY_DRIFT, verdict=verdict), sensor


def _record(selection: SelectionResult, material: list[Step], verdicts: list[ReplayVerdict]) -> None:
    """Every evaluation the inverse model accepted gets the verdict as its decision (in place); a closed-loop proposal's verdict is
    written beside the inverse model's last word on it."""
    by_effect = {v.effect: v for v in verdicts}
    on_loop = {st.effect.id for st in material if st.level is not None and st.effect.id in by_effect}
    for step in selection.tried:
        for i, ev in enumerate(step):
            if ev.accepted and ev.effect in by_effect and ev.effect not in on_loop:
                step[i] = replace(ev, accepted=by_effect[ev.effect].accepted, reason=f"{ev.reason}; {by_effect[ev.effect].reason}")
    for eid in on_loop:  # the closed loop's proposal: its verdict beside the inverse model's last word on it
        if (at := selection.last_at(eid)) is not None:
            k, i = at
            ev = selection.tried[k][i]
            # accepted: at the dwells, or confirmed held out as a proposal but not at the replay's level; else rejected by the inverse model
            how = "valued on the closed loop instead" if ev.accepted else "proposed on the closed loop instead"
            selection.tried[k][i] = replace(ev, accepted=ev.accepted and by_effect[eid].accepted, reason=f"{ev.reason}; {how}: {by_effect[eid].reason}")


def without_last(kept: list[Step], verdicts: list[ReplayVerdict], why: str) -> tuple[list[Step], list[ReplayVerdict]]:
    """``kept`` without its last effect, and ``verdicts`` with that effect's accepting verdict turned into a rejection that says ``why``."""
    gone = kept[-1].effect.id
    return kept[:-1], [
        replace(v, accepted=False, reason=f"{v.reason}; {why}", verdict=Verdict.REFUTED) if v.effect == gone and v.accepted else v for v in verdicts
    ]
