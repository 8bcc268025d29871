"""Replay of a log through the plant, and the relative errors of a simulation against the recording.

The replay uses the plant's public :func:`plant.simulate_replay` (the
controller of the log's metadata). The relative errors
(:func:`ilic_cli.closed_loop_id.relative_errors`, the benchmark's simulation
table) are defined with the closed-loop estimators, which score their replays
by them, and offered here beside the replay.
"""

from __future__ import annotations

from typing import Any

from ilic_cli.closed_loop_id import relative_errors
from ilic_cli.prepare import tau_sensor
from ilic_cli.runlog import RunLog
from plant.controllers import PDSettings
from plant.replay import simulate_replay

__all__ = ["relative_errors", "replay", "tau_sensor"]


def replay(log: RunLog, params: dict[str, float], effects: dict[str, Any] | None, *, controller: PDSettings | None = None, seed: int = 0) -> RunLog:
    """Replay ``log``'s reference (and pulses) through the plant (:func:`plant.simulate_replay`).

    The controller is the log's (metadata) unless ``controller`` is given; the force sensor is the one the
    log was simulated with when it says so, else the benchmark's command
    (``tau = gtau * vir``). ``payload_change`` times are log times; the
    closed loop counts from the first sample. ``seed``: of the noise effects
    (:mod:`ilic_cli.diagnosis.null`'s replicates).
    """
    effects = dict(effects or {})
    if "payload_change" in effects:
        effects["payload_change"] = {**effects["payload_change"], "t_change": max(float(effects["payload_change"]["t_change"]) - float(log.t[0]), 0.0)}
    return simulate_replay(log, params, effects, controller, tau_sensor=tau_sensor(log), seed=seed)
