"""Replay of a log through the plant, and the relative errors of a simulation against the recording.

The replay uses the plant's public :func:`plant.simulate_replay` (the
controller of the log's metadata). A lag the recording's timing gave the loop (:data:`LAG_READ`) and a ``delay`` effect are one
lag from the sample to the force: a model with the effect replays the loop acting at its sample, the effect the whole lag. The relative errors
(:func:`ilic_cli.closed_loop_id.relative_errors`, the benchmark's simulation
table) are defined with the closed-loop estimators, which score their replays
by them, and offered here beside the replay.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from ilic_cli.closed_loop_id import relative_errors
from ilic_cli.prepare import law_inside, tau_sensor
from ilic_cli.runlog import FRICTION_LAW, RunLog
from plant.controllers import PDSettings
from plant.replay import controller_from_log, simulate_replay

__all__ = ["DRIVE_LAGS", "LAG_READ", "LAW_INSIDE_STEP_S", "REPLAY_STEP_S", "relative_errors", "replay", "replay_substeps", "tau_sensor"]

LAG_READ = "delay_samples_read"
"""The key of a PD controller's metadata saying that its ``delay_samples`` (below one period: the command acts within its sample)
was read from the recording by replaying it with a model (:func:`ilic_cli.simulation.timing.with_recorded_timing`), not
declared. That lag stands in for a lag the model lacks: it is the same lag as a ``delay`` effect's (the plant adds both to the
drive's lag), and read with a model without a drive lag it absorbs that lag (a 2 ms actuator delay on a loop written apart
from ``ilic``, acting within its sample: 0.9 of the 1 ms period read as timing and 1.15 ms left to the effect). A model with a
drive lag (:data:`DRIVE_LAGS`) is replayed with the command acting at its sample, the effect carrying the whole lag (2.03 ms
there, as the inverse model's rows say)."""

DRIVE_LAGS = ("delay", "current_loop")
"""The plant's entries that realise a drive lag (a ``delay`` effect's value: a lag shorter than a sample is the current loop's,
:func:`ilic_cli.effects.drive` ``_delay_realise``)."""

REPLAY_STEP_S = 2e-4
"""The finest integration step the diagnosis's replays need (s): a fifth of the 1 kHz period, the 500 Hz logs' tenth. Against
replays of the same plants at 20 substeps a period (50 us) it moves the noise-free replay of every catalogue effect at 1 kHz by at
most 2e-5 % of the force's RMS, 0.023 % with the 700 Hz current loop (0.23 ms), and the position by under 1e-8 m; the
sensor's own noise moves a replay by 0.6-2.6 % (a quantisation step flipped by a roundoff feeds the loop), whatever the step
(``docs/simulation.md``, "The replays' step"). A law inside the dynamics steps at :data:`LAW_INSIDE_STEP_S`."""

LAW_INSIDE_STEP_S = 1e-4
"""The integration step of a replay whose PD law acts on the plant's state at every step (``PDSettings.continuous``, the law
inside a simulator's dynamics): the law's own update interval there, which stands for a continuous law; at 0.2 ms it reads as a
law held for part of the step (a 1.5 ms actuator delay beside it at 1 kHz was then read as the held law's)."""


def replay_substeps(fs_hz: float, continuous: bool = False) -> int:
    """Integration steps per control period of a replay at ``fs_hz``: ten (a tenth of the period, as at 500 Hz and below), but
    no finer than :data:`REPLAY_STEP_S` (:data:`LAW_INSIDE_STEP_S` for a ``continuous`` law), and at least two (the drive
    lag's switch within a period; 5 at 1 kHz, 3 at 2 kHz, 2 at 4 and 8 kHz).

    Ten at every rate spent 8 times the 1 kHz work per second of an 8 kHz log on steps of 12.5 us.
    """
    step = LAW_INSIDE_STEP_S if continuous else REPLAY_STEP_S
    return max(2, min(10, math.ceil(1.0 / (fs_hz * step) - 1e-9)))


def replay(log: RunLog, params: dict[str, float], effects: dict[str, Any] | None, *, controller: PDSettings | None = None, seed: int = 0) -> RunLog:
    """Replay ``log``'s reference (and pulses) through the plant (:func:`plant.simulate_replay`).

    The controller is the log's (metadata) unless ``controller`` is given; the force sensor is the one the
    log was simulated with when it says so, else the benchmark's command
    (``tau = gtau * vir``). ``payload_change`` times are log times; the
    closed loop counts from the first sample. ``seed``: of the noise effects
    (:mod:`ilic_cli.diagnosis.null`'s replicates).
    """
    effects = dict(effects or {})
    if FRICTION_LAW in log.meta and "coulomb_smoothing" not in effects:  # the law the recording shows near zero speed
        effects["coulomb_smoothing"] = dict(log.meta[FRICTION_LAW])
    if controller is None and any(e in effects for e in DRIVE_LAGS):
        controller = _at_the_sample(log)
    if "payload_change" in effects:
        effects["payload_change"] = {**effects["payload_change"], "t_change": max(float(effects["payload_change"]["t_change"]) - float(log.t[0]), 0.0)}
    inside = controller.continuous if controller is not None else law_inside(log)  # the law the replay runs: given, else the log's
    return simulate_replay(log, params, effects, controller, substeps=replay_substeps(log.fs_hz, inside), tau_sensor=tau_sensor(log), seed=seed)


def _at_the_sample(log: RunLog) -> PDSettings | None:
    """The log's PD loop acting at its sample when its lag was read from the recording (:data:`LAG_READ`), else ``None`` (the
    log's loop as it is)."""
    recorded = log.controller
    if recorded is None or not recorded.settings.get(LAG_READ):
        return None
    ctl = controller_from_log(log)
    return replace(ctl, delay_samples=0.0) if isinstance(ctl, PDSettings) else None
