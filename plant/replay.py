"""Replay a recorded log's reference (and pulses) through the plant under the log's controller."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.derivatives import central_difference
from ilic_cli.effects import EffectParams, make_effects
from ilic_cli.errors import ParameterError, SimulationError
from ilic_cli.filtering import butter_lowpass_zero_phase
from ilic_cli.regressor import get_model
from ilic_cli.runlog import Controller, RunLog, joint_type
from plant.closed_loop import LoopResult, loop_log, simulate_loop
from plant.controllers import CTCSettings, OpenLoopSettings, PDSettings
from plant.dynamics import RigidParameters, plant_model
from plant.trajectories import Trajectory

CTC_REPLAY_KEYS = ("omega", "xi", "alpha", "model", "window_s", "sigma_max_pct", "cutoff_hz", "velocity")
"""CTC settings a replay takes over from the log (the parameters come from its ``*_hat`` channels or the model)."""


def records_controller(log: RunLog) -> bool:
    """Whether ``log`` records the controller that ran (its :attr:`~ilic_cli.runlog.RunLog.controller`, or the PD command ``vir``)."""
    return log.controller is not None or "vir" in log


def _gain(value: float | None) -> float:
    """``value``; a gain missing from the metadata (None) raises TypeError, as float(None) does."""
    if value is None:
        raise TypeError("a controller gain is missing")
    return float(value)


def controller_from_log(log: RunLog) -> CTCSettings | PDSettings:
    """The controller the log records (:func:`records_controller`, read through :attr:`~ilic_cli.runlog.RunLog.controller`);
    a log with none is refused. A log with a ``vir`` channel and no controller entry is a PD loop of unnamed kind."""
    if not records_controller(log):
        raise SimulationError(
            log.provenance.source,
            "the log records no controller (its kind and gains): a replay needs the loop that ran; give the PD loop's gains and drive gain, or choose CTC",
        )
    # no controller entry (a PD log known by its vir): the view of an entry of no kind, its gains read from the top-level keys
    view = log.controller or Controller.from_meta({**log.meta, "controller": {"kind": ""}})
    assert view is not None  # an entry was given above
    ctl = view.settings
    if view.kind == "pd" or (not view.kind and "vir" in log):
        try:
            return PDSettings(
                kp=_gain(view.kp),
                kv=_gain(view.kv),
                gtau=_gain(view.drive_gain),
                vmax=float(ctl.get("vmax", 10.0)),
                pulse_input=str(ctl.get("pulse_input", "held")),
                delay_samples=float(ctl.get("delay_samples", 1.0)),
                velocity=str(ctl.get("velocity", "averaged")),
                continuous=bool(ctl.get("continuous", False)),
            )
        except (TypeError, ValueError):
            raise SimulationError(log.provenance.source, "the log's PD controller lacks kp, kv or drive_gain in its metadata") from None
    kw = {k: ctl[k] for k in CTC_REPLAY_KEYS if k in ctl}
    return CTCSettings(**kw, ilic=False)


def simulate_replay(
    log: RunLog,
    params: RigidParameters | Mapping[str, float],
    effects: Mapping[str, EffectParams | Any] | None = None,
    controller: CTCSettings | PDSettings | None = None,
    *,
    substeps: int = 10,
    seed: int = 0,
    tau_sensor: str | None = None,
    clock_s: float | None = None,
) -> RunLog:
    """Replay ``log``'s recorded reference (and pulses) through the plant; return the simulated log.

    Parameters
    ----------
    log : RunLog
        Needs ``t`` and ``q_ref`` (``qd_ref, qdd_ref`` are used when present,
        else central differences of ``q_ref``); ``pulses`` are added to the PD
        output as in the benchmark. A log written by ``ilic simulate`` carries
        its trajectory in ``meta["scenario"]["trajectory"]``: the controller
        then gets the exact point reference it had (the logged ``qd_ref,
        qdd_ref`` are centred averages, see ``plant.trajectories``).
    params : RigidParameters or dict
        Plant parameters ``M, Fv, Fc, offset``; with ``Fv_pos/Fc_pos/Fv_neg/Fc_neg``
        in the dict the ``asymmetric_friction`` effect is made from them.
    effects : dict
        Effect id -> parameters or :class:`~ilic_cli.effects.EffectParams`.
    controller : CTCSettings or PDSettings, optional
        Default: the log's controller (``meta["controller"]``): PD with its
        ``kp, kv`` and ``drive_gain``; otherwise CTC with the log's gains and,
        when the log has ``*_hat`` channels, the parameters in force at each
        sample (else the given plant parameters, no online update).
    substeps, seed : integration substeps per period; noise seed.
    tau_sensor : ``centred`` or ``command``; default ``command`` for PD
        (``tau = gtau*vir``), ``centred`` for CTC.
    clock_s : float, optional
        Control period of the replay; default the log's sample period. With
        another period the reference (and pulses) are interpolated linearly
        at ``k*clock_s`` and the result is on that clock, sample ``k`` for
        sample ``k`` of the log (the published benchmark simulation ran its
        controller at ``t(10) - t(9)`` of the file, see ``ilic_cli.simulation.scenarios``).

    Returns
    -------
    RunLog
        Same time base; ``q`` simulated, ``q_ref`` etc. from the log, ``tau``
        simulated (and ``vir`` for PD); metadata as ``ilic simulate`` with
        ``meta["replay_of"]`` the source.
    """
    if isinstance(params, RigidParameters):
        eff = make_effects(effects)
    else:
        params, eff = plant_model(params, effects)
    log.require("t", "q_ref")
    ctl = controller or controller_from_log(log)
    ref = _replay_reference(log, clock_s)
    q_ctl, qd_ctl, qdd_ctl = ref.q_ref, ref.qd_ref, ref.qdd_ref
    traj = None if ref.grid is not None else _trajectory_from_meta(log, ref.fs)
    if traj is not None:  # a log of ilic simulate: the controller's exact (point) reference
        _, q_ctl, qd_ctl, qdd_ctl = traj.sample(len(log), ref.fs)
    sensor = tau_sensor or ("command" if isinstance(ctl, PDSettings) else "centred")
    ctl, sched = _replay_controller(log, ctl, params)
    res = simulate_loop(
        q_r=q_ctl,
        qd_r=qd_ctl,
        qdd_r=qdd_ctl,
        qd_log=ref.qd_ref,
        qdd_log=ref.qdd_ref,
        params=params,
        effects=eff,
        controller=ctl,
        fs_hz=ref.fs,
        substeps=substeps,
        seed=seed,
        pulses=ref.pulses,
        tau_sensor=sensor,
        chi_schedule=sched,
        x0=_measured_start(log, 1.0 / ref.fs) if isinstance(ctl, PDSettings) else None,
    )
    res.t = ref.grid if ref.grid is not None else np.asarray(log.t, dtype=np.float64).copy()
    source = log.provenance.source
    meta: dict[str, Any] = {"replay_of": source, "scenario": {"name": "replay", "source": source}}
    if ref.grid is not None:
        meta["replay_clock_s"] = clock_s
    return loop_log(res, q_ref=ref.q_ref, qd_ref=ref.qd_ref, qdd_ref=ref.qdd_ref, meta=meta, joint=joint_type(log.units.get("q")))


@dataclass(frozen=True)
class _Reference:
    """The reference a replay logs: on the log's clock (``grid`` None) or interpolated at ``k*clock_s`` (``grid`` those instants)."""

    fs: float
    q_ref: np.ndarray
    qd_ref: np.ndarray
    qdd_ref: np.ndarray
    pulses: np.ndarray | None
    grid: np.ndarray | None


