"""The closed loop's driver: run the compiled loop over control periods, with the CTC's online update, and the run log.

:func:`simulate_loop` runs :func:`plant.kernel.run_periods` (or the kernel
compiled for effects without a compiled form, :mod:`plant.generic`) window by
window; with ``CTCSettings.ilic`` it hands each full window (:class:`LoopWindow`)
to the update it is given (:class:`OnlineUpdate`: the plant imports no
estimator; IDIM-ILIC's is :func:`ilic_cli.simulation.online.ilic_update`) and
runs the next window with the parameters it returns. :func:`loop_log` builds
the log ``ilic simulate`` writes. Replaying a recorded log is :mod:`plant.replay`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ilic_cli.effects import Effects, effects_to_dict
from ilic_cli.errors import DivergedError, ParameterError
from ilic_cli.jointlog import channel_units
from ilic_cli.prefault import populate_beside
from ilic_cli.regressor import Model, get_model
from ilic_cli.runlog import RunLog
from plant.controllers import C_PD_CONTINUOUS, CTCSettings, OpenLoopSettings, PDSettings, chi_vector
from plant.dynamics import P_LAG, STICK_VELOCITY, RigidParameters, drive_lag_s, plant_vector
from plant.generic import kernel_for
from plant.sensors import TAU_SENSORS, draw_disturbance, draw_noise, measured_force
from plant.trajectories import Multisine, Trajectory


@dataclass
class LoopResult:
    """Samples of one closed-loop run (all arrays of length n) and the settings it ran with (for :func:`loop_log`)."""

    t: np.ndarray
    q: np.ndarray
    q_true: np.ndarray
    qd_true: np.ndarray
    qdd_true: np.ndarray
    u: np.ndarray
    vir: np.ndarray
    tau: np.ndarray
    chi: np.ndarray
    names: tuple[str, ...]
    controller: CTCSettings | PDSettings
    params: RigidParameters
    effects: Effects
    fs_hz: float
    substeps: int
    seed: int
    tau_sensor: str
    pulses: np.ndarray | None = None
    windows: list[Any] = field(default_factory=list)  # the online update's records (WindowRecord), one per full window


def _initial_state(x0: tuple[float, float], T: float) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's state at ``x0 = (q, qd)`` (the load with the motor, the current loop's force NaN: the first command),
    and the controller's memory as if the axis had been moving at ``qd`` before."""
    q_prev = x0[0] - x0[1] * T
    return np.array([x0[0], x0[1], x0[0], x0[1], np.nan], dtype=np.float64), np.array([q_prev, q_prev, 0.0, 1.0])


def simulate_segments(
    *,
    params: RigidParameters,
    effects: Effects,
    command: np.ndarray,
    fs_hz: float,
    starts: list[int] | np.ndarray,
    length: int,
    x0: np.ndarray,
    gain: float = 1.0,
    substeps: int = 10,
) -> np.ndarray:
    """The plant driven by ``gain * command`` (held over each period, no feedback) over the segments ``[i, i + length)``
    of ``starts``, each from its own state ``x0[j] = (q, qd)``: the segments' positions, one after another (multiple shooting).

    One set-up for every segment (the plant's vector, the kernel); the command before a segment
    feeds a drive lag as in one run.
    """
    T = 1.0 / fs_hz
    p = plant_vector(params, effects)
    c = OpenLoopSettings(gtau=gain).vector()
    run_periods = kernel_for(effects).run_periods
    u = np.ascontiguousarray(command, dtype=np.float64)
    n = len(u)
    zero = np.zeros(n)
    out_q, out_u, out_vir, out_qt, out_qd, out_qdd = (np.zeros(n) for _ in range(6))
    chi8 = np.zeros(8)
    for j, i in enumerate(starts):
        if not (0 <= i and i + length <= n):
            raise ParameterError("segment", (int(i), int(length)), f"within the command's {n} samples")
        x, cs = _initial_state((float(x0[j][0]), float(x0[j][1])), T)
        a, b = int(i), int(i) + length
        bad = run_periods(a, b, x, cs, zero, zero, zero, u, zero, p, c, chi8, int(substeps), T, out_q, out_u, out_vir, out_qt, out_qd, out_qdd, zero)
        if bad >= 0:
            raise DivergedError(None, f"the open-loop segment from t = {i * T:.6g} s diverged at t = {bad * T:.6g} s (non-finite state)")
    return np.concatenate([out_qt[i : i + length] for i in starts]) if len(starts) else np.zeros(0)


