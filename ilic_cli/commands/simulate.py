"""``ilic simulate``: run a named closed-loop scenario and write its log."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import click

from ilic_cli.commands.common import (
    LOG_FORMATS,
    STRUCTURES,
    note,
    options_named,
    parse_assignment,
    parse_effect_option,
    plant_of_model_file,
    progress_enabled,
    structure_or_model_file,
)
from ilic_cli.commands.robot_sim import simulate_options
from ilic_cli.errors import SimulationError
from ilic_cli.io import WriteOptions, write_log
from ilic_cli.io.atomic import same_path
from ilic_cli.simulation.scenarios import DEFAULT_EMPS_LOG, Overrides, check, get_scenario, run_scenario

SCENARIO_NAMES = ("paper-sim", "paper-payload", "emps-benchmark", "robot-sim")


@click.command("simulate")
@click.option("--scenario", default="paper-sim", show_default=True, help=f"Scenario: {', '.join(SCENARIO_NAMES)}.")
@click.option("--duration", "duration", type=float, default=None, help="Simulated time (s) [default: the scenario's: 124 s; emps-benchmark: the log's].")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the noise (numpy PCG64).")
@click.option("-o", "--output", "output", type=click.Path(path_type=Path), required=True, help="Output log (.mcap, .mat, .csv, .bag or a ROS 2 bag folder).")
@click.option("--format", "out_format", type=click.Choice(LOG_FORMATS), default=None, help="Output format [default: from the extension; MCAP for .mcap].")
@click.option("--storage", type=click.Choice(["sqlite3", "mcap"]), default="sqlite3", show_default=True, help="Storage plugin of a ROS 2 bag.")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE", help="Plant parameter (M, Fv, Fc, offset); repeatable.")
@click.option(
    "--effect",
    "effects",
    multiple=True,
    metavar="ID[:k=v,...]",
    help="Add an effect (asymmetric_friction, stribeck, position_ripple, spring, payload_change, delay, flexibility, saturation, "
    "quantization, noise, disturbance, current_loop, or any other defined in ilic_cli.effects); repeatable.",
)
@click.option("--controller", type=click.Choice(["ctc", "pd"]), default=None, help="Controller [default: the scenario's].")
@click.option("--omega", type=float, default=None, help="CTC bandwidth (rad/s) [default: 2*pi*20].")
@click.option("--xi", type=float, default=None, help="CTC damping [default: sqrt(2)/2].")
@click.option("--alpha", type=float, default=None, help="CTC Coulomb smoothing (2/pi)atan(alpha*qd) [default: 1000].")
@click.option("--structure", "structure", type=click.Choice(STRUCTURES), default=None, help="CTC/IDIM-ILIC model structure [default: rigid].")
@click.option(
    "--model",
    "model",
    default=None,
    metavar="FILE",
    help="Model file (model.json): the plant's parameters and effects (--param and --effect apply on top; "
    "--model STRUCTURE: deprecated spelling of --structure).",
)
@click.option(
    "--velocity",
    "velocity",
    type=click.Choice(["backward", "exact"]),
    default=None,
    help="CTC velocity: backward difference (eq. 25) or the plant's exact velocity, to study the eq. 27 bias [default: backward].",
)
@click.option("--chi0", "chi0", multiple=True, metavar="NAME=VALUE", help="Initial CTC parameter (eq. 28; default M=100, others 0); repeatable.")
@click.option("--window", "window_s", type=float, default=None, help="IDIM-ILIC window T_obs (s) [default: 6.2].")
@click.option("--sigma-max", "sigma_max", type=float, default=None, help="%sigma_max of essential parameters [default: 15].")
@click.option("--no-ilic", is_flag=True, help="Keep the initial CTC parameters (no online update).")
@click.option("--kp", type=float, default=None, help="PD position gain (1/s) [default: 160.18 or the log's].")
@click.option("--kv", type=float, default=None, help="PD velocity gain (V/(m/s)) [default: 243.45 or the log's].")
@click.option("--drive-gain", "gtau", type=float, default=None, help="PD drive gain (N/V) [default: 35.1507 or the log's].")
@click.option("--substeps", type=int, default=10, show_default=True, help="Integration steps per 1 ms control period.")
@click.option("--noise-tau", type=float, default=None, help="Std of the force measurement noise (N) (effect 'noise').")
@click.option("--noise-q", type=float, default=None, help="Std of the position measurement noise (m) (effect 'noise').")
@click.option("--resolution", type=float, default=None, help="Encoder resolution (m) (effect 'quantization').")
@click.option(
    "--tau-sensor",
    type=click.Choice(["centred", "command"]),
    default=None,
    help="Logged force: centred mean over the sample interval (CTC default) or the held command (PD default).",
)
@click.option(
    "--trajectory",
    type=click.Choice(["paper", "trapezoid", "multisine"]),
    default=None,
    help="Reference shape: the paper's exciting cycle, back-and-forth trapezoidal moves with dwell, or a 0.1-1.2 Hz multisine [default: paper].",
)
@click.option("--trajectory-seed", type=int, default=None, help="Vary the reference with this seed (cycle amplitudes; trapezoid speeds; multisine phases).")
@click.option(
    "--published-setup",
    is_flag=True,
    help="emps-benchmark: replay as the published simulation did (controller clock t(10)-t(9) of the file, pulses interpolated in continuous time).",
)
@click.option(
    "--log",
    "log_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Recorded log replayed by emps-benchmark [default: ../shared/emps/DATA_EMPS.mat from the repository root].",
)
@simulate_options
def command(
    scenario: str,
    duration: float | None,
    seed: int,
    output: Path,
    out_format: str | None,
    storage: str,
    params: tuple[str, ...],
    effects: tuple[str, ...],
    controller: str | None,
    omega: float | None,
    xi: float | None,
    alpha: float | None,
    structure: str | None,
    model: str | None,
    velocity: str | None,
    chi0: tuple[str, ...],
    window_s: float | None,
    sigma_max: float | None,
    no_ilic: bool,
    kp: float | None,
    kv: float | None,
    gtau: float | None,
    substeps: int,
    noise_tau: float | None,
    noise_q: float | None,
    resolution: float | None,
    tau_sensor: str | None,
    trajectory: str | None,
    trajectory_seed: int | None,
    log_path: Path | None,
    published_setup: bool,
) -> None:
    """Simulate the axis in closed loop and write the log.

    Scenarios: paper-sim (paper VI-E: M=95, Fv=200, Fc=20, CTC with online
    IDIM-ILIC from chi0=(100,0,0)), paper-payload (+10 kg at 60 s, VI-G),
    emps-benchmark (the benchmark PD loop replaying DATA_EMPS.mat's reference).
    Everything used goes into the log metadata. Same arguments and seed give
    a bit-identical file.

    \b
    Examples:
      ilic simulate --scenario paper-sim -o sim.mcap
      ilic simulate --scenario paper-sim --param M=90 --effect stribeck:Fs=5,vs=0.01 -o s.mcap
      ilic simulate --scenario emps-benchmark -o emps_sim.mat
    """

    with options_named():
        get_scenario(scenario)
        structure, model_path = structure_or_model_file(model, structure)
        ov = Overrides(
            duration_s=duration,
            substeps=substeps,
            seed=seed,
            tau_sensor=tau_sensor,
            log_path=log_path,
            trajectory_seed=trajectory_seed,
            trajectory=trajectory,
            controller=controller,
            published_setup=published_setup,
        )
        _parameter_overrides(ov, model_path, params, chi0, effects, {"tau_std": noise_tau, "q_std": noise_q}, resolution)
        ctc = {"omega": omega, "xi": xi, "alpha": alpha, "window_s": window_s, "sigma_max_pct": sigma_max, "model": structure, "velocity": velocity}
        _controller_overrides(ov, ctc, no_ilic, {"kp": kp, "kv": kv, "gtau": gtau})
        check(scenario, ov)
        if get_scenario(scenario).reference == "log":  # refuse before simulating, not after
            if same_path(log_path or DEFAULT_EMPS_LOG, output):
                raise SimulationError(output, "output would overwrite the replayed log; choose another output path")
        note(f"ilic: simulating {scenario} ...")
        log = run_scenario(scenario, ov, progress=_progress() if progress_enabled() else None)
        for w in log.meta.get("ilic_windows", []):
            est = ", ".join(f"{n}={p['value']:.6g}" + ("" if w["essential"][n] else "*") for n, p in w["parameters"].items() if p["value"] is not None)
            note(f"  window {w['k']} [{w['t_start']:.1f}, {w['t_end']:.1f}] s: {est}")
        reference = (log.provenance.scenario or {}).get("log")
        write_log(log, output, out_format, WriteOptions(storage=storage), inputs=(reference,) if reference else ())
        note(f"ilic: wrote {output} ({len(log)} samples, {log.duration_s:.3f} s)")


def _parameter_overrides(
    ov: Overrides,
    model_path: Path | None,
    params: tuple[str, ...],
    chi0: tuple[str, ...],
    effects: tuple[str, ...],
    noise: dict[str, float | None],
    resolution: float | None,
) -> None:
    """Put the parameters into ``ov``: the model file's parameters and effects, ``--param``, ``--chi0``, ``--effect``, the noise and resolution options."""
    if model_path is not None:
        rigid, plant_effects = plant_of_model_file(model_path)
        ov.params.update(rigid.to_dict())
        ov.effects.update({eid: e.to_dict() for eid, e in plant_effects.items()})
    for text in params:
        k, v = parse_assignment(text, "--param")
        ov.params[k] = v
    for text in chi0:
        k, v = parse_assignment(text, "--chi0")
        ov.chi0[k] = v
    for text in effects:
        eid, values = parse_effect_option(text)
        ov.effects[eid] = {**ov.effects.get(eid, {}), **values}
    given = {k: v for k, v in noise.items() if v is not None}
    if given:
        ov.effects["noise"] = {**ov.effects.get("noise", {}), **given}
    if resolution is not None:
        ov.effects["quantization"] = {"resolution": resolution}


def _controller_overrides(ov: Overrides, ctc: Mapping[str, object], no_ilic: bool, pd: Mapping[str, float | None]) -> None:
    """Put the controllers' options into ``ov``: the CTC's (those given) and ``--no-ilic``, the PD's gains (those given)."""
    ov.ctc.update({key: value for key, value in ctc.items() if value is not None})
    if no_ilic:
        ov.ctc["ilic"] = False
    ov.pd.update({key: value for key, value in pd.items() if value is not None})


def _progress():
    def report(done: int, total: int) -> None:
        click.echo(f"\r  {100 * done // total:3d} %", err=True, nl=done >= total)

    return report
