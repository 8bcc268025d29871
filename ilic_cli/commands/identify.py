"""``ilic identify``: parse, call :func:`ilic_cli.identify.identify`, render."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from ilic_cli import identify_report as render
from ilic_cli.commands.common import (
    STRUCTURES,
    ControllerOptions,
    InputOptions,
    closed_loop_settings,
    controller_options,
    declared_joint,
    input_options,
    joint_option,
    note,
    options_named,
    parse_effect_option,
    structure_or_model_file,
)
from ilic_cli.commands.robot_identify import identify_options
from ilic_cli.effects import get as get_effect
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.estimators.base import ModelSpec, regressor_effects
from ilic_cli.identify import IdentifyReport, IdentifySettings, identify_with
from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io.atomic import atomic_write_text, same_path
from ilic_cli.methods import CHOICES, METHODS, methods_of
from ilic_cli.modelfile import load_model_file, model_document
from ilic_cli.output_error import OESettings
from ilic_cli.parameters import DEFAULTS
from ilic_cli.plotting import plot_identify
from ilic_cli.prepare import to_load_side
from ilic_cli.runlog import RunLog


@click.command("identify")
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--method",
    type=click.Choice(list(CHOICES)),
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
    help=(
        "Identify this effect's regressor columns too (IDIM-LS; nonlinear parameters fixed at the given or default values); repeatable. "
        "A drive lag, delay:delay=-SECONDS, evaluates the regressor that much later and goes into the closed-loop methods' plant; "
        "unstated, it is estimated where rows at rest are left out (drive_lag in the JSON); delay:delay=0 states none."
    ),
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
@joint_option(" With --gear-ratio, the load's [default: prismatic].")
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
@click.option(
    "--decimation",
    type=click.IntRange(min=1),
    default=None,
    help=(
        "IDIM-LS parallel decimation factor [default: from the log's rate, round(0.8·(fs/2)/min(40 Hz, 0.04·fs)): "
        "10 at and below 1 kHz, 20 at 2 kHz, 80 at 8 kHz]."
    ),
)
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
@identify_options
def command(log: Path, **options: Any) -> None:
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

    o = options
    spec = _model_spec(o)
    out = OutputOptions.of(o)
    validate: tuple[Path, ...] = o["validate"]
    out.refuse_overwriting(log, validate)
    inputs = InputOptions.of(o)
    run = inputs.load(log)
    controller = ControllerOptions.of(o)
    method = str(o["method"])
    if any(METHODS[m].closed_loop for m in methods_of(method)) or controller.given:
        # the loop that ran: DIDIM / IDIM-IV / CLOE replay it; for every method it says the force is the PD drive's held command
        run = controller.apply(run, log)
    oe_settings = _oe_settings(o)
    others = [inputs.load(p, named_format=False) for p in validate]
    run, *others = TransmissionOptions.of(o).apply([run, *others])
    by_rate = {} if o["decimation"] is None else {"decimation": o["decimation"], "band_hz": None}  # given: as given; else the rate's rule
    ls_settings = LSSettings(cutoff_hz=o["cutoff"], order=o["order"], trim=o["trim"], matlab=(o["filtering"] == "matlab"), **by_rate)
    ilic_settings = ILICSettings(
        window_s=o["window_s"], cutoff_hz=o["ilic_cutoff"], decimation=o["ilic_decimation"], sigma_max_pct=o["sigma_max"], ref_lag=o["ref_lag"]
    )
    with options_named():
        settings = IdentifySettings(method, spec, ls_settings, ilic_settings, closed_loop_settings(o), controller.pd_timing, oe_settings())
        result = identify_with(run, settings, validate=others)
    for w in result.warnings:
        note(f"ilic: warning: {w}")
    text = {"md": render.to_markdown, "csv": render.to_csv, "json": lambda r: render.to_json(r.to_dict())}[out.out_format](result)
    if out.out_dir is not None:
        _write_outputs(result, run, out.out_dir, out.plot_format, inputs=(log, *validate))
    click.echo(text, nl=False)


def _model_spec(o: Mapping[str, Any]) -> ModelSpec:
    """The model the options name: ``--structure`` or a model file's, with the model file's and ``--effect``'s effect columns."""
    structure, model_path = structure_or_model_file(o["model"], o["structure"])
    doc = load_model_file(model_path) if model_path is not None else None
    if structure is None:
        structure = str(doc["model"]) if doc is not None and doc.get("model") in STRUCTURES else "rigid-offset"
    mass = float(doc["parameters"].get("M", DEFAULTS["M"])) if doc is not None else DEFAULTS["M"]
    try:
        chosen, skipped = regressor_effects((doc or {}).get("effects", {}), mass)
    except ParameterError as exc:
        raise exc.at(model_path) from None
    if skipped:
        note(f"ilic: warning: {model_path}: not identified as regressor columns: {', '.join(skipped)}")
    try:
        for text in o["effects"]:
            eid, values = parse_effect_option(text)
            if get_effect(eid).shift and not values:  # a lag has no default a fit could start from: it is the log's, stated
                raise IlicError("--effect", f"'{text}': a drive lag is stated with its value, e.g. {eid}:{eid}=-0.00023 (s; negative: the force acts later)")
            chosen.update(regressor_effects({eid: values}, mass, keep_all=True)[0])
    except ParameterError as exc:
        raise exc.at("--effect") from None
    return ModelSpec(structure, chosen)


