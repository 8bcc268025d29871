"""``ilic replay``: run a log's recorded reference through the plant with a model's parameters."""

from __future__ import annotations

from pathlib import Path

import click

from ilic_cli.commands.common import (
    LOG_FORMATS,
    controller_options,
    declared_joint,
    input_options,
    joint_option,
    load,
    note,
    plant_of_model_file,
    with_controller,
)
from ilic_cli.commands.robot_replay import replay_options
from ilic_cli.errors import IlicError
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io import write_log
from ilic_cli.io.atomic import same_path
from ilic_cli.prepare import prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import relative_errors
from ilic_cli.usable import refuse_glitches
from plant.replay import simulate_open_loop, simulate_replay


@click.command("replay")
@click.argument("log", type=click.Path(path_type=Path))
@click.option(
    "--model",
    "model_file",
    type=click.Path(path_type=Path),
    required=True,
    help='Model parameter file (ilic identify --out DIR/model.json, or {"M": ..., ...}).',
)
@click.option("-o", "--output", "output", type=click.Path(path_type=Path), default=None, help="Simulated log to write (required but with --open-loop).")
@click.option("--format", "out_format", type=click.Choice(LOG_FORMATS), default=None, help="Output format [default: from the extension].")
@click.option("--substeps", type=int, default=10, show_default=True, help="Integration steps per control period.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the noise effects, if any.")
@click.option(
    "--open-loop",
    "open_loop",
    is_flag=True,
    help="The benchmark's simulation instead (its official protocol): the recorded drive command (vir) into the plant without feedback, "
    "the state from the first 20 samples; prints the RMSE of the position after them (mm) and the fit (%).",
)
@controller_options
@input_options
@joint_option()
@replay_options
def command(
    log: Path,
    model_file: Path,
    output: Path | None,
    out_format: str | None,
    substeps: int,
    seed: int,
    open_loop: bool,
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
    """Replay LOG's reference (and pulses) through the plant under LOG's controller.

    The controller is the log's: the PD loop with its kp, kv and drive gain
    when the metadata says "pd" (the EMPS recordings), otherwise CTC with the
    logged gains and controller parameters. The plant uses the model file's
    parameters (M, Fv, Fc, offset or Fv_pos/Fc_pos/Fv_neg/Fc_neg) and effects.

    With --urdf ARM.urdf, LOG is an arm's and the model file an arm's
    (ilic identify LOG --urdf ARM.urdf --out DIR writes DIR/model.json; it
    must have been made for that URDF): docs/robots.md.

    \b
    Examples:
      ilic replay DATA_EMPS.mat --model report/model.json -o replay.mcap
      ilic replay arm2.csv --urdf fixtures/arm2.urdf --model out/model.json -o replayed.csv
    """

    if substeps < 1:
        raise IlicError("--substeps", f"must be >= 1 (got {substeps})")
    if output is None and not open_loop:
        raise IlicError("--output", "required: the simulated log to write (only --open-loop may go without)")
    if output is not None and same_path(log, output):  # refuse before any work (and before any warning)
        raise IlicError(output, "output would overwrite the input; choose another output path")
    params, effects = plant_of_model_file(model_file)
    if open_loop:
        prepared = prepare_log(declared_joint(load(log, input_format, topic, ref_topic, joint, columns), load_joint))
        prepared.require_contiguous("an open-loop simulation")
        refuse_glitches(prepared)
        run = prepared.log  # an irregularly sampled log is on a uniform grid now
        sim, figure = simulate_open_loop(run, params, effects, substeps=substeps)
        sim.meta["model_file"] = str(model_file)
        if output is not None:
            write_log(sim, output, out_format, inputs=(log,))
        wrote = f"; wrote {output}" if output is not None else ""
        note(f"ilic: open loop (vir in, q out, after {figure.init_samples} samples): RMSE {figure.rmse_mm:.4g} mm, fit {figure.fit_pct:.4g} %{wrote}")
        return
    assert output is not None
    run = with_controller(declared_joint(load(log, input_format, topic, ref_topic, joint, columns), load_joint), log, controller, kp, kv, drive_gain)
    prepared = prepare_log(run)
    prepared.require_contiguous("a replay")
    refuse_glitches(prepared)
    run = prepared.log  # an irregularly sampled log is on a uniform grid now
    for w in prepared.warnings:
        note(f"ilic: warning: {w}")
    kept: RunLog | None = None  # the replay of the loop kept, when the loop was chosen by replays
    if pd_timing == "recorded":  # the loop that ran: a PD log's timing read from the recording with this model
        from ilic_cli.simulation.pd_law import inside_is_closer, law_may_act_inside  # deferred: with the replay (the IDIM filter)
        from ilic_cli.simulation.timing import recorded_loop, with_pd_law  # deferred: with the replay

        run, timing = recorded_loop(run, params, effects, LSSettings())
        if timing is not None and timing.sentence():
            note(f"ilic: loop timing: {timing.sentence()} (--pd-timing documented: the loop as its metadata states it)")
        if timing is not None and law_may_act_inside(timing.law):  # the law on the plant's velocity: held, or inside the dynamics?
            inside = with_pd_law(run, continuous=True)
            held_sim, inside_sim = (simulate_replay(r, params, effects, substeps=substeps, seed=seed) for r in (run, inside))
            held_e, inside_e = (relative_errors(r, sm, LSSettings()) for r, sm in ((run, held_sim), (inside, inside_sim)))
            kept = held_sim
            if inside_is_closer(held_e, inside_e):
                run, kept = inside, inside_sim
                note(
                    f"ilic: loop: the law inside the dynamics, on the plant's state at every integration step, replays the recording "
                    f"clearly closer than the law held over the period (force error {held_e['force']:.3g} % -> {inside_e['force']:.3g} %)"
                )
    sim = kept if kept is not None else simulate_replay(run, params, effects, substeps=substeps, seed=seed)
    sim.meta["model_file"] = str(model_file)
    write_log(sim, output, out_format, inputs=(log,))
    note(f"ilic: replayed {log} with {model_file}: wrote {output} ({len(sim)} samples)")
    if "q" in run and "tau" in run:
        errors = relative_errors(run, sim, LSSettings())
        note(
            f"ilic: closed loop against the recording (first {LSSettings().trim} samples dropped): force error {errors['force']:.4g} %, "
            f"position error {errors['position']:.4g} %, velocity error {errors['velocity']:.4g} %"
        )
