"""``ilic replay LOG --urdf ARM.urdf --model model.json -o OUT``: an arm's log replayed with an identified model.

The log's reference runs through the log's recorded controller
(:func:`ilic_cli.robot.replay.replay_loop`; ``--controller pd|ctc`` for a log
that records none) with the plant of the model file's base parameters
(:func:`ilic_cli.modelfile.robot_parameters`: a model made for another URDF, by
its sha256, is refused). The simulated log goes to OUT (CSV, MCAP or bag
folder); stderr says each joint's torque error against the recording.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np

from ilic_cli.commands.common import note
from ilic_cli.commands.robot import joints_option, load_robot, read_log, recorded_controller, refuse_joint_type, urdf_option
from ilic_cli.errors import IlicError
from ilic_cli.io.atomic import same_path

F = TypeVar("F", bound=Callable[..., Any])

TRIM = 100
"""Samples left out at the start of the torque error (the loop's start from rest on the reference)."""


def replay_options(func: F) -> F:
    """Add ``--urdf`` and ``--joints`` to ``ilic replay``; with ``--urdf`` the arm's log is replayed instead."""

    @functools.wraps(func)
    def wrapper(log: Path, **options: Any) -> Any:
        urdf, joints = options.pop("urdf"), options.pop("robot_joints")
        if urdf is None:
            if joints is not None:
                raise IlicError("--joints", "needs --urdf (an arm of n joints)")
            return func(log, **options)
        refuse_joint_type(options)
        return replay(log, urdf, joints_option(joints), options)

    return urdf_option(cast(F, wrapper))


def model_beta(model_file: Path, robot: Any, base: Any) -> np.ndarray:
    """The model file's base parameters, if it was made for this URDF (one line naming the file otherwise)."""
    from ilic_cli.modelfile import load_model_file, robot_parameters  # deferred: with the model file

    return np.array(robot_parameters(load_model_file(model_file), robot.sha256, base.names, model_file), dtype=np.float64)


def torque_errors_pct(measured: np.ndarray, simulated: np.ndarray, trim: int = TRIM) -> np.ndarray:
    """Each joint's ``100 ||tau_sim - tau|| / ||tau||`` over the samples after ``trim`` (arrays (n, N))."""
    d = measured[:, trim:] - simulated[:, trim:]
    return 100.0 * np.linalg.norm(d, axis=1) / np.maximum(np.linalg.norm(measured[:, trim:], axis=1), 1e-300)


def replay(log_path: Path, urdf: Path, joints: list[str] | None, o: Mapping[str, Any]) -> None:
    """Replay the arm's log with the model file's plant, write the simulated log and say the torque errors."""
    output: Path | None = o["output"]
    if o.get("open_loop"):
        raise IlicError("--open-loop", "the benchmark's open-loop simulation is a 1-joint drive's; an arm's log is replayed in closed loop")
    if output is None:
        raise IlicError("--output", "required: the simulated log to write")
    if same_path(log_path, output) or output.exists():
        raise IlicError(output, "exists already: choose another output")
    if output.suffix.lower() not in (".csv", ".mcap") and output.suffix:
        raise IlicError(output, "an n-joint log is a .csv, an .mcap file or a ROS 2 bag folder (no extension)")
    robot = load_robot(urdf)
    from ilic_cli.robot.base import base_parameters  # deferred: numba only for an arm

    base = base_parameters(robot)
    beta = model_beta(o["model_file"], robot, base)
    log = read_log(log_path, robot, joints).contiguous(log_path)
    from ilic_cli.robot.idim import joint_glitch  # deferred: numba only for an arm

    if (why := joint_glitch(log.q.T, log.tau.T, log.t, robot.joints)) is not None:  # the fits' refusal (identify --urdf)
        raise IlicError(log_path, why)
    controller = recorded_controller(log, o, "a replay runs")
    from ilic_cli.io import jointlogs  # deferred: the writers only for an arm's log
    from ilic_cli.robot.dynamics import kept_vector  # deferred: numba only for an arm
    from ilic_cli.robot.replay import SampledReference, replay_loop  # deferred: with the loop

    assert log.q_ref is not None and log.qd_ref is not None and log.qdd_ref is not None
    pi = kept_vector(base.kept, beta, 14 * robot.n)
    reference = SampledReference(log.q_ref.T.copy(), log.qd_ref.T.copy(), log.qdd_ref.T.copy())
    try:
        run = replay_loop(robot, pi, reference, log.fs_hz, controller, robot.standard)
    except FloatingPointError:
        raise IlicError(o["model_file"], "the replay diverged: the model's inertia matrix is not positive definite along this log") from None
    except ValueError as exc:
        raise IlicError(log_path, str(exc)) from None
    meta = dict(log.meta) | {"model_file": str(o["model_file"]), "replay_of": str(log_path), "true_parameters": dict(zip(robot.names, pi.tolist()))}
    meta.pop("source", None)
    sim = replace(log, q=np.ascontiguousarray(run.q.T), tau=np.ascontiguousarray(run.tau.T), meta=meta)
    jointlogs.write(sim, output)
    errors = ", ".join(f"{j} {e:.4g} %" for j, e in zip(robot.joints, torque_errors_pct(log.tau, sim.tau)))
    note(f"ilic: replayed {log_path} with {o['model_file']}: wrote {output} ({len(log.t)} samples); torque error against the recording: {errors}")
