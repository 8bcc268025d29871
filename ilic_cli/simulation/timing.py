"""When does the recorded command act? The PD loop's timing, read from the recording.

The EMPS benchmark documents its PD loop with one period of computation delay
(the command computed from ``qm(k-1)`` acts over ``[kT, (k+1)T)``), and the
replay runs it so (:class:`plant.controllers.PDSettings`, ``delay_samples = 1``).
A recording that logs the command (``vir``) beside the position tells which
sample the command was computed from: :func:`~ilic_cli.simulation.pd_law.pd_law_residuals` evaluates the
law on the same sample's position and on the previous one's. When the command
follows the same sample, the documented loop holds each command one period too
long, and :func:`control_timing` replays the log with the command acting a
fraction of a period after its sample, keeping the fraction that minimises the
replayed force error (an optimum at a bound of the range is reported as such,
never as a measured lag). :func:`with_recorded_timing` gives the log whose
controller carries that timing: the diagnosis replays the loop that ran.

The law is read with both of the loop's velocity estimates (:data:`plant.controllers.PD_VELOCITIES`): the benchmark's
difference of the position averaged over two samples, and the textbook backward difference of the measured position.
A loop written the textbook way records a command the benchmark's law does not fit (its velocity term is half a period
earlier and noisier), and the replay then ran another loop than the recording's: on a 12 kg axis whose viscous friction
warms up by a third, simulated apart from ``ilic``'s plant with that loop acting within its sample, the replay with the
benchmark's loop put the simulated force error at 24 %, 22 % with the warm-up in the plant, and the diagnosis rejected
the warm-up the inverse model had found (-31 %, time constant 2.0 s for 2.0 s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.errors import ParameterError, SimulationError
from ilic_cli.idim_ls import LSSettings
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.pd_law import LawResiduals, log_law
from ilic_cli.simulation.replay import LAG_READ, relative_errors, replay
from plant.controllers import PD_VELOCITIES, PDSettings
from plant.replay import controller_from_log

GRID = tuple(round(0.1 * i, 1) for i in range(10))
"""Computation delays tried (control periods, 0 to 0.9): below one period, the command computed from the same sample."""

VELOCITY_WORDS = {
    "averaged": "the difference of the position averaged over two samples",
    "backward": "the backward difference of the position",
    "exact": "the plant's own velocity",
}
"""The velocity estimates of :data:`plant.controllers.PD_VELOCITIES`, in words."""


def vertex(x: np.ndarray, y: np.ndarray, i: int) -> float:
    """Abscissa of the minimum of the parabola through points ``i-1, i, i+1`` (``x[i]`` when they are not convex)."""
    x0, x1, x2 = x[i - 1 : i + 2]
    y0, y1, y2 = y[i - 1 : i + 2]
    den = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / den
    b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / den
    if not a > 0:
        return float(x1)
    return float(min(max(-b / (2 * a), x0), x2))


@dataclass
class ControlTiming:
    """The loop's timing read from the recording and, when it differs from the replay's, the replayed errors at the best one.

    Attributes
    ----------
    law : LawResiduals
        Which sample the recorded command follows, and with which velocity estimate.
    replay_velocity : str
        The velocity estimate of the loop the log declares (the replay's before the law was read).
    lag_found : bool
        The diagnosis kept a drive lag: its model replays the loop acting at the sample, the lag the delay's (:data:`LAG_READ`).
    negative_flexibility : bool
        The diagnosis rejected a flexibility for its negative mass (the sentence then says what it is).
    period_s : float
        Control period.
    tried : list of (float, float)
        ``(delay in periods, replayed force error %)`` at the delays of :data:`GRID` replayed (up to the first rise).
    best : float or None
        Computation delay (periods) of the least replayed force error.
    at_edge : str or None
        Why ``best`` is a bound of the range, not a measured lag.
    documented, refined : dict
        Replay errors (position, velocity, force, %) with the declared loop (one period of delay) and with the loop read
        (``best``, the velocity estimate of ``law``).
    """

    law: LawResiduals
    period_s: float
    tried: list[tuple[float, float]] = field(default_factory=list)
    best: float | None = None
    at_edge: str | None = None
    documented: dict[str, float] = field(default_factory=dict)
    refined: dict[str, float] = field(default_factory=dict)
    negative_flexibility: bool = False
    lag_found: bool = False
    replay_velocity: str = PD_VELOCITIES[0]
    continuous: bool = False
    """The law on the plant's velocity is replayed inside the dynamics (:attr:`plant.controllers.PDSettings.continuous`), as the
    diagnosis decides it (:mod:`ilic_cli.diagnosis.loop_read`)."""
    held: dict[str, float] = field(default_factory=dict)
    """Replay errors of the law on the plant's velocity held over the period from its sample (tried beside :attr:`continuous`)."""

    @property
    def velocity_mismatch(self) -> bool:
        """The recorded command follows a law whose velocity estimate is not the declared loop's."""
        return self.law.follows is not None and self.law.velocity != self.replay_velocity

    @property
    def mismatch(self) -> bool:
        """The replay's loop is not the recording's: the command follows the same sample while the replay delays it by a
        period (and a delay was read), or its velocity estimate is another, or the law acts inside the dynamics."""
        return (self.law.follows == "same" and bool(self.tried)) or self.velocity_mismatch or self.continuous

    def sentence(self) -> str:
        """One sentence for reports (empty when the replay's loop is the recording's)."""
        if not self.mismatch or (self.tried and self.best is None) or not self.refined:
            return ""
        law = self.law
        f0, f1 = self.documented["force"], self.refined["force"]
        v0, v1 = self.documented["velocity"], self.refined["velocity"]
        estimate = (
            f" with {VELOCITY_WORDS[law.velocity]} as its velocity ({law.other_pct:.2g} % left with the other estimates; the declared loop "
            f"uses {VELOCITY_WORDS[self.replay_velocity]})"
            if self.velocity_mismatch
            else ""
        )
        if self.continuous:
            head = (
                f"The recorded command follows the PD law{estimate} on the same sample's position ({law.same_pct:.2g} % of its RMS left), and its "
                f"replays are closest with the law inside the dynamics, on the plant's state at every integration step (as a solver's "
                f"right-hand side; held over the period from its sample: force {self.held['force']:.2f} %, position {self.held['position']:.3g} %): "
                "the replays here run that loop"
            )
        elif self.tried and self.best is not None:
            ms = self.best * self.period_s * 1e3
            where = f"acting {ms:.2g} ms after its sample" if self.at_edge is None else f"acting {ms:.2g} ms after its sample ({self.at_edge})"
            head = (
                f"The recorded command follows the PD law{estimate} on the same sample's position ({law.same_pct:.2g} % of its RMS left, "
                f"{law.previous_pct:.2g} % on the previous sample's), so the drive acts within the sample, not one period later "
                f"as the documented loop assumes: the replays here run the loop with the command {where}"
            )
        else:
            head = (
                f"The recorded command follows the PD law{estimate} on the {law.follows} sample's position "
                f"({min(law.same_pct, law.previous_pct):.2g} % of its RMS left): the replays here run that loop"
            )
        return (
            (
                f"{head}; the simulated force error of the model the timing is read with is {f1:.2f} % so, {f0:.2f} % with the documented loop "
                f"(velocity {v1:.3g} %, {v0:.3g} %)"
            )
            + (
                "; the model with the delay found replays the loop acting at its sample, the delay the whole lag"
                if self.lag_found and self.tried and self.best is not None
                else ""
            )
            + (
                "; a drive lag this short is what the flexibility candidate's negative mass shows (a rigid plant simulated with a 0.2 ms lag "
                "on the EMPS reference gives one too, README), not a two-mass axis"
                if self.negative_flexibility and not self.continuous
                else ""
            )
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "law": self.law.to_dict(),
            "period_s": self.period_s,
            "tried": [{"delay_samples": d, "force_pct": f} for d, f in self.tried],
            "best_delay_samples": self.best,
            "best_delay_s": None if self.best is None else self.best * self.period_s,
            "at_edge": self.at_edge,
            "lag_found": self.lag_found,
            "continuous": self.continuous,
            "held": self.held,
            "documented": self.documented,
            "refined": self.refined,
            "sentence": self.sentence(),
        }


def recorded_law(log: RunLog) -> tuple[PDSettings, LawResiduals] | None:
    """The PD loop ``log`` declares and the law its recorded command follows (:func:`ilic_cli.simulation.pd_law.log_law`); ``None``
    for a log without a recorded PD command, ``q_ref`` or the loop's gains."""
    try:
        ctl = controller_from_log(log)
    except (SimulationError, ParameterError):  # no recorded controller (or an invalid one): nothing to read the timing of
        return None
    if not isinstance(ctl, PDSettings) or ctl.pulse_input != "held":
        return None
    law = log_law(log, ctl.kp, ctl.kv, ctl.vmax)
    return None if law is None else (ctl, law)


def with_pd_law(log: RunLog, continuous: bool) -> RunLog:
    """``log`` whose PD loop is the law on the plant's velocity acting at its sample: held over the period, or inside the dynamics
    (``continuous``, :attr:`plant.controllers.PDSettings.continuous`)."""
    recorded = log.controller
    controller = {**(recorded.settings if recorded is not None else {}), "kind": "pd", "velocity": "exact", "delay_samples": 0.0}
    controller.pop(LAG_READ, None)
    if continuous:
        controller["continuous"] = True
    else:
        controller.pop("continuous", None)
    return RunLog(dict(log.channels), dict(log.units), {**log.meta, "controller": controller})


def control_timing(log: RunLog, params: dict[str, float], effects: dict[str, Any] | None, ls: LSSettings) -> ControlTiming | None:
    """The timing of ``log``'s PD loop; ``None`` for a log without a recorded PD command (``vir``, or its force with a declared
    drive gain: :func:`ilic_cli.prepare.drive_command`), ``q_ref`` or the loop's gains.

    When the command follows the same sample and the replay's loop delays it
    by a period, the log is replayed with ``params``/``effects`` at the delays
    of :data:`GRID` in turn until the force error rises (it is unimodal in the
    lag), and the least one is refined by a parabola (a minimum at 0 or at the
    top of the grid is a bound: ``at_edge``).
    """
    recorded = recorded_law(log)
    if recorded is None:
        return None
    ctl, law = recorded
    out = ControlTiming(law, log.dt_s, replay_velocity=ctl.velocity)
    read = replace(ctl, velocity=law.velocity) if out.velocity_mismatch else ctl

    def replayed(loop: PDSettings) -> dict[str, float]:
        return relative_errors(log, replay(log, params, effects, controller=loop), ls)

    if law.follows != "same" or ctl.same_sample:
        if out.velocity_mismatch:  # the declared timing, the velocity estimate read
            out.documented, out.refined = replayed(ctl), replayed(read)
        return out

    cache: dict[float, dict[str, float]] = {}

    def errors(delay: float) -> dict[str, float]:
        if delay not in cache:
            cache[delay] = replayed(replace(read, delay_samples=delay))
        return cache[delay]

    out.documented = replayed(ctl)  # the loop as declared: one period late (not the same sample, tested above)
    # walk up the grid while the force error falls (it is unimodal in the lag: measured on both EMPS runs),
    # so a minimum at 0 costs two replays instead of the whole grid
    for d in GRID:
        out.tried.append((d, errors(d)["force"]))
        if len(out.tried) >= 2 and out.tried[-1][1] > out.tried[-2][1]:
            break
    x = np.array([d for d, _ in out.tried])
    y = np.array([f for _, f in out.tried])
    i = int(np.argmin(y))
    if i == 0:
        out.best, out.at_edge = 0.0, "the lower bound of the range: a command cannot act before its sample, so the lag is bounded, not measured"
    elif i == len(GRID) - 1:
        out.best, out.at_edge = float(x[i]), "the upper end of the range, next to a whole period: not a measured lag"
    else:
        out.best = vertex(x, y, i)
    out.refined = errors(out.best)
    if not math.isfinite(out.refined["force"]):
        out.best = None
    return out


def with_recorded_timing(log: RunLog, timing: ControlTiming | None) -> RunLog:
    """``log`` whose PD controller acts with the timing read from it (``delay_samples`` = ``timing.best``) and estimates the
    velocity as its recorded command does.

    Unchanged when the recording follows the replay's loop already (or tells
    nothing). At a bound of the range the bound is used: the least replayed
    error there, though only bounded as a lag (:attr:`ControlTiming.at_edge`).
    """
    if timing is None or not timing.mismatch or (timing.tried and timing.best is None):
        return log
    recorded = log.controller
    controller = {**(recorded.settings if recorded is not None else {}), "kind": "pd"}
    if timing.tried and timing.best is not None:
        controller["delay_samples"], controller[LAG_READ] = float(timing.best), True
    if timing.velocity_mismatch:
        controller["velocity"] = timing.law.velocity
    return RunLog(dict(log.channels), dict(log.units), {**log.meta, "controller": controller})


def recorded_loop(log: RunLog, params: dict[str, float], effects: dict[str, Any] | None, ls: LSSettings) -> tuple[RunLog, ControlTiming | None]:
    """``log`` with the loop that ran (:func:`with_recorded_timing`), timed with the model ``params``/``effects``; and the timing read.

    A log whose model cannot be simulated, or without a recorded PD command, is
    returned as it is (timing ``None`` or without replays).
    """
    try:
        timing = control_timing(log, params, effects, ls)
    except (ParameterError, SimulationError):
        return log, None
    return with_recorded_timing(log, timing), timing