def _oe_settings(o: Mapping[str, Any]) -> Callable[[], OESettings]:
    """OE's options, checked now; the settings built where a domain error names its option (:func:`options_named`)."""
    method, oe_segment, oe_state, max_iterations = o["method"], o["oe_segment"], o["oe_state"], o["max_iterations"]
    if oe_segment is not None and method != "oe":
        raise IlicError("--oe-segment", "multiple shooting is --method oe's")
    if oe_state != "fitted" and (method != "oe" or oe_segment is not None):
        raise IlicError("--oe-state", "the initial state of --method oe's one shot (without --oe-segment)")
    return lambda: OESettings(
        segment_s=oe_segment, fit_state=oe_state == "fitted", max_iterations=OESettings.max_iterations if max_iterations is None else max_iterations
    )


def _write_outputs(result: IdentifyReport, run: RunLog, out_dir: Path, plot_format: str, inputs: tuple[Path, ...]) -> None:

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


@dataclass(frozen=True)
class OutputOptions:
    """``--format``, ``--out`` and ``--plots``."""

    out_format: str
    out_dir: Path | None
    plot_format: str

    @classmethod
    def of(cls, o: Mapping[str, Any]) -> OutputOptions:
        return cls(o["out_format"], o["out_dir"], o["plot_format"])

    def refuse_overwriting(self, log: Path, validate: tuple[Path, ...]) -> None:
        """Refuse an --out that is no folder, or where a report file would replace an input (before any work)."""
        if self.out_dir is not None and self.out_dir.exists() and not self.out_dir.is_dir():
            raise IlicError(self.out_dir, "--out must be a folder")
        if self.out_dir is not None:
            _refuse_overwriting_inputs(self.out_dir, self.plot_format, (log, *validate))


@dataclass(frozen=True)
class TransmissionOptions:
    """``--gear-ratio``, ``--torque-constant`` and ``--load-joint``: a motor-side log read on the load's side, or the joint's type."""

    gear_ratio: float | None
    torque_constant: float | None
    load_joint: str | None

    @classmethod
    def of(cls, o: Mapping[str, Any]) -> TransmissionOptions:
        return cls(o["gear_ratio"], o["torque_constant"], o["load_joint"])

    def apply(self, runs: list[RunLog]) -> list[RunLog]:
        """``runs`` on the load's side (:func:`ilic_cli.prepare.to_load_side`), or declared of the joint's type."""
        if self.torque_constant is not None and self.gear_ratio is None:
            raise IlicError("--torque-constant", "needs --gear-ratio (the transmission from the motor to the load)")
        if self.gear_ratio is not None:
            with options_named():
                return [to_load_side(x, self.gear_ratio, self.torque_constant, self.load_joint or "prismatic") for x in runs]
        return [declared_joint(x, self.load_joint) for x in runs]


def _refuse_overwriting_inputs(out_dir: Path, plot_format: str, inputs: tuple[Path, ...]) -> None:
    """Refuse an --out folder where a report file would replace an input (checked before any work)."""

    names = ["report.md", "report.csv", "report.json", "model.json"]
    if plot_format != "none":
        names += [f"{n}.{plot_format}" for n in ("parameters", "force", "tracking", "convergence")]
    for name in names:
        target = out_dir / name
        if target.exists() and any(same_path(src, target) for src in inputs):
            raise IlicError(target, "output would overwrite the input; choose another --out folder")
