"""``ilic simulate --urdf ARM.urdf --scenario robot-sim -o OUT``: the arm in CTC with online IDIM-ILIC, its n-joint log and Table I.

The scenario is :func:`ilic_cli.robot.scenario.robot_sim`; the log
(:class:`ilic_cli.jointlog.JointLog`) goes to a wide CSV, an MCAP file or a
ROS 2 bag folder (:func:`ilic_cli.io.jointlogs.write`), with the true standard
parameters, the window and the controller in its metadata, so that
``ilic identify OUT --urdf ARM.urdf`` can be checked against them. stdout: the
per-window convergence table of every base parameter.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

import click
import numpy as np

from ilic_cli.commands.robot import load_robot
from ilic_cli.commands.robot_report import convergence_markdown
from ilic_cli.errors import IlicError
from ilic_cli.io import jointlogs
from ilic_cli.jointlog import JointLog

F = TypeVar("F", bound=Callable[..., Any])

SCENARIO = "robot-sim"
WINDOW_S = 10.0
WINDOWS = 5


def simulate_options(func: F) -> F:
    """Add ``--urdf`` to ``ilic simulate``; with it the ``robot-sim`` scenario of that arm runs instead."""

    @functools.wraps(func)
    def wrapper(**options: Any) -> Any:
        urdf = options.pop("urdf")
        if urdf is None:
            if options["scenario"] == SCENARIO:
                raise IlicError("--scenario", f"{SCENARIO} needs --urdf ARM.urdf (an arm of n joints)")
            return func(**options)
        return simulate(urdf, options)

    return cast(
        F,
        click.option(
            "--urdf", "urdf", type=click.Path(path_type=Path), default=None, help=f"An arm of n joints: its URDF (with --scenario {SCENARIO}; docs/robots.md)."
        )(wrapper),
    )


def _settings(robot: Any, o: dict[str, Any]) -> Any:
    from ilic_cli.idim_ilic import ILICSettings  # deferred: the robot chain only for an arm
    from ilic_cli.robot.plant import LoopSettings  # deferred: numba only for an arm
    from ilic_cli.robot.scenario import RobotSimSettings  # deferred: with the plant

    window = WINDOW_S if o["window_s"] is None else float(o["window_s"])
    if window <= 0:
        raise IlicError("--window", "must be > 0 s")
    windows = WINDOWS if o["duration"] is None else int(round(o["duration"] / window))
    if windows < 1:
        raise IlicError("--duration", f"shorter than one window ({window:g} s)")
    if o["controller"] not in (None, "ctc"):
        raise IlicError("--controller", f"{SCENARIO} runs the CTC with online IDIM-ILIC (paper eqs. 11-16)")
    noise = () if o["noise_tau"] is None else (float(o["noise_tau"]),) * robot.n
    loop = LoopSettings(velocity=o["velocity"] or "exact", torque_noise=noise, seed=int(o["seed"]))
    ilic = ILICSettings(window_s=window, sigma_max_pct=15.0 if o["sigma_max"] is None else float(o["sigma_max"]))
    return RobotSimSettings(windows=windows, window_s=window, loop=loop, ilic=ilic)


def _model_truth(model_file: Path, robot: Any) -> np.ndarray:
    """The arm's standard parameters from an arm's model file made for this URDF (``--model``)."""
    from ilic_cli.commands.robot_replay import model_beta  # deferred: with the model file
    from ilic_cli.robot.base import base_parameters  # deferred: numba only for an arm
    from ilic_cli.robot.dynamics import kept_vector  # deferred: numba only for an arm

    base = base_parameters(robot)
    return kept_vector(base.kept, model_beta(model_file, robot, base), 14 * robot.n)


def simulate(urdf: Path, o: dict[str, Any]) -> None:
    """Run robot-sim on the URDF's arm, write its log and print the convergence table."""
    ctx = click.get_current_context()
    if ctx.get_parameter_source("scenario") == click.core.ParameterSource.DEFAULT or o["scenario"] != SCENARIO:
        raise IlicError("--scenario", f"an arm of n joints (--urdf) runs --scenario {SCENARIO}")
    output: Path = o["output"]
    if output.exists():
        raise IlicError(output, "exists already: choose another output")
    if output.suffix.lower() not in (".csv", ".mcap") and output.suffix:
        raise IlicError(output, "an n-joint log is a .csv, an .mcap file or a ROS 2 bag folder (no extension)")
    robot = load_robot(urdf)
    settings = _settings(robot, o)
    from ilic_cli.robot.replay import controller_meta  # deferred: numba only for an arm
    from ilic_cli.robot.scenario import robot_sim, true_parameters  # deferred: numba only for an arm

    pi = true_parameters(robot) if o.get("model") is None else _model_truth(Path(o["model"]), robot)
    result = robot_sim(robot, settings, truth=pi, true_state=False)  # the log holds the measured position, not the true one
    run = result.run
    meta = {
        "scenario": {"name": SCENARIO, "windows": settings.windows, "window_s": settings.window_s, "seed": settings.seed},
        "window_s": settings.window_s,
        "torque_held": True,
        "controller": controller_meta(settings.loop, run.models, settings.window_s),  # the loop that ran, for DIDIM, IDIM-IV and replay
        "true_parameters": dict(zip(robot.names, pi.tolist())),
        "urdf": robot.path,
        "urdf_sha256": robot.sha256,
    }
    log = JointLog(
        t=run.t,
        joints=robot.joints,
        kinds=robot.kinds,
        # views (joint, sample) of the run's (sample, joint) arrays: the writers read them by blocks of samples, unchanged
        q=run.q.T,
        tau=run.tau.T,
        q_ref=run.q_ref.T,
        qd_ref=run.qd_ref.T,
        qdd_ref=run.qdd_ref.T,
        meta=meta,
    )
    jointlogs.write(log, output)
    base = result.base
    errors = result.relative_errors_pct()
    click.echo(f"# {SCENARIO}: {Path(robot.path).name}, {settings.windows} windows of {settings.window_s:g} s -> {output}\n")
    estimates, essential = [w.result.theta.tolist() for w in result.windows], [w.essential.tolist() for w in result.windows]
    table = convergence_markdown(base.names, result.truth[-1].tolist(), estimates, errors.tolist(), essential, settings.ilic.sigma_max_pct)
    click.echo(table, nl=False)
