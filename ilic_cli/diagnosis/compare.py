"""Simulation against recording: replay the recorded reference through the plant and compare.

The replay uses the plant's public :func:`plant.simulate_replay` (the
controller of the log's metadata). Relative errors follow the benchmark's
simulation table: position, and velocity from the filtered position (as
IDIM-LS), first samples dropped; force ``100 ||tau_sim - tau|| / ||tau||``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.diagnosis.locate import Region, locate
from ilic_cli.filtering import butter_lowpass_zero_phase, central_difference
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.lsq import relative_error_pct
from ilic_cli.prepare import tau_sensor
from ilic_cli.runlog import RunLog, joint_type
from plant.controllers import PDSettings
from plant.replay import simulate_replay

__all__ = ["SimulationComparison", "compare_simulation", "relative_errors", "replay", "tau_sensor"]


@dataclass
class SimulationComparison:
    """Replay of the recorded reference compared with the recording (relative errors, %)."""

    before: dict[str, float]
    after: dict[str, float] | None
    source: str
    located: list[Region] = field(default_factory=list)
    note: str = ""
    signals: dict[str, np.ndarray] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "before": self.before, "after": self.after, "located": [r.to_dict() for r in self.located], "note": self.note}


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


def compare_simulation(
    log: RunLog,
    data: IDIMData,
    rows: np.ndarray,
    before_params: dict[str, float],
    before_effects: dict[str, Any],
    after_params: dict[str, float],
    after_effects: dict[str, Any] | None,
    *,
    against: RunLog | None,
    ls: LSSettings,
    alpha: float,
    after_sim: RunLog | None = None,
) -> SimulationComparison:
    """Before (the rigid model, or ``against``) and after (the augmented model) replays against the recording.

    ``after_sim``: the replay of ``after_params`` and ``after_effects`` when the caller has it (not replayed again).
    """
    note = ""
    if against is not None:
        if len(against) != len(log):
            note = f"the simulated log has {len(against)} samples and the recording {len(log)}: compared on the common part"
        sim0, source = against, str(against.meta.get("source", "simulated log"))
    else:
        if "q_ref" not in log:
            return SimulationComparison({}, None, "replay", note="no simulation comparison: the log has no reference position (q_ref)")
        sim0, source = replay(log, before_params, before_effects), "replay through the plant"
    before = relative_errors(log, sim0, ls)
    after = None
    sim1 = None
    if after_effects is not None and "q_ref" in log:
        sim1 = after_sim if after_sim is not None else replay(log, after_params, after_effects)
        after = relative_errors(log, sim1, ls)
    n = min(len(log), len(sim0))
    tau_s = np.asarray(sim0["tau"][:n])
    tau_r = np.asarray(log["tau"][:n])
    s = slice(ls.trim, n)
    e_full = np.zeros(len(data.kin.qd))
    m = min(len(e_full), n - ls.trim)
    e_full[:m] = (tau_s[s] - tau_r[s])[:m]
    e_dec = data.decimate(e_full)[rows]
    dec = data.decimate
    assert data.kin.q is not None  # the residual's kinematics carry the position (located against it)
    located = locate(
        e_dec,
        t=data.t_dec[rows],
        q=dec(data.kin.q)[rows],
        qd=dec(data.kin.qd)[rows],
        qdd=dec(data.kin.qdd)[rows],
        W=data.W[rows],
        fs_hz=log.fs_hz / ls.decimation,
        alpha=alpha,
        q_unit="rad" if joint_type(log.units.get("q")) == "revolute" else "m",
    )
    signals = {"t": log.t[:n], "tau": tau_r, "tau_before": tau_s}
    if sim1 is not None:
        signals["tau_after"] = np.asarray(sim1["tau"][:n])
    return SimulationComparison(before, after, source, located, note, signals)
