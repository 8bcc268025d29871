"""Replay of a log through the plant, and the relative errors of a simulation against the recording.

The replay uses the plant's public :func:`plant.simulate_replay` (the
controller of the log's metadata). Relative errors follow the benchmark's
simulation table: position, and velocity from the filtered position (as
IDIM-LS), first samples dropped; force ``100 ||tau_sim - tau|| / ||tau||``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ilic_cli.filtering import butter_lowpass_zero_phase, central_difference
from ilic_cli.idim_ls import LSSettings
from ilic_cli.lsq import relative_error_pct
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


def relative_errors(rec: RunLog, sim: RunLog, ls: LSSettings) -> dict[str, float]:
    """Relative errors (%) of position, velocity and force of ``sim`` against ``rec`` (first ``trim`` samples dropped)."""
    fs = rec.fs_hz
    n = min(len(rec), len(sim))
    s = slice(ls.trim, n)

    def vel(q: np.ndarray) -> np.ndarray:
        return central_difference(butter_lowpass_zero_phase(q[:n], ls.cutoff_hz, fs, ls.order, matlab=ls.matlab), 1.0 / fs)

    return {
        "position": relative_error_pct(rec["q"][s], sim["q"][s]),
        "velocity": relative_error_pct(vel(rec["q"])[s], vel(sim["q"])[s]),
        "force": relative_error_pct(rec["tau"][s], sim["tau"][s]),
    }
