"""The loop that ran and the friction law near zero speed, read from the recording before any candidate is decided.

Three readings, each proposed by the inverse model and decided by replays of the recording (:func:`read_the_loop`):

1. **The loop's timing** (:func:`ilic_cli.simulation.timing.recorded_loop`): which sample the recorded command follows, with
   which velocity estimate, and the lag of a command acting within its sample.
2. **A law inside the dynamics.** A simulator that writes its PD law in the right-hand side of its ODE (``solve_ivp``, or an
   Euler loop that computes the command every step) applies it on the plant's state at every instant and logs it at the
   samples; at the samples the command is the law on the plant's own velocity, as a discrete loop fed the state records it.
   The two differ between the samples: the discrete loop holds its command over the period, whose half-period lag the
   inverse model's hold (:func:`ilic_cli.prepare.force_hold_s`) then assumes. On a law inside the dynamics that hold
   mistimes the force by half a period: a 500 Hz chirp's clean log got a rising viscous friction (a drift, +6.7 %), and a
   1.5 ms drive lag came out 1.03 ms. When the law reads on the plant's velocity at its sample, each hypothesis is proposed
   by the inverse model with its own hold and replayed with its own loop (:attr:`plant.controllers.PDSettings.continuous`),
   and the law inside the dynamics is taken when its replay's force error is below :data:`~ilic_cli.simulation.pd_law.CLEAR_GAIN` of the held
   law's and its position error lower. Each hypothesis's fit absorbs most of the other's timing (the held law's proposes a lag
   of about half a period), so the decision asks for a clear margin. Measured on the independent simulator
   (:mod:`tests.corpus.independent`, 64 logs: the 12 kg axis and the 0.5 kg·m² joint, trapezoids and chirps, 500 Hz and
   2 kHz, clean, a drive lag, Stribeck friction, a warm-up): with the law inside the dynamics the ratio is 0.02-0.49 but with
   a drive lag (0.62-3.3: a lag beside that law reads as the held law's, half a period shorter) or Stribeck friction on the
   trapezoids (0.81-1.0); with the discrete loop fed the state, 0.89-3.6.
3. **The friction law near zero speed** (:mod:`ilic_cli.diagnosis.friction_law`), with the model of the loop read. A smoothed
   law read, the inverse model proposes again with the law's sign in its friction columns, as the plant puts it there: on the
   independent simulator's tanh friction, gravity on the 0.5 kg·m² joint's chirps MX 39-76 % off -> 2-40 %, a warm-up's
   time constant 20 % -> within 2 %.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from ilic_cli.diagnosis.friction_law import FrictionLaw, read_friction_law, with_friction_law
from ilic_cli.diagnosis.propose import Proposal
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.errors import IlicError
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.pd_law import inside_is_closer, law_may_act_inside
from ilic_cli.simulation.replay import relative_errors, replay
from ilic_cli.simulation.timing import ControlTiming, recorded_loop, with_pd_law

Model = tuple[dict[str, float], dict[str, Any]]
"""Rigid parameters and plant effects of a replay."""


def read_the_loop(
    prop: Proposal,
    settings: DiagnosisSettings,
    log: RunLog,
    validate: RunLog | None,
    models: Callable[[Proposal], tuple[Model, Model, Model]],
    proposed_again: Callable[[RunLog], Proposal],
) -> tuple[Proposal, RunLog, RunLog | None, ControlTiming | None, FrictionLaw]:
    """The loop that ran and the friction law (module docstring): the proposal (again, for a law inside the dynamics), the log the
    replays run and its validation log, the timing and the law.

    ``models(prop)``: the model the timing is read with, the same with a proposed drive lag (replayed at the sample), and the
    rigid fit; ``proposed_again(log)``: the inverse model's proposal on ``log`` (its loop read: its hold)."""
    timed, lagged, rigid = models(prop)
    timed_log, timing = recorded_loop(log, *timed, settings.ls)
    if timing is None and timed != rigid:  # the proposal does not replay: the rigid fit
        timed = lagged = rigid
        timed_log, timing = recorded_loop(log, *timed, settings.ls)
    if timing is not None and law_may_act_inside(timing.law):
        inside = _inside_the_dynamics(log, timed_log, timing, lagged, models, proposed_again, settings)
        if inside is not None:
            prop, timed_log, timing, lagged = inside
    law = read_friction_law(timed_log, prop.data, prop.base, prop.known, prop.rows, lagged, settings.ls, settings.select.alpha)
    if law.vc is None and law.candidate is not None and law.after and law.after["position"] < law.before["position"]:
        law = _with_its_own_fit(timed_log, law, models, proposed_again, settings)
    timed_log = with_friction_law(timed_log, law)
    if law.vc is not None:  # the inverse model proposes again with the law's sign in its friction columns, as the plant has it
        prop = proposed_again(timed_log)
    if validate is not None:
        validate = with_friction_law(recorded_loop(validate, *timed, settings.ls)[0], law)
    return prop, timed_log, validate, timing, law


