"""Named simulation scenarios with documented defaults, and their overrides.

==================  ==========================================================
``paper-sim``       paper section VI-E: M = 95 kg, Fv = 200 N.s/m, Fc = 20 N,
                    rigid model, CTC (omega = 20 Hz, xi = sqrt(2)/2,
                    alpha = 1000) with online IDIM-ILIC every T_obs = 6.2 s,
                    chi0 = (100, 0, 0), the default exciting cycle; 124 s.
``paper-payload``   as ``paper-sim`` plus 10 kg added at 60 s (section VI-G); 124 s.
``emps-benchmark``  the benchmark PD loop with the published rigid-model
                    estimates (M = 95.1089, Fv = 203.5034, Fc = 20.3935,
                    offset = -3.1648) replaying the recorded ``qg`` (and
                    ``pulses_N``) of ``../shared/emps/DATA_EMPS.mat``; the
                    log's duration (24.84 s).
==================  ==========================================================

``emps-benchmark`` with ``published_setup`` (``--published-setup``) replays as
the benchmark's published simulation did, which its table of relative errors
reflects: the controller runs at ``t(10) - t(9)`` of the file (0.99998396 ms
for DATA_EMPS.mat, 1.00000802 ms for DATA_EMPS_PULSES.mat, not 1 ms: the
simulated samples drift against the recording by up to 0.4 ms), and the
pulses enter interpolated in continuous time (``PDSettings.pulse_input =
"ramp"``). The default replays on the recording's clock with the pulses held
per sample, as the rig applied them (closer to the measurement).

Every value can be overridden (:class:`Overrides`, the ``ilic simulate``
options). :func:`run_scenario` returns the simulated :class:`RunLog`; the CTC's
online IDIM-ILIC is handed to the loop here (:func:`ilic_cli.simulation.online.ilic_update`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ilic_cli.effects import Effects, effects_to_dict, make_effects
from ilic_cli.errors import ParameterError, SimulationError
from ilic_cli.io import read_log
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.online import ilic_update
from plant.closed_loop import trajectory_log
from plant.controllers import CTCSettings, PDSettings
from plant.dynamics import RigidParameters, plant_vector
from plant.replay import simulate_replay
from plant.trajectories import TRAJECTORIES, make_trajectory

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_EMPS_LOG = REPO_ROOT.parent / "shared" / "emps" / "DATA_EMPS.mat"
"""``../shared/emps/DATA_EMPS.mat`` relative to the repository root."""

FS_HZ = 1000.0
PUBLISHED_RIGID = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}


@dataclass(frozen=True)
class Scenario:
    """A named scenario: plant, effects, controller, duration and reference."""

    name: str
    description: str
    section: str
    params: RigidParameters
    effects: dict[str, dict[str, float]]
    controller: str
    duration_s: float | None
    reference: str  # "exciting_cycle" or "log"


SCENARIOS: dict[str, Scenario] = {
    "paper-sim": Scenario(
        "paper-sim",
        "CTC + online IDIM-ILIC on the rigid axis, stationary parameters",
        "paper section VI-E, Table I",
        RigidParameters(95.0, 200.0, 20.0, 0.0),
        {},
        "ctc",
        124.0,
        "exciting_cycle",
    ),
    "paper-payload": Scenario(
        "paper-payload",
        "as paper-sim with a 10 kg payload added at 60 s",
        "paper section VI-G",
        RigidParameters(95.0, 200.0, 20.0, 0.0),
        {"payload_change": {"dM": 10.0, "t_change": 60.0}},
        "ctc",
        124.0,
        "exciting_cycle",
    ),
    "emps-benchmark": Scenario(
        "emps-benchmark",
        "benchmark PD loop with the published rigid estimates, replaying the recorded qg (and pulses)",
        "emps-benchmark.md, closed-loop simulation table",
        RigidParameters(**PUBLISHED_RIGID),
        {},
        "pd",
        None,
        "log",
    ),
}


@dataclass
class Overrides:
    """Command-line overrides; ``None``/empty means the scenario's default.

    ``params``: ``M, Fv, Fc, offset``; ``effects``: id -> parameters (merged
    over the scenario's; an empty dict uses the effect's defaults);
    ``ctc``: ``omega, xi, alpha, window_s, sigma_max_pct, cutoff_hz, model,
    ilic, velocity``; ``chi0``: initial controller parameters; ``pd``: ``kp, kv, gtau, vmax``;
    ``published_setup``: ``emps-benchmark`` as the published simulation ran (module docstring);
    ``trajectory``: the reference's shape (:data:`plant.trajectories.TRAJECTORIES`, default
    ``paper``) for the scenarios that follow an exciting trajectory, varied by ``trajectory_seed``.
    """

    params: dict[str, float] = field(default_factory=dict)
    effects: dict[str, dict[str, float]] = field(default_factory=dict)
    controller: str | None = None
    ctc: dict[str, Any] = field(default_factory=dict)
    chi0: dict[str, float] = field(default_factory=dict)
    pd: dict[str, float] = field(default_factory=dict)
    duration_s: float | None = None
    substeps: int = 10
    seed: int = 0
    tau_sensor: str | None = None
    log_path: str | Path | None = None
    trajectory_seed: int | None = None
    published_setup: bool = False
    trajectory: str | None = None


def get_scenario(name: str) -> Scenario:
    """Return the named scenario; :class:`SimulationError` (exit 2) for an unknown name."""
    try:
        return SCENARIOS[name]
    except KeyError:
        raise ParameterError("scenario", name, f"one of {', '.join(SCENARIOS)}") from None


def resolve(name: str, ov: Overrides) -> tuple[Scenario, RigidParameters, Effects, CTCSettings | PDSettings]:
    """Scenario with the overrides applied: parameters, effects, controller."""
    sc = get_scenario(name)
    params = sc.params.replace(**ov.params)
    spec = {k: dict(v) for k, v in sc.effects.items()}
    for eid, values in ov.effects.items():
        spec[eid] = {**spec.get(eid, {}), **values}
    effects = make_effects(spec)
    kind = ov.controller or sc.controller
    if kind not in ("ctc", "pd"):
        raise ParameterError("controller", kind, "one of ctc, pd")
    ctl: CTCSettings | PDSettings
    if kind == "ctc":
        known = {"omega", "xi", "alpha", "window_s", "sigma_max_pct", "cutoff_hz", "model", "ilic", "velocity"}
        bad = sorted(set(ov.ctc) - known)
        if bad:
            raise ParameterError("controller", bad[0], f"a CTC setting ({', '.join(sorted(known))})")
        ctl = replace(CTCSettings(), **ov.ctc, chi0=dict(ov.chi0) or None)
    else:
        if ov.chi0 or ov.ctc:
            raise SimulationError(None, f"CTC settings ({', '.join(sorted(ov.ctc) + sorted(f'chi0.{k}' for k in ov.chi0))}) do not apply to the PD controller")
        ctl = _pd_with(PDSettings(), ov.pd)
    ctl.validate()
    return sc, params, effects, ctl


def check(name: str, ov: Overrides) -> None:
    """Raise :class:`SimulationError` for any bad value before anything runs."""
    sc, params, effects, ctl = resolve(name, ov)
    if ov.duration_s is not None and not (math.isfinite(ov.duration_s) and ov.duration_s > 0):
        raise ParameterError("duration", ov.duration_s, "a positive number of seconds")
    if not isinstance(ov.substeps, int) or ov.substeps < 1:
        raise ParameterError("substeps", ov.substeps, "a positive integer")
    plant_vector(params, effects)
    if ov.trajectory is not None and ov.trajectory not in TRAJECTORIES:
        raise ParameterError("trajectory", ov.trajectory, f"one of {', '.join(TRAJECTORIES)}")
    if ov.trajectory is not None and sc.reference == "log":
        raise ParameterError("trajectory", ov.trajectory, "left out: the emps-benchmark scenario replays the recorded reference")
    if ov.published_setup and sc.reference != "log":
        raise ParameterError("published_setup", name, "used with the emps-benchmark replay only")
    if sc.reference == "log":
        p = Path(ov.log_path) if ov.log_path is not None else DEFAULT_EMPS_LOG
        if not p.exists():
            raise SimulationError(p, "recorded reference log not found (the emps-benchmark scenario replays DATA_EMPS.mat; give another recorded log)")


def run_scenario(name: str, ov: Overrides | None = None, progress: Any = None) -> RunLog:
    """Simulate a named scenario and return its log (metadata: every value used)."""
    ov = ov or Overrides()
    check(name, ov)
    sc, params, effects, ctl = resolve(name, ov)
    scen_meta: dict[str, Any] = {"name": sc.name, "description": sc.description, "source": sc.section}
    if sc.reference == "log":
        log = _read_reference_log(ov.log_path)
        n = len(log)
        if ov.duration_s is not None:
            n = min(n, int(round(ov.duration_s * FS_HZ)) + 1)
            log = log.slice(0, n)
        if isinstance(ctl, PDSettings) and not ov.pd:
            ctl = _pd_from_log(log, ctl)
        clock = None
        if ov.published_setup:
            clock = float(log.t[9] - log.t[8]) if len(log) > 9 else log.dt_s
            if isinstance(ctl, PDSettings):
                ctl = replace(ctl, pulse_input="ramp")
        out = simulate_replay(log, params, effects, ctl, substeps=ov.substeps, seed=ov.seed, tau_sensor=ov.tau_sensor, clock_s=clock)
        out.meta["scenario"] = {**scen_meta, "log": str(log.provenance.source)}
        if ov.published_setup:
            out.meta["scenario"]["published_setup"] = {"clock_s": clock, "pulse_input": "ramp"}
        out.meta.pop("replay_of", None)
        return out
    duration = sc.duration_s if ov.duration_s is None else ov.duration_s
    assert duration is not None  # only the scenarios that replay a log (handled above) have no duration of their own
    n = int(round(duration * FS_HZ))
    traj = make_trajectory(ov.trajectory or "paper", ov.trajectory_seed)
    sensor = ov.tau_sensor or ("centred" if isinstance(ctl, CTCSettings) else "command")
    return trajectory_log(
        traj,
        n,
        params=params,
        effects=effects,
        controller=ctl,
        fs_hz=FS_HZ,
        seed=ov.seed,
        tau_sensor=sensor,
        scenario=scen_meta,
        substeps=ov.substeps,
        progress=progress,
        update=ilic_update,
    )


def _read_reference_log(path: str | Path | None) -> RunLog:
    p = Path(path) if path is not None else DEFAULT_EMPS_LOG
    if not p.exists():
        raise SimulationError(p, "recorded reference log not found (the emps-benchmark scenario replays DATA_EMPS.mat; give another recorded log)")
    log = read_log(p)
    if "q_ref" not in log:
        raise SimulationError(p, "the log has no reference position (q_ref / qg) to replay")
    return log


def _pd_from_log(log: RunLog, default: PDSettings) -> PDSettings:
    """``default`` with the gains the log records (its controller's ``kp``, ``kv``; its drive gain)."""
    view = log.controller
    kw: dict[str, float] = {}
    if view is not None and view.kp is not None:
        kw["kp"] = view.kp
    if view is not None and view.kv is not None:
        kw["kv"] = view.kv
    if log.sensor.drive_gain:
        kw["gtau"] = log.sensor.drive_gain
    return _pd_with(default, kw)


def _pd_with(default: PDSettings, gains: Mapping[str, float]) -> PDSettings:
    """``default`` with the gains ``kp``, ``kv``, ``gtau`` given in ``gains`` (another key is a TypeError, as in ``dataclasses.replace``)."""
    bad = sorted(set(gains) - {"kp", "kv", "gtau"})
    if bad:
        raise TypeError(f"PDSettings gets no gain {bad[0]!r}")
    return replace(default, kp=gains.get("kp", default.kp), kv=gains.get("kv", default.kv), gtau=gains.get("gtau", default.gtau))


def describe() -> dict[str, Any]:
    """All scenarios with their defaults (for ``--list`` and documentation)."""
    out = {}
    for name, sc in SCENARIOS.items():
        _, params, effects, ctl = resolve(name, Overrides())
        out[name] = {
            "description": sc.description,
            "source": sc.section,
            "parameters": params.to_dict(),
            "effects": effects_to_dict(effects),
            "controller": ctl.to_dict(),
            "duration_s": sc.duration_s,
        }
    return out


__all__ = ["SCENARIOS", "Overrides", "Scenario", "describe", "get_scenario", "resolve", "run_scenario"]
