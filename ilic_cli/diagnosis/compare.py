"""Simulation against recording: the rigid and the augmented models replayed (:func:`ilic_cli.simulation.replay.replay`),
their relative errors, and the replay residual located in the motion (:func:`ilic_cli.diagnosis.locate.locate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.diagnosis.locate import Region, locate
from ilic_cli.filtering import decimate_matlab
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.jointlog import position_unit
from ilic_cli.lsq import relative_error_pct
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import relative_errors, replay

__all__ = ["SimulationComparison", "band_force_error", "band_force_error_pct", "compare_simulation"]


def band_force_error(rec: RunLog, sim: RunLog, decimation: int) -> np.ndarray:
    """Simulated minus recorded force, decimated as the IDIM system is (every decimated sample of the log)."""
    return decimate_matlab(np.asarray(sim["tau"]) - np.asarray(rec["tau"]), max(decimation, 1))


def band_force_error_pct(rec: RunLog, sim: RunLog, ls: LSSettings) -> float:
    """The replayed force against the recorded one in the inverse model's band (:func:`band_force_error`), the filters'
    edges (``ls.trim`` samples each side) left out (%): what the model can explain, where the full-band figure also
    counts the loop's answer to the sensor noise, which a noise-free replay does not have (a 3 kg·m² joint at 4 kHz,
    clean: 59.7 % in full, 4.3 % in the band)."""
    n = min(len(rec), len(sim))
    if n < len(rec) or n < len(sim):  # a simulated log of another length: compared on the common part
        rec, sim = rec.slice(0, n), sim.slice(0, n)
    r = max(ls.at_rate(rec.fs_hz).decimation, 1)
    edge = slice(ls.trim // r, n // r - ls.trim // r)
    tau = decimate_matlab(np.asarray(rec["tau"]), r)[edge]
    return relative_error_pct(tau, tau + band_force_error(rec, sim, r)[edge])


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
    before = relative_errors(log, sim0, ls) | {"force_in_band": band_force_error_pct(log, sim0, ls)}
    after = None
    sim1 = None
    if after_effects is not None and "q_ref" in log:
        sim1 = after_sim if after_sim is not None else replay(log, after_params, after_effects)
        after = relative_errors(log, sim1, ls) | {"force_in_band": band_force_error_pct(log, sim1, ls)}
    n = min(len(log), len(sim0))
    tau_s = np.asarray(sim0["tau"][:n])
    tau_r = np.asarray(log["tau"][:n])

    def on_rows(tau_sim: np.ndarray) -> np.ndarray:
        """The replay's force minus the recorded one, decimated as the IDIM rows are, on the rows used."""
        e_full = np.zeros(len(data.kin.qd))
        m = min(len(e_full), n - ls.trim)
        e_full[:m] = (tau_sim[ls.trim : n] - tau_r[ls.trim : n])[:m]
        return data.decimate(e_full)[rows]

    e_dec = on_rows(tau_s)
    dec = data.decimate
    assert data.kin.q is not None  # the residual's kinematics carry the position (located against it)
    located = locate(
        e_dec,
        t=data.t_dec[rows],
        q=dec(data.kin.q)[rows],
        qd=dec(data.kin.qd)[rows],
        qdd=dec(data.kin.qdd)[rows],
        W=data.W[rows],
        fs_hz=log.fs_hz / ls.at_rate(log.fs_hz).decimation,
        alpha=alpha,
        q_unit=position_unit(data.joint),
    )
    # in full, and in the inverse model's band on the rows (what the model explains: force_in_band)
    signals = {"t": log.t[:n], "tau": tau_r, "tau_before": tau_s, "t_band": data.t_dec[rows], "before_band": e_dec}
    if sim1 is not None:
        signals["tau_after"] = np.asarray(sim1["tau"][:n])
        signals["after_band"] = on_rows(signals["tau_after"])
    return SimulationComparison(before, after, source, located, note, signals)