def _with_its_own_fit(
    timed_log: RunLog,
    law: FrictionLaw,
    models: Callable[[Proposal], tuple[Model, Model, Model]],
    proposed_again: Callable[[RunLog], Proposal],
    settings: DiagnosisSettings,
) -> FrictionLaw:
    """A smoothed law that brought the replay closer but not clearly, judged again with a model of its own: the inverse model's
    proposal under the law's sign at the candidate's speed, the law's speed searched with it, against stick/slip's errors with
    its own model (:func:`~ilic_cli.diagnosis.friction_law.read_friction_law`'s ``stick_slip``); ``law`` when not kept so.

    The rigid fit made with the plain sign carries the law's difference near zero speed in its Coulomb and viscous levels (and
    a warm-up it proposes): with ``Fc tanh(v/eps)``, eps 5 % of the cruise speed, on the independent simulator's 12 kg chirp
    at 1 kHz the law's search with that fit brought the position error to 0.55 of stick/slip's only, the law was refused, and
    the clean log got a friction drift (Fv -50 %, Fc +56 %)."""
    speed, again = law.candidate, law
    assert speed is not None  # the caller's: a candidate replayed
    for _ in range(OWN_FIT_ROUNDS):  # the model fitted at the speed the last search found, until that speed holds
        try:
            prop = proposed_again(with_friction_law(timed_log, replace(law, vc=speed)))
            again = read_friction_law(
                timed_log, prop.data, prop.base, prop.known, prop.rows, models(prop)[1], settings.ls, settings.select.alpha, stick_slip=law.before
            )
        except IlicError:  # no proposal or no replay under the law: stick/slip stays
            return law
        if again.vc is None or abs(again.vc / speed - 1.0) < OWN_FIT_TOL:
            break
        speed = again.vc
    if again.vc is None:
        return law
    return replace(again, reason=f"{again.reason}, the model fitted under the law's sign (with the plain sign's fit: {law.reason})")


OWN_FIT_ROUNDS, OWN_FIT_TOL = 4, 0.05
"""At most this many fits under a smoothed law's sign (:func:`_with_its_own_fit`), until the speed the search finds is within
this share of the one the model was fitted at."""


def _inside_the_dynamics(
    log: RunLog,
    timed_log: RunLog,
    timing: ControlTiming,
    lagged: Model,
    models: Callable[[Proposal], tuple[Model, Model, Model]],
    proposed_again: Callable[[RunLog], Proposal],
    settings: DiagnosisSettings,
) -> tuple[Proposal, RunLog, ControlTiming, Model] | None:
    """The proposal, log, timing and model (with its drive lag) of the law inside the dynamics when its replay explains the recording
    clearly better than the held law's (:func:`~ilic_cli.simulation.pd_law.inside_is_closer`), each with the inverse model's
    proposal under its own hold; else ``None``."""
    inside = replace(timing, continuous=True)
    inside_log = with_pd_law(log, continuous=True)
    try:
        held = relative_errors(log, replay(timed_log, *lagged), settings.ls)
        prop = proposed_again(inside_log)
        model = models(prop)[1]
        errors = relative_errors(log, replay(inside_log, *model), settings.ls)
    except IlicError:  # either model does not replay: the held law stays
        return None
    if not inside_is_closer(held, errors):
        return None
    return prop, inside_log, replace(inside, held=held, refined=errors), model


def lag_if_inside(timing: ControlTiming | None, fs_hz: float, delay: float) -> tuple[float, str] | None:
    """What a drive lag's finding (``delay`` s, negative: a lag) adds when the command reads as the law on the plant's velocity at
    its sample and the replays hold it over the period: the delay a law inside the dynamics would have instead, half a period
    longer, and the words (``None`` otherwise). The two loops differ only between the samples, and with a lag beside them barely:
    on the independent simulator's 12 kg chirp at 1 kHz (law inside, 1.5 ms) the true model's replay has a force error of 0.033 %
    inside, the held law with 1.0 ms 0.043 %, short of the margin the loop's reading asks (:data:`~ilic_cli.simulation.pd_law.CLEAR_GAIN`)."""
    if timing is None or timing.continuous or not law_may_act_inside(timing.law):
        return None
    inside = delay - 0.5 / fs_hz
    return inside, (
        f"if the simulator computes its PD law inside its dynamics (on the state at every instant, as a solver's right-hand side) "
        f"instead of holding its command over the period, the lag is half a period longer, {-1e3 * inside:.3g} ms: the recording "
        "tells the two apart only weakly"
    )
