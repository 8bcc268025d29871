"""The PD law a recorded command follows, read without a replay: which sample, which velocity estimate (:func:`pd_law_residuals`),
and the rule by which a replay changes the loop or the friction law the replays run (:data:`CLEAR_GAIN`).

Light on purpose (numpy and the IDIM filter, no plant): ``identify`` asks it of every PD log before it knows whether it needs a
replay (:func:`follows_the_law_on_the_state`); :mod:`ilic_cli.simulation.timing` reads the loop's timing with it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.idim_ls import LSSettings, filtered_position, min_samples
from ilic_cli.prepare import drive_command
from ilic_cli.runlog import PD_VELOCITIES, RunLog

FOLLOWS_RATIO = 0.5
"""The recorded command follows one sample's law when its residual is below this share of the other's."""


@dataclass(frozen=True)
class LawResiduals:
    """RMS of the recorded command minus the PD law, in % of the command's RMS.

    Attributes
    ----------
    same_pct : float
        Law on the same sample's position: ``vir(k) = sat(v(k)) + pulses(k)``.
    previous_pct : float
        Law on the previous sample's position (the documented one-period delay):
        ``vir(k) = sat(v(k-1)) + pulses(k)``.
    """

    same_pct: float
    previous_pct: float
    velocity: str = "averaged"
    """The velocity estimate of the law the residuals are of (:data:`plant.controllers.PD_VELOCITIES`): another than the
    benchmark's when its law fits clearly better (its least residual below :data:`FOLLOWS_RATIO` of every other's)."""
    other_pct: float | None = None
    """The other estimates' least residual (% of the command's RMS), ``None`` when not read."""

    @property
    def follows(self) -> str | None:
        """``"same"``, ``"previous"``, or ``None`` when neither residual is clearly the smaller.

        A law on the plant's own velocity (``"exact"``) that tells neither is taken to follow the same sample: its estimate's
        noise (the filtered position's) hides the one sample between them (the 0.5 kg·m² joint's logs of the independent
        simulator: 3.3 % and 5.3 %), and a loop fed the state is a simulation's, computed where it acts; the replay then reads
        when it acts (0 to 0.9 of a period), as for any loop on the same sample."""
        if self.same_pct < FOLLOWS_RATIO * self.previous_pct:
            return "same"
        if self.previous_pct < FOLLOWS_RATIO * self.same_pct:
            return "previous"
        return "same" if self.velocity == PD_VELOCITIES[2] else None

    def to_dict(self) -> dict[str, Any]:
        return {
            "same_sample_pct": self.same_pct,
            "previous_sample_pct": self.previous_pct,
            "follows": self.follows,
            "velocity": self.velocity,
            "other_velocity_pct": self.other_pct,
        }


def pd_law_residuals(
    q: np.ndarray, q_ref: np.ndarray, vir: np.ndarray, pulses: np.ndarray | None, kp: float, kv: float, vmax: float, dt_s: float
) -> LawResiduals:
    """How well the recorded command follows the PD law on the same and on the previous sample, with the velocity estimate
    whose law fits it (:attr:`LawResiduals.velocity`).

    ``v(k) = kv*(kp*(q_ref(k) - q(k)) - (q(k) - q(k-2))/(2 dt))`` (the benchmark's: the
    position averaged over two samples, then differenced), or ``(q(k) - q(k-1))/dt`` in its place (the backward
    difference), or the plant's own velocity (``"exact"``), estimated as IDIM-LS estimates it or by the central difference,
    whichever its law fits better (the first leaves the position noise's filtered trace, 0.5-3.6 % of the command on the
    independent simulator's logs, where the two differences leave 6-25 %; the second 0.3 % on a noise-free loop ringing after
    each pulse, where the low-pass leaves 2.6 % and the backward difference 4.1 %); another estimate than the benchmark's is
    taken when its least residual is below :data:`FOLLOWS_RATIO` of every other's. The first three samples and those where
    either reading saturates (``|v| >= vmax``) are left out, and the pulses enter with the gain that fits best (one
    least-squares factor per reading).

    Parameters
    ----------
    q, q_ref, vir : ndarray
        Measured position, reference and recorded command (V), equally long.
    pulses : ndarray or None
        Signal added to the saturated command (the pulse run's), else none.
    kp, kv, vmax, dt_s : float
        Position gain (1/s), velocity gain (V/(m/s)), saturation (V), period (s).

    Returns
    -------
    LawResiduals
    """
    q, q_ref, vir = (np.asarray(a, dtype=np.float64) for a in (q, q_ref, vir))
    fs_hz = 1.0 / dt_s
    ls = LSSettings().at_rate(fs_hz)
    central = (q[3:] - q[1:-2]) / (2.0 * dt_s)
    estimates = {
        "averaged": [(q[2:] - q[:-2]) / (2.0 * dt_s)],
        "backward": [(q[2:] - q[1:-1]) / dt_s],
        # the plant's own velocity at the sample, estimated as IDIM-LS estimates it (zero-phase low-pass, then differences:
        # the better under position noise) or by the central difference (the better when the loop rings above the low-pass)
        "exact": [np.r_[central, central[-1:]]],
    }
    if len(q) >= min_samples(ls):  # long enough for the filter (every log a fit takes)
        estimates["exact"].append(derivative(filtered_position(q, fs_hz, ls), dt_s, ls.stencil)[2:])
    laws = {name: min((_law_residuals(q, q_ref, vir, pulses, kp, kv, vmax, e) for e in estimates[name]), key=min) for name in PD_VELOCITIES}

    def others(name: str) -> float:
        return min(min(r) for other, r in laws.items() if other != name)

    best = min(laws, key=lambda name: min(laws[name]))
    if not min(laws[best]) < FOLLOWS_RATIO * others(best):
        best = PD_VELOCITIES[0]  # the benchmark's, unless another fits clearly better
    return LawResiduals(*laws[best], velocity=best, other_pct=others(best))


def _law_residuals(
    q: np.ndarray, q_ref: np.ndarray, vir: np.ndarray, pulses: np.ndarray | None, kp: float, kv: float, vmax: float, qd: np.ndarray
) -> tuple[float, float]:
    """``(same, previous)``: the residuals (% of the command's RMS) of the law with the velocity estimate ``qd`` (from the third
    sample on) on the same and on the previous sample (:func:`pd_law_residuals`)."""
    add = np.zeros_like(vir) if pulses is None else np.asarray(pulses, dtype=np.float64)
    v = np.empty_like(q)
    v[2:] = kv * (kp * (q_ref[2:] - q[2:]) - qd)
    v[:2] = v[2]
    inside = np.abs(v) < vmax
    keep = inside[3:] & inside[2:-1]  # off the saturation on both readings (where the rig's clipping may differ)
    scale = float(np.sqrt(np.mean(vir[3:][keep] ** 2))) or 1.0

    a = add[3:][keep]

    def rms_pct(e: np.ndarray) -> float:
        e = e[keep]
        if np.any(a):  # the pulses' size as the command holds it (the pulse run's is 1.4 % above its pulses_N)
            e = e - a * (float(a @ e) / float(a @ a))
        return 100.0 * float(np.sqrt(np.mean(e**2))) / scale

    return rms_pct(vir[3:] - v[3:] - add[3:]), rms_pct(vir[3:] - v[2:-1] - add[3:])


CLEAR_GAIN = 0.5
"""A reading of the loop or of the plant's friction law changes the replays only when its replay halves their error in the
measure it acts on: a PD law inside the dynamics the force error (:func:`inside_is_closer`), a smoothed friction the position
error (:mod:`ilic_cli.diagnosis.friction_law`). Each hypothesis's fit absorbs much of the other's: with the law inside the
dynamics a held law's fit proposes a lag of about half a period, and a smoothed law nearly a switch replays as stick/slip
does. Measured on the independent simulator: the law inside the dynamics 0.02-0.49 of the held law's force error where it is
taken (with a drive lag or Stribeck friction on a trapezoid not: 0.62-3.3), the discrete loop fed the state 0.89-3.6;
tanh friction 0.08-0.41 of stick/slip's position error; on a stick/slip corpus log a law at 0.55 mm/s moved the errors
by 1 % and 0.1 %, and had been kept until this margin."""


def law_may_act_inside(law: LawResiduals) -> bool:
    """Whether the recorded command may be a law inside the dynamics: it follows the law on the plant's velocity at its sample,
    which a discrete loop fed the state logs too (the two differ only between the samples)."""
    return law.follows == "same" and law.velocity == "exact"


def log_law(log: RunLog, kp: float, kv: float, vmax: float) -> LawResiduals | None:
    """The law ``log``'s recorded PD command follows (:func:`pd_law_residuals`) with the gains ``kp, kv`` and saturation ``vmax``;
    ``None`` for a log without a recorded PD command (``vir``, or its force with a declared drive gain:
    :func:`ilic_cli.prepare.drive_command`) or ``q_ref``."""
    command = drive_command(log)  # its vir, or its force over the declared drive gain (the one definition)
    if command is None or "q_ref" not in log or "q" not in log:
        return None
    pulses = log["pulses"] if "pulses" in log else None
    return pd_law_residuals(log["q"], log["q_ref"], command, pulses, kp, kv, vmax, log.dt_s)


def follows_the_law_on_the_state(log: RunLog) -> bool:
    """Whether ``log``'s recorded PD command follows the law on the plant's velocity at its sample (:func:`law_may_act_inside`),
    read with the loop's gains its controller entry declares (:func:`log_law`); ``False`` without a PD entry and its gains."""
    view = log.controller
    if view is None or view.kind != "pd" or not (view.kp and view.kv):
        return False
    law = log_law(log, float(view.kp), float(view.kv), float(view.settings.get("vmax", 10.0)))
    return law is not None and law_may_act_inside(law)


def inside_is_closer(held: dict[str, float], inside: dict[str, float]) -> bool:
    """The law inside the dynamics is taken: its replay's force error below :data:`CLEAR_GAIN` of the held law's, its position
    error lower (each replayed with its own model)."""
    return inside["position"] < held["position"] and inside["force"] < CLEAR_GAIN * held["force"]