def _replay_reference(log: RunLog, clock_s: float | None) -> _Reference:
    """The log's reference and pulses on the replay's clock (:func:`simulate_replay`'s ``clock_s``); derivatives logged or differenced."""
    fs = log.fs_hz
    q_ref = log["q_ref"]
    pulses = log["pulses"] if "pulses" in log else None
    grid = None
    resampled = clock_s is not None and clock_s != log.dt_s
    if resampled:
        if not (clock_s is not None and math.isfinite(clock_s) and clock_s > 0):
            raise ParameterError("clock_s", clock_s, "a positive number of seconds")
        fs = 1.0 / clock_s
        grid = np.arange(len(log), dtype=np.float64) * clock_s + float(log.t[0])
        q_ref = np.interp(grid, log.t, q_ref)
        pulses = None if pulses is None else np.interp(grid, log.t, pulses)
    dt = 1.0 / fs
    qd_ref = log["qd_ref"] if "qd_ref" in log and not resampled else central_difference(q_ref, dt)
    qdd_ref = log["qdd_ref"] if "qdd_ref" in log and not resampled else central_difference(qd_ref, dt)
    return _Reference(fs, q_ref, qd_ref, qdd_ref, pulses, grid)


def _replay_controller(log: RunLog, ctl: CTCSettings | PDSettings, params: RigidParameters) -> tuple[CTCSettings | PDSettings, np.ndarray | None]:
    """The replay's controller, and the CTC's parameters at each sample from the log's ``*_hat`` channels (else None).

    A CTC without them runs with the plant's parameters, no online update.
    """
    if not isinstance(ctl, CTCSettings):
        return ctl, None
    names = get_model(ctl.model).names
    if all(f"{n}_hat" in log for n in names):
        return ctl, np.stack([log[f"{n}_hat"] for n in names], axis=1)
    fixed = CTCSettings(
        **{
            **{k: getattr(ctl, k) for k in CTC_REPLAY_KEYS},
            "ilic": False,
            "chi0": {n: getattr(params, n, 0.0) for n in names if n in RigidParameters.NAMES},
        }
    )
    return fixed, None


