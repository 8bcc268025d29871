"""``ilic identify``: parse, call :func:`ilic_cli.identify.identify`, render."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click

from ilic_cli import identify_report as render
from ilic_cli.closed_loop_id import DEFAULT_SETTINGS
from ilic_cli.commands.common import (
    STRUCTURES,
    controller_options,
    input_options,
    load,
    note,
    options_named,
    parse_effect_option,
    structure_or_model_file,
    with_controller,
)
from ilic_cli.effects import get
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.identify import identify
from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io.atomic import atomic_write_text, same_path
from ilic_cli.modelfile import load_model_file, model_document
from ilic_cli.output_error import OESettings
from ilic_cli.parameters import DEFAULTS
from ilic_cli.plotting import plot_identify
from ilic_cli.prepare import as_joint, to_load_side


@click.command("identify")
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--method",
    type=click.Choice(["ls", "ilic", "both", "didim", "iv", "all", "oe", "cloe"]),
    default="both",
    show_default=True,
    help="IDIM-LS, IDIM-ILIC per window, both; DIDIM or IDIM-IV (closed-loop, from IDIM-LS, shown beside it); or all; "
    "OE / CLOE: open- / closed-loop output error of the position (from IDIM-LS; docs/output-error.md).",
)
@click.option(
    "--oe-segment",
    "oe_segment",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="OE: multiple shooting over stretches of this length (s), each with its own fitted state [default: one shot from the 20th sample].",
)
@click.option(
    "--oe-state",
    "oe_state",
    type=click.Choice(["fitted", "protocol"]),
    default="fitted",
    show_default=True,
    help="OE's one shot: fit its initial state with the parameters, or keep the EMPS benchmark protocol's (read from the first 20 samples).",
)
@click.option(
    "--structure",
    "structure",
    type=click.Choice(STRUCTURES),
    default=None,
    help="Model structure (regressor columns) [default: the model file's, else rigid-offset].",
)
@click.option(
    "--model",
    "model",
    default=None,
    metavar="FILE",
    help="Model file (model.json): its structure and effects are identified again (--model STRUCTURE: deprecated spelling of --structure).",
)
@click.option(
    "--effect",
    "effects",
    multiple=True,
    metavar="ID[:k=v,...]",
    help="Identify this effect's regressor columns too (IDIM-LS; nonlinear parameters fixed at the given or default values); repeatable.",
)
@click.option(
    "--gear-ratio",
    "gear_ratio",
    type=float,
    default=None,
    help="Motor-side log: motor rad per unit of load motion (rad/m of a screw, rad/rad of a gearbox); parameters are the load's.",
)
@click.option(
    "--torque-constant",
    "torque_constant",
    type=float,
    default=None,
    help="Motor-side log whose tau is the motor current (A): torque constant (N·m/A); needs --gear-ratio.",
)
@click.option(
    "--load-joint",
    "load_joint",
    type=click.Choice(["prismatic", "revolute"]),
    default=None,
    help=(
        "The joint's type, i.e. its units (m, N or rad, N·m): with --gear-ratio the load's [default: prismatic]; "
        "without, it declares the log's units (a ROS JointState does not say)."
    ),
)
@click.option(
    "--validate", "validate", multiple=True, type=click.Path(path_type=Path), help="Apply the estimates to this log too (cross-test validation); repeatable."
)
@click.option("--window", "window_s", type=click.FloatRange(min=0, min_open=True), default=6.2, show_default=True, help="IDIM-ILIC window T_obs (s).")
@click.option(
    "--sigma-max",
    "sigma_max",
    type=click.FloatRange(min=0, min_open=True),
    default=15.0,
    show_default=True,
    help="%σ_max: parameters above it are not essential.",
)
@click.option(
    "--ilic-cutoff", type=click.FloatRange(min=0, min_open=True), default=5.0, show_default=True, help="IDIM-ILIC force/regressor low-pass cut-off (Hz)."
)
@click.option("--ilic-decimation", type=click.IntRange(min=1), default=None, help="IDIM-ILIC decimation factor [default: from the cut-off, 0.8·fs/2/cut-off].")
@click.option(
    "--ref-lag",
    type=click.IntRange(min=0),
    default=None,
    help="IDIM-ILIC: delay the reference by this many samples to line it up with the measured motion "
    "[default: estimated from the positions; 0 for a loop that tracks well].",
)
@click.option("--cutoff", type=click.FloatRange(min=0, min_open=True), default=100.0, show_default=True, help="IDIM-LS position low-pass cut-off (Hz).")
@click.option("--order", type=click.IntRange(min=1, max=12), default=4, show_default=True, help="IDIM-LS Butterworth order.")
@click.option("--decimation", type=click.IntRange(min=1), default=10, show_default=True, help="IDIM-LS parallel decimation factor.")
@click.option("--trim", type=click.IntRange(min=0), default=49, show_default=True, help="IDIM-LS samples dropped at the start.")
@click.option(
    "--filtering",
    type=click.Choice(["matlab", "scipy"]),
    default="matlab",
    show_default=True,
    help="MATLAB-compatible filtering (reproduces published digits) or SciPy second-order sections.",
)
@click.option(
    "--max-iterations",
    "max_iterations",
    type=click.IntRange(min=1),
    default=None,
    help="DIDIM / IDIM-IV / OE / CLOE: most iterations [default: DIDIM 20, IDIM-IV 10, OE and CLOE 40].",
)
@click.option(
    "--tolerance",
    "tolerance",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="DIDIM / IDIM-IV: stop when the residual norm or the largest relative parameter change moves by less (%) [default: DIDIM 0.1, IDIM-IV 2.5].",
)
@controller_options
@click.option("--format", "out_format", type=click.Choice(["md", "csv", "json"]), default="md", show_default=True, help="What to print on stdout.")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Folder for report files (report.md/.csv/.json, model.json) and plots.")
@click.option("--plots", "plot_format", type=click.Choice(["png", "svg", "none"]), default="png", show_default=True, help="Plot format under --out.")
@input_options
def command(
    log: Path,
    method: str,
    structure: str | None,
    model: str | None,
    effects: tuple[str, ...],
    gear_ratio: float | None,
    torque_constant: float | None,
    load_joint: str | None,
    validate: tuple[Path, ...],
    window_s: float,
    sigma_max: float,
    ilic_cutoff: float,
    ilic_decimation: int | None,
    ref_lag: int | None,
    cutoff: float,
    order: int,
    decimation: int,
    trim: int,
    filtering: str,
    max_iterations: int | None,
    tolerance: float | None,
    oe_segment: float | None,
    oe_state: str,
    controller: str | None,
    kp: float | None,
    kv: float | None,
    drive_gain: float | None,
    pd_timing: str,
    out_format: str,
    out_dir: Path | None,
    plot_format: str,
    input_format: str | None,
    topic: str | None,
    ref_topic: str | None,
    joint: str | None,
    columns: str | None,
) -> None:
    """Identify the axis's parameters from LOG by IDIM-LS, IDIM-ILIC, DIDIM or IDIM-IV.

    IDIM-LS (paper section III) filters and differentiates the measured
    position; IDIM-ILIC (section V) regresses each window of the force on the
    noise-free reference trajectory. DIDIM and IDIM-IV iterate on closed-loop
    simulations of LOG's reference through LOG's controller (the PD loop of
    the EMPS recordings, or the controller in the metadata; --controller for
    a log that records none). Defaults reproduce the published EMPS
    benchmark tables. With --format json stdout holds only the JSON document.

    \b
    Examples:
      ilic identify DATA_EMPS.mat --method ls
      ilic identify DATA_EMPS.mat --structure asymmetric --validate DATA_EMPS_PULSES.mat
      ilic identify DATA_EMPS.mat --method ls --effect position_ripple:L=0.0125
      ilic identify DATA_EMPS.mat --method didim --structure asymmetric --validate DATA_EMPS_PULSES.mat
      ilic identify sim.mcap --format json --out report/
    """

    structure, model_path = structure_or_model_file(model, structure)
    doc = load_model_file(model_path) if model_path is not None else None
    if structure is None:
        structure = str(doc["model"]) if doc is not None and doc.get("model") in STRUCTURES else "rigid-offset"
    mass = float(doc["parameters"].get("M", DEFAULTS["M"])) if doc is not None else DEFAULTS["M"]
    chosen: dict[str, object] = {}
    try:
        skipped = []
        for eid, values in (doc or {}).get("effects", {}).items():
            if not get(eid).columns:  # a time shift or a measurement effect: nothing to add to the regressor
                skipped.append(eid)
                continue
            chosen[eid] = get(eid).value_from_plant(get(eid).values(values), mass)
    except ParameterError as exc:
        raise exc.at(model_path) from None
    if skipped:
        note(f"ilic: warning: {model_path}: not identified as regressor columns: {', '.join(skipped)}")
    try:
        for text in effects:
            eid, values = parse_effect_option(text)
            chosen[eid] = get(eid).value_from_plant(get(eid).values(values), mass)
    except ParameterError as exc:
        raise exc.at("--effect") from None
    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise IlicError(out_dir, "--out must be a folder")
    if out_dir is not None:
        _refuse_overwriting_inputs(out_dir, plot_format, (log, *validate))
    run = load(log, input_format, topic, ref_topic, joint, columns)
    if method in ("didim", "iv", "all", "cloe") or controller is not None or any(v is not None for v in (kp, kv, drive_gain)):
        # the loop that ran: DIDIM / IDIM-IV / CLOE replay it; for every method it says the force is the PD drive's held command
        run = with_controller(run, log, controller, kp, kv, drive_gain)
    if oe_segment is not None and method != "oe":
        raise IlicError("--oe-segment", "multiple shooting is --method oe's")
    if oe_state != "fitted" and (method != "oe" or oe_segment is not None):
        raise IlicError("--oe-state", "the initial state of --method oe's one shot (without --oe-segment)")
    others = [load(p, None, topic, ref_topic, joint, columns) for p in validate]
    if torque_constant is not None and gear_ratio is None:
        raise IlicError("--torque-constant", "needs --gear-ratio (the transmission from the motor to the load)")
    if gear_ratio is not None:
        with options_named():
            run, *others = [to_load_side(x, gear_ratio, torque_constant, load_joint or "prismatic") for x in (run, *others)]
    elif load_joint is not None:
        run, *others = [as_joint(x, load_joint) for x in (run, *others)]
    ls_settings = LSSettings(cutoff_hz=cutoff, order=order, decimation=decimation, trim=trim, matlab=(filtering == "matlab"))
    ilic_settings = ILICSettings(window_s=window_s, cutoff_hz=ilic_cutoff, decimation=ilic_decimation, sigma_max_pct=sigma_max, ref_lag=ref_lag)
    with options_named():
        closed = {
            m: replace(
                s,
                max_iterations=s.max_iterations if max_iterations is None else max_iterations,
                tolerance_pct=s.tolerance_pct if tolerance is None else tolerance,
            )
            for m, s in DEFAULT_SETTINGS.items()
        }
        oe_settings = OESettings(
            segment_s=oe_segment, fit_state=oe_state == "fitted", max_iterations=OESettings.max_iterations if max_iterations is None else max_iterations
        )
        result = identify(
            run,
            method=method,
            structure=structure,
            effects=chosen,
            ls_settings=ls_settings,
            ilic_settings=ilic_settings,
            validate=others,
            closed_loop_settings=closed,
            pd_timing=pd_timing,
            oe_settings=oe_settings,
        )
    for w in result.warnings:
        note(f"ilic: warning: {w}")
    text = {"md": render.to_markdown, "csv": render.to_csv, "json": lambda r: render.to_json(r.to_dict())}[out_format](result)
    if out_dir is not None:
        _write_outputs(result, run, out_dir, plot_format, inputs=(log, *validate))
    click.echo(text, nl=False)


def _write_outputs(result, run, out_dir: Path, plot_format: str, inputs: tuple[Path, ...]) -> None:

    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "report.md", render.to_markdown(result), inputs=inputs)
    atomic_write_text(out_dir / "report.csv", render.to_csv(result), inputs=inputs)
    atomic_write_text(out_dir / "report.json", render.to_json(result.to_dict()), inputs=inputs)
    oe = result.output_error()
    std = None if oe is None else {"parameters": {n: float(s) for n, s in zip(oe.names, oe.std, strict=True)}}
    doc = model_document(result.model, result.model_parameters(), method=result.model_method(), effects=result.model_effects(), source=result.source, std=std)
    atomic_write_text(out_dir / "model.json", render.to_json(doc), inputs=inputs)
    written = [out_dir / n for n in ("report.md", "report.csv", "report.json", "model.json")]
    if plot_format != "none":
        written += plot_identify(result, run, out_dir, plot_format)
    note(f"ilic: wrote {', '.join(str(p) for p in written)}")


def _refuse_overwriting_inputs(out_dir: Path, plot_format: str, inputs: tuple[Path, ...]) -> None:
    """Refuse an --out folder where a report file would replace an input (checked before any work)."""

    names = ["report.md", "report.csv", "report.json", "model.json"]
    if plot_format != "none":
        names += [f"{n}.{plot_format}" for n in ("parameters", "force", "tracking", "convergence")]
    for name in names:
        target = out_dir / name
        if target.exists() and any(same_path(src, target) for src in inputs):
            raise IlicError(target, "output would overwrite the input; choose another --out folder")
