"""``ilic diagnose``: parse, call :func:`ilic_cli.diagnosis.diagnose`, render."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ilic_cli.commands.common import STRUCTURES, ControllerOptions, controller_options, declared_joint, input_options, joint_option, load, note, with_controller
from ilic_cli.diagnosis import DiagnosisSettings, SelectSettings, diagnose
from ilic_cli.diagnosis.null import NULL_KINDS, NullSettings
from ilic_cli.diagnosis.plots import write_plots
from ilic_cli.diagnosis.report import to_json, to_markdown
from ilic_cli.diagnosis.settings import replay_alpha as replay_alpha_of
from ilic_cli.effects import catalogue_ids
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.io.atomic import atomic_write_text
from ilic_cli.modelfile import load_model_file


@click.command("diagnose")
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--model",
    "model_path",
    type=click.Path(path_type=Path),
    default=None,
    help="Model file (PARAMS.json) to start from instead of identifying the rigid model.",
)
@click.option(
    "--structure",
    "structure",
    type=click.Choice(STRUCTURES),
    default="rigid-offset",
    show_default=True,
    help="Rigid model structure identified first (without --model).",
)
@click.option(
    "--against",
    "against",
    type=click.Path(path_type=Path),
    default=None,
    help="A simulated log to compare the recording with (instead of replaying it through the plant).",
)
@click.option(
    "--validate",
    "validate",
    type=click.Path(path_type=Path),
    default=None,
    help="Another recording: an effect is kept only if it does not raise the error there.",
)
@click.option(
    "--alpha",
    type=click.FloatRange(min=0, max=1, min_open=True, max_open=True),
    default=0.001,
    show_default=True,
    help="Level of each F-test (after Bonferroni).",
)
@click.option("--folds", type=click.IntRange(min=2), default=5, show_default=True, help="Contiguous cross-validation blocks over time.")
@click.option("--effects", "effects", default=None, help="Comma-separated catalogue ids to try [default: all].")
@click.option(
    "--no-simulation", "no_simulation", is_flag=True, help="Skip the replay through the plant (the comparison, and its decision on the proposed effects)."
)
@click.option(
    "--replay-noise/--no-replay-noise",
    "replay_noise",
    default=True,
    show_default=True,
    help="The replays that decide carry the recording's own sensor noise (position noise and encoder step, estimated from its position).",
)
@click.option(
    "--null",
    "null",
    type=click.Choice(NULL_KINDS),
    default="dm",
    show_default=True,
    help="Test that decides the replay: dm (Diebold-Mariano, asymptotic) or montecarlo "
    "(the kept model simulated in closed loop with the log's own noise model, --replicates times; "
    "a candidate must pass both it and the Diebold-Mariano test).",
)
@click.option(
    "--replicates",
    type=click.IntRange(min=1),
    default=99,
    show_default=True,
    help="Replicates B of --null montecarlo; at least 1/alpha - 1 for --replay-alpha.",
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Seed of the Monte-Carlo replicates.")
@click.option(
    "--replay-alpha",
    "replay_alpha",
    type=click.FloatRange(min=0, max=1, min_open=True, max_open=True),
    default=None,
    help="Level of the replay's test, the decision [default: 0.05, as the inverse model's held-out test that proposes].",
)
@click.option("--format", "out_format", type=click.Choice(["md", "json"]), default="md", show_default=True, help="What to print on stdout.")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Folder for report.md, report.json, model.json and plots.")
@controller_options
@input_options
@joint_option(" Gravity is tried on a revolute joint only.")
def command(
    log: Path,
    model_path: Path | None,
    structure: str,
    against: Path | None,
    validate: Path | None,
    alpha: float,
    folds: int,
    effects: str | None,
    no_simulation: bool,
    replay_noise: bool,
    null: str,
    replicates: int,
    seed: int,
    replay_alpha: float | None,
    out_format: str,
    out_dir: Path | None,
    controller: str | None,
    kp: float | None,
    kv: float | None,
    drive_gain: float | None,
    pd_timing: str,
    input_format: str | None,
    topic: str | None,
    ref_topic: str | None,
    joint: str | None,
    columns: str | None,
    load_joint: str | None,
) -> None:
    """Find and model the physics the rigid model leaves out of LOG.

    Identifies the rigid model (IDIM-LS) with the logged command's sample
    hold, locates where the force residual is structured (velocity, position,
    time, frequency), and lets the inverse model propose effects of the
    catalogue one at a time (prewhitened F-test, Bonferroni; blocked
    cross-validation). The replay decides: a proposed effect is kept only if
    it is material and, replayed through the log's controller, lowers the
    held-out closed-loop force error significantly without raising the
    position error (nor, with --validate, the other log's error). The report
    says why each candidate was kept or rejected. "No significant mismatch"
    is a result; "undecided" says a proposal no replay could judge (its fit
    is no plant). With --format json stdout holds only the JSON document.

    \b
    Examples:
      ilic diagnose DATA_EMPS.mat
      ilic diagnose DATA_EMPS.mat --validate DATA_EMPS_PULSES.mat --out diag/
      ilic diagnose run.mcap --model model.json --format json
    """

    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise IlicError(out_dir, "--out must be a folder")
    catalogue = catalogue_ids()
    chosen = catalogue
    if effects is not None:
        chosen = tuple(e.strip() for e in effects.split(",") if e.strip())
        unknown = [e for e in chosen if e not in catalogue]
        if unknown or not chosen:
            raise IlicError("--effects", f"unknown effect {', '.join(unknown) or '(none given)'} (catalogue: {', '.join(catalogue)})")
    model_doc = load_model_file(model_path) if model_path is not None else None
    run = declared_joint(load(log, input_format, topic, ref_topic, joint, columns), load_joint)
    replayed = not no_simulation and against is None  # the replay needs the loop that ran
    if replayed or ControllerOptions(controller, kp, kv, drive_gain).given:  # given, it says how the force was sampled (as in identify)
        run = with_controller(run, log, controller, kp, kv, drive_gain)
    sim = declared_joint(load(against, None, topic, ref_topic, joint, columns), load_joint) if against is not None else None
    other = declared_joint(load(validate, None, topic, ref_topic, joint, columns), load_joint) if validate is not None else None
    settings = DiagnosisSettings(
        model=structure,
        select=SelectSettings(alpha=alpha, folds=folds, effects=chosen),
        simulate=not no_simulation,
        pd_timing=pd_timing,
        null=NullSettings(null, replicates, seed, replay_alpha),
        replay_noise=replay_noise,
    )
    try:
        settings.null.check(replay_alpha_of(settings))
    except ParameterError as exc:
        raise IlicError("--replicates", f"{exc.problem}; or a larger --replay-alpha (B = 19 suffices for 0.05)") from None
    result = diagnose(run, settings=settings, model_doc=model_doc, against=sim, validate=other)
    for w in result.warnings:
        note(f"ilic: warning: {w}")
    text = to_json(result) if out_format == "json" else to_markdown(result)
    if out_dir is not None:
        inputs = tuple(p for p in (log, model_path, against, validate) if p is not None)
        _write_outputs(result, out_dir, inputs)
    click.echo(text if text.endswith("\n") else text + "\n", nl=False)


def _write_outputs(result, out_dir: Path, inputs: tuple[Path, ...]) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "report.md", to_markdown(result), inputs=inputs)
    atomic_write_text(out_dir / "report.json", to_json(result), inputs=inputs)
    atomic_write_text(out_dir / "model.json", json.dumps(result.model_file, indent=2) + "\n", inputs=inputs)
    written = [out_dir / n for n in ("report.md", "report.json", "model.json")]
    written += write_plots(result, out_dir)
    note(f"ilic: wrote {', '.join(str(p) for p in written)}")