def _measured_start(log: RunLog, dt: float) -> tuple[float, float] | None:
    """Where the recording starts (a PD replay starts there): measured position, velocity of its first samples; None without ``q``."""
    if "q" not in log:
        return None
    q_meas = log["q"]
    v0 = float((q_meas[min(2, len(q_meas) - 1)] - q_meas[0]) / (min(2, len(q_meas) - 1) * dt)) if len(q_meas) > 1 else 0.0
    return (float(q_meas[0]), v0)


def _trajectory_from_meta(log: RunLog, fs: float) -> Any:
    """The exciting trajectory recorded by ``ilic simulate``, if it matches the log's samples."""
    doc = (log.provenance.scenario or {}).get("trajectory")
    if not isinstance(doc, dict) or "segments" not in doc:
        return None
    try:
        traj = Trajectory(
            tuple((float(d), float(a)) for d, a in doc["segments"]),
            q0=float(doc["q0"]),
            v0=float(doc.get("v0", 0.0)),
            repeat=bool(doc.get("repeat", True)),
            t_offset=float(doc.get("t_offset", 0.0)),
        )
        q = traj.evaluate(np.asarray(log.t, dtype=np.float64))[0]
    except (KeyError, TypeError, ValueError, SimulationError):
        return None
    return traj if np.allclose(q, log["q_ref"], rtol=0, atol=1e-12) else None


BENCHMARK_INIT_SAMPLES = 20
"""Samples at the start of the test log given to the model's state (the benchmark's state-initialisation window)."""


@dataclass(frozen=True)
class BenchmarkFigure:
    """The nonlinear system identification benchmark's EMPS figure of a model on a test log.

    Attributes
    ----------
    rmse_mm : float
        RMSE of the open-loop simulated position against the measured one, after the window (mm).
    fit_pct : float
        ``100 (1 - RMSE / std(q))`` over the same samples.
    samples, init_samples : int
        Samples compared, and the state-initialisation window before them.
    """

    rmse_mm: float
    fit_pct: float
    samples: int
    init_samples: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "rmse_mm": self.rmse_mm,
            "fit_pct": self.fit_pct,
            "samples": self.samples,
            "init_samples": self.init_samples,
            "task": "EMPS: u = vir, y = qm, open-loop simulation after the state-initialisation window",
        }


STATE_CUTOFF_HZ = 100.0
"""Cut-off of the zero-phase low-pass the measured state an open-loop simulation starts from is read through (:func:`measured_state`)."""