@dataclass(frozen=True)
class LoopWindow:
    """One full window ``[a, b)`` of the loop, handed to the online update (:class:`OnlineUpdate`).

    ``k`` numbers the windows from 1; ``model`` is the CTC's structure; ``t, q_ref, q`` the window's time, reference and
    measured position; ``qd_ref, qdd_ref`` the logged reference's derivatives and ``tau`` the measured force over it.
    """

    k: int
    model: Model
    controller: CTCSettings
    fs_hz: float
    t: np.ndarray
    q_ref: np.ndarray
    q: np.ndarray
    qd_ref: np.ndarray
    qdd_ref: np.ndarray
    tau: np.ndarray


class WindowRecord(Protocol):
    """What the online update says of a window (kept in :attr:`LoopResult.windows`, logged by :func:`loop_log`)."""

    def to_dict(self) -> dict[str, Any]: ...


class OnlineUpdate(Protocol):
    """The CTC's online re-estimation: the parameters in force and a full window in, the new parameters and the window's record out.

    The plant knows no estimator: the caller hands one in (IDIM-ILIC: :func:`ilic_cli.simulation.online.ilic_update`).
    """

    def __call__(self, chi: np.ndarray, window: LoopWindow) -> tuple[np.ndarray, WindowRecord]: ...


def _check_loop(n: int, substeps: int, tau_sensor: str, controller: CTCSettings | PDSettings, effects: Effects, update: OnlineUpdate | None) -> None:
    """Refuse a loop that cannot run (:class:`ParameterError`)."""
    if n < 2:
        raise ParameterError("duration", n, "at least two control periods")
    if not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ParameterError("substeps", substeps, "a positive integer")
    if tau_sensor not in TAU_SENSORS:
        raise ParameterError("tau_sensor", tau_sensor, f"one of {', '.join(TAU_SENSORS)}")
    controller.validate()
    if isinstance(controller, CTCSettings) and controller.ilic and update is None:
        raise ParameterError("update", None, "an online update (OnlineUpdate, e.g. ilic_cli.simulation.online.ilic_update) with CTCSettings.ilic")
    if isinstance(controller, PDSettings) and controller.pulse_input == "ramp" and drive_lag_s(effects) > 0:
        raise ParameterError(
            "delay.delay",
            effects["delay"]["delay"],
            '>= 0 with ramped pulses (pulse_input="ramp", the published setup): a drive lag cannot be combined with them',
        )
    if isinstance(controller, PDSettings) and controller.pulse_input == "ramp" and "current_loop" in effects:
        raise ParameterError("current_loop", effects["current_loop"].to_dict(), 'left out with ramped pulses (pulse_input="ramp", the published setup)')
    if isinstance(controller, PDSettings) and controller.pulse_input == "ramp" and controller.same_sample:
        raise ParameterError("delay_samples", controller.delay_samples, '1 with ramped pulses (pulse_input="ramp", the published setup)')


@dataclass
class _Loop:
    """The compiled loop's inputs and outputs over one run; :meth:`run` advances it over periods ``[a, b)``."""

    run_periods: Callable[..., int]
    x: np.ndarray
    cs: np.ndarray
    q_r: np.ndarray
    qd_r: np.ndarray
    qdd_r: np.ndarray
    pulses: np.ndarray
    noise_q: np.ndarray
    p: np.ndarray
    c: np.ndarray
    names: tuple[str, ...]
    substeps: int
    T: float
    dist: np.ndarray  # zeros without a disturbance (plant.kernel.run_periods)
    out: tuple[np.ndarray, ...]  # q, u, vir, q_true, qd_true, qdd_true

    def run(self, a: int, b: int, chi_now: np.ndarray) -> None:
        chi8 = chi_vector(self.names, chi_now) if len(self.names) else np.zeros(8)
        args = (self.x, self.cs, self.q_r, self.qd_r, self.qdd_r, self.pulses, self.noise_q, self.p, self.c, chi8, self.substeps, self.T)
        bad = self.run_periods(a, b, *args, *self.out, self.dist)
        if bad >= 0:
            raise DivergedError(None, f"the closed loop diverged at t = {bad * self.T:.6g} s (non-finite state); check the parameters and gains")


def _scheduled(loop: _Loop, sched: np.ndarray, chi_hist: np.ndarray) -> None:
    """The CTC with the logged parameters ``sched`` (n, b) in force: one run per stretch of constant parameters."""
    change = np.flatnonzero(np.any(np.diff(sched, axis=0) != 0, axis=1)) + 1
    bounds = [0, *change.tolist(), len(sched)]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        loop.run(a, b, sched[a])
    chi_hist[:] = sched


def _online(
    loop: _Loop,
    chi: np.ndarray,
    chi_hist: np.ndarray,
    update: OnlineUpdate,
    window: Callable[[int, int, int], LoopWindow],
    nwin: int,
    progress: Callable[[int, int], None] | None,
) -> list[WindowRecord]:
    """The CTC re-estimated online: run window by window, and after each full window hand it to ``update``."""
    n = len(chi_hist)
    windows: list[WindowRecord] = []
    a, k = 0, 1
    while a < n:
        b = min(a + nwin, n)
        loop.run(a, b, chi)
        chi_hist[a:b] = chi
        if b - a == nwin:
            chi, record = update(chi, window(a, b, k))
            windows.append(record)
            k += 1
        if progress is not None:
            progress(b, n)
        a = b
    return windows


def _fixed(loop: _Loop, chi: np.ndarray, chi_hist: np.ndarray, progress: Callable[[int, int], None] | None) -> None:
    """Fixed parameters (the PD, or a CTC without update): one run, or 50 with a progress callback (one for the PD law inside the
    dynamics, whose drive lag keeps the commands of its last steps within a run: the output is the same either way)."""
    n = len(chi_hist)
    step = max(1, n // 50) if progress is not None and loop.c[C_PD_CONTINUOUS] != 1.0 else n
    for a in range(0, n, step):
        b = min(a + step, n)
        loop.run(a, b, chi)
        if progress is not None:
            progress(b, n)
    chi_hist[:] = chi


def _ctc_start(controller: CTCSettings | PDSettings) -> tuple[Model | None, tuple[str, ...], np.ndarray]:
    """The CTC's model, its parameters' names and their initial values (``chi0``); none for the PD."""
    if not isinstance(controller, CTCSettings):
        return None, (), np.zeros(0)
    model = get_model(controller.model)
    init = controller.initial()
    return model, model.names, np.array([init[nm] for nm in model.names], dtype=np.float64)


def simulate_loop(
    *,
    q_r: np.ndarray,
    qd_r: np.ndarray,
    qdd_r: np.ndarray,
    params: RigidParameters,
    effects: Effects,
    controller: CTCSettings | PDSettings,
    fs_hz: float = 1000.0,
    substeps: int = 10,
    seed: int = 0,
    qd_log: np.ndarray | None = None,
    qdd_log: np.ndarray | None = None,
    pulses: np.ndarray | None = None,
    tau_sensor: str = "centred",
    chi_schedule: np.ndarray | None = None,
    x0: tuple[float, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
    update: OnlineUpdate | None = None,
) -> LoopResult:
    """Run the closed loop over ``len(q_r)`` control periods.

    Parameters
    ----------
    q_r, qd_r, qdd_r : ndarray
        Reference used by the controller at each sample (PD: only ``q_r``).
    params, effects : plant parameters and effects.
    controller : CTCSettings or PDSettings
        With ``CTCSettings.ilic`` the parameters are re-estimated online every
        ``window_s`` by ``update`` (required then) on the window's logged reference
        (``qd_log, qdd_log``, default ``qd_r, qdd_r``) and measured force.
    update : OnlineUpdate, optional
        The online re-estimation (IDIM-ILIC: :func:`ilic_cli.simulation.online.ilic_update`).
    chi_schedule : ndarray (n, b), optional
        CTC parameters in force at each sample (replaying a logged controller);
        disables the online update.
    tau_sensor : ``centred`` or ``command`` (see :data:`TAU_SENSORS`).
    x0 : (q, qd), optional
        Initial state; default on the reference, ``(q_r[0], qd_r[0])``, with
        the controller's memory (previous measured position) consistent with it.
    """
    n = len(q_r)
    _check_loop(n, substeps, tau_sensor, controller, effects, update)
    T = 1.0 / fs_hz
    p = plant_vector(params, effects)
    if isinstance(controller, PDSettings) and controller.same_sample:  # the computation delay is a lag of the drive
        p[P_LAG] += controller.delay_samples * T
    q_r, qd_r, qdd_r = (np.ascontiguousarray(a, dtype=np.float64) for a in (q_r, qd_r, qdd_r))
    qd_log = qd_r if qd_log is None else np.asarray(qd_log, dtype=np.float64)
    qdd_log = qdd_r if qdd_log is None else np.asarray(qdd_log, dtype=np.float64)
    pul = np.zeros(n) if pulses is None else np.ascontiguousarray(pulses, dtype=np.float64)
    noise_tau, noise_q = draw_noise(n, seed, effects)
    dist = draw_disturbance(n, seed, effects, fs_hz) if "disturbance" in effects else np.zeros(n)
    x, cs = _initial_state((float(q_r[0]), float(qd_r[0])) if x0 is None else x0, T)
    out = tuple(np.zeros(n) for _ in range(6))
    backing = populate_beside(out)  # their pages' memory on another core, not in the loop's writes
    model, names, chi = _ctc_start(controller)
    chi_hist = np.zeros((len(names), n)).T  # (n, b), each parameter's history contiguous (the log's channels)
    loop = _Loop(kernel_for(effects).run_periods, x, cs, q_r, qd_r, qdd_r, pul, noise_q, p, controller.vector(), names, int(substeps), T, dist, out)
    out_q, out_u = out[0], out[1]
    windows: list[WindowRecord] = []
    if isinstance(controller, CTCSettings) and chi_schedule is not None:
        _scheduled(loop, np.asarray(chi_schedule, dtype=np.float64), chi_hist)
    elif isinstance(controller, CTCSettings) and controller.ilic:
        assert model is not None and update is not None  # set with the CTC controller above; checked by _check_loop
        ctc, m = controller, model

        def window(a: int, b: int, k: int) -> LoopWindow:
            tau_w = measured_force(out_u[:b], T, b, effects, tau_sensor, noise_tau[:b], start=a)
            return LoopWindow(k, m, ctc, fs_hz, np.arange(a, b) * T, q_r[a:b], out_q[a:b], qd_log[a:b], qdd_log[a:b], tau_w)

        windows = _online(loop, chi, chi_hist, update, window, int(round(controller.window_s * fs_hz)), progress)
    else:
        _fixed(loop, chi, chi_hist, progress)
    if backing is not None:
        backing.join()
    tau = measured_force(out_u, T, n, effects, tau_sensor, noise_tau)
    t = np.arange(n, dtype=np.float64)
    t *= T  # = np.arange(n) * T
    return LoopResult(
        t=t,
        q=out_q,
        q_true=out[3],
        qd_true=out[4],
        qdd_true=out[5],
        u=out_u,
        vir=out[2],
        tau=tau,
        chi=chi_hist,
        names=names,
        controller=controller,
        params=params,
        effects=effects,
        fs_hz=fs_hz,
        substeps=int(substeps),
        seed=seed,
        tau_sensor=tau_sensor,
        pulses=pulses,
        windows=list(windows),
    )


def loop_log(
    res: LoopResult,
    *,
    q_ref: np.ndarray,
    qd_ref: np.ndarray,
    qdd_ref: np.ndarray,
    meta: dict[str, Any] | None = None,
    joint: str = "prismatic",
) -> RunLog:
    """Build the run log of a closed-loop result (with the controller, plant and settings it ran with), in a ``joint``'s units.

    Channels: ``t, q`` (measured position: with the quantization and noise
    effects), ``q_ref, qd_ref, qdd_ref`` (the logged reference), ``tau`` (the
    force sensor), ``qd_plant, qdd_plant`` (the plant's own velocity and
    acceleration at the sample instants, noise-free: what a simulation is
    compared with, see ``fixtures/emps_simulation_table.json``), ``vir`` (PD),
    ``pulses`` and ``<parameter>_hat`` (CTC: the parameters in force).
    Metadata: true parameters, effects, controller, simulation settings and
    the IDIM-ILIC windows.
    """
    chans: dict[str, np.ndarray] = {
        "t": res.t,
        "q": res.q,
        "q_ref": q_ref,
        "qd_ref": qd_ref,
        "qdd_ref": qdd_ref,
        "tau": res.tau,
        "qd_plant": res.qd_true,
        "qdd_plant": res.qdd_true,
    }
    motion = channel_units(joint)
    units: dict[str, str] = {n: motion[n] for n in ("q", "q_ref", "qd_ref", "qdd_ref", "tau")} | {"qd_plant": motion["qd"], "qdd_plant": motion["qdd_ref"]}
    controller, fs_hz, pulses = res.controller, res.fs_hz, res.pulses
    if isinstance(controller, PDSettings):
        chans["vir"] = res.vir
    if pulses is not None:
        chans["pulses"] = np.asarray(pulses, dtype=np.float64)
        units["pulses"] = "V"
    if isinstance(controller, CTCSettings):
        model = get_model(controller.model)
        for i, name in enumerate(res.names):
            chans[f"{name}_hat"] = res.chi[:, i]
            units[f"{name}_hat"] = model.units[i]
    m: dict[str, Any] = {
        "sample_rate_hz": fs_hz,
        "true_parameters": res.params.to_dict(),
        "effects": effects_to_dict(res.effects),
        "controller": controller.to_dict(),
        "simulation": {
            "seed": int(res.seed),
            "substeps": res.substeps,
            "dt": 1.0 / fs_hz / res.substeps,
            "control_period": 1.0 / fs_hz,
            "integrator": "RK4, fixed step, control held per period, Karnopp stick/slip with zero-crossing location",
            "stick_velocity": STICK_VELOCITY,
            "tau_sensor": res.tau_sensor,
            "samples": len(res.t),
            "duration_s": len(res.t) / fs_hz,
            "plant": "plant (ilic)",
        },
    }
    if isinstance(controller, PDSettings):
        m["drive_gain"] = controller.gtau
    if res.windows:
        m["ilic_windows"] = [w.to_dict() for w in res.windows]
    m.update(meta or {})
    return RunLog(chans, units, m)


def trajectory_log(
    traj: Trajectory | Multisine,
    n: int,
    *,
    params: RigidParameters,
    effects: Effects,
    controller: CTCSettings | PDSettings,
    fs_hz: float,
    seed: int,
    tau_sensor: str,
    scenario: dict[str, Any],
    substeps: int = 10,
    progress: Callable[[int, int], None] | None = None,
    update: OnlineUpdate | None = None,
) -> RunLog:
    """The run log of the loop on ``n`` samples of ``traj`` (:meth:`~plant.trajectories.Sampled.sample_both`: the reference, and the
    logged derivatives the controller sees), with ``scenario`` and the trajectory in its metadata (``meta['scenario']``);
    ``update``: the CTC's online update (:func:`simulate_loop`)."""
    _, q_r, qd_r, qdd_r, qd_log, qdd_log = traj.sample_both(n, fs_hz)  # = sample(), sample_centred()
    res = simulate_loop(
        q_r=q_r,
        qd_r=qd_r,
        qdd_r=qdd_r,
        qd_log=qd_log,
        qdd_log=qdd_log,
        params=params,
        effects=effects,
        controller=controller,
        fs_hz=fs_hz,
        substeps=substeps,
        seed=seed,
        tau_sensor=tau_sensor,
        progress=progress,
        update=update,
    )
    return loop_log(res, q_ref=q_r, qd_ref=qd_log, qdd_ref=qdd_log, meta={"scenario": {**scenario, "trajectory": traj.to_dict()}})