def measured_state(q_m: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity read from a measured position: zero-phase low-pass at :data:`STATE_CUTOFF_HZ`, central difference."""
    qf = butter_lowpass_zero_phase(np.asarray(q_m, dtype=np.float64), STATE_CUTOFF_HZ, fs_hz)
    return qf, central_difference(qf, 1.0 / fs_hz)


def open_loop(
    params: RigidParameters,
    effects: Mapping[str, EffectParams],
    command: np.ndarray,
    fs_hz: float,
    x0: tuple[float, float],
    *,
    gain: float = 1.0,
    substeps: int = 10,
) -> LoopResult:
    """The plant driven by ``gain * command`` held over each period (no feedback), from the state ``x0 = (q, qd)``."""
    u = np.ascontiguousarray(command, dtype=np.float64)
    zero = np.zeros(len(u))
    return simulate_loop(
        q_r=np.full(len(u), x0[0]),
        qd_r=zero,
        qdd_r=zero,
        params=params,
        effects=dict(effects),
        controller=OpenLoopSettings(gtau=gain),
        fs_hz=fs_hz,
        substeps=substeps,
        pulses=u,
        tau_sensor="command",
        x0=x0,
    )


def initial_state(q_m: np.ndarray, init_samples: int, fs_hz: float) -> tuple[float, float]:
    """The state ``(q, qd)`` at sample ``init_samples - 1`` read from the first ``init_samples`` measured positions only.

    A least-squares parabola through ``q_m[:init_samples]``, its value and slope at the last of them: the
    benchmark's state-initialisation window, nothing after it used.
    """
    k = np.arange(init_samples, dtype=np.float64) - (init_samples - 1)
    c = np.polyfit(k, np.asarray(q_m[:init_samples], dtype=np.float64), 2)
    return float(c[2]), float(c[1] * fs_hz)


def simulate_open_loop(
    log: RunLog,
    params: RigidParameters | Mapping[str, float],
    effects: Mapping[str, EffectParams | Any] | None = None,
    *,
    init_samples: int = BENCHMARK_INIT_SAMPLES,
    substeps: int = 10,
) -> tuple[RunLog, BenchmarkFigure]:
    """The benchmark's simulation of ``log``: its recorded drive command in, no feedback; and the figure.

    The official protocol of the EMPS task (``nonlinear_benchmarks``): u = ``vir``, y = ``qm``, the first
    ``init_samples`` samples set the state and the score is the RMSE of ``y[init_samples:]``. The plant
    starts at sample ``init_samples - 1`` from :func:`initial_state` (those samples only) and is driven by
    ``drive_gain * vir`` held over each period from there; the simulated position is compared with the
    measured one from sample ``init_samples`` on.
    """
    if isinstance(params, RigidParameters):
        eff = make_effects(effects)
    else:
        params, eff = plant_model(params, effects)
    log.require("t", "q", "vir")
    gain = log.sensor.drive_gain
    if not gain:
        raise SimulationError(log.provenance.source, "the log has no drive gain (N/V): the benchmark drives the model with drive_gain * vir")
    n = len(log)
    if not 3 <= init_samples < n - 2:
        raise ParameterError("init_samples", init_samples, f"between 3 and {n - 3}")
    T = log.dt_s
    q_all = np.asarray(log["q"], dtype=np.float64)
    k0 = init_samples - 1
    x0 = initial_state(q_all, init_samples, 1.0 / T)
    res = open_loop(params, eff, np.asarray(log["vir"][k0:], dtype=np.float64), 1.0 / T, x0, gain=float(gain), substeps=substeps)
    for name in ("q", "q_true", "qd_true", "qdd_true", "u", "vir", "tau", "chi"):
        setattr(res, name, getattr(res, name)[1:])
    res.pulses = None if res.pulses is None else res.pulses[1:]
    res.t = np.asarray(log.t[init_samples:], dtype=np.float64).copy()
    q = q_all[init_samples:]
    zero = np.zeros(len(q))
    rmse = float(np.sqrt(np.mean((res.q_true - q) ** 2)))
    figure = BenchmarkFigure(rmse_mm=1e3 * rmse, fit_pct=100.0 * (1.0 - rmse / float(np.std(q))), samples=len(q), init_samples=init_samples)
    meta = {"replay_of": log.provenance.source, "benchmark": figure.to_dict()}
    out = loop_log(res, q_ref=q, qd_ref=zero, qdd_ref=zero, meta=meta, joint=joint_type(log.units.get("q")))
    out.channels["q"] = res.q_true  # the simulated output (no sensor effects in the benchmark's comparison)
    return out, figure
