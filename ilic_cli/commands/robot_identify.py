"""``ilic identify LOG --urdf ARM.urdf``: the base parameters of an arm by n-joint IDIM-LS (weighted) and IDIM-ILIC per window.

JSON (``--format json``): the URDF and its hash, the base parameters with the
standard parameters each combines, and per method its parameters (value, std,
%σ), the friction and offsets named ``Fv_<joint>``, ``Fc_<joint>``,
``offset_<joint>``, and with ``--validate`` ``validation.relative_error_pct``.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar, cast

import click
import numpy as np

from ilic_cli.commands.robot import joints_option, load_robot, read_log, urdf_option
from ilic_cli.errors import IlicError
from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.idim_ls import LSSettings
from ilic_cli.jointlog import JointLog
from ilic_cli.lsq import finite_or_none

F = TypeVar("F", bound=Callable[..., Any])

FRICTION = ("Fv", "Fc", "offset")

ROBOT_LS: dict[str, Any] = {"cutoff": 50.0, "decimation": 20, "trim": 100}
"""IDIM-LS settings of an arm when the options are left at their 1-DOF defaults (docs/robots.md: the cut-off above the decimation's)."""

RUNNABLE = {"ls": ("ls",), "ilic": ("ilic",), "both": ("ls", "ilic"), "all": ("ls", "ilic")}
"""The ``--method`` choices that run on n joints, and what they run."""


def identify_options(func: F) -> F:
    """Add ``--urdf``, ``--joints`` and ``--min-speed`` to ``ilic identify``; with ``--urdf`` the n-joint identification runs instead."""

    @functools.wraps(func)
    def wrapper(log: Path, **options: Any) -> Any:
        urdf, joints, min_speed = options.pop("urdf"), options.pop("robot_joints"), options.pop("min_speed")
        if urdf is None:
            if joints is not None:
                raise IlicError("--joints", "needs --urdf (an arm of n joints; --joint NAME picks one joint of a 1-joint log)")
            return func(log, **options)
        return identify(log, urdf, joints_option(joints), min_speed, options, _defaults(options))

    wrapper = click.option(
        "--min-speed",
        "min_speed",
        type=click.FloatRange(min=0),
        default=0.2,
        show_default=True,
        help="n-joint IDIM-LS: leave out a joint's rows where it moves slower (rad/s or m/s: near rest it sticks).",
    )(wrapper)
    return urdf_option(cast(F, wrapper))


def _defaults(options: Mapping[str, Any]) -> set[str]:
    """The options left at their defaults (their source, from click's context)."""
    ctx = click.get_current_context()
    return {name for name in options if ctx.get_parameter_source(name) in (click.core.ParameterSource.DEFAULT, None)}


def _ls_settings(o: Mapping[str, Any], defaults: set[str]) -> LSSettings:
    """The IDIM-LS options, with :data:`ROBOT_LS` for those left at their 1-DOF defaults."""
    value = {k: (ROBOT_LS[k] if k in defaults and k in ROBOT_LS else o[k]) for k in ("cutoff", "decimation", "trim", "order")}
    return LSSettings(cutoff_hz=value["cutoff"], order=value["order"], decimation=value["decimation"], trim=value["trim"], matlab=o["filtering"] == "matlab")


def _ilic_settings(o: Mapping[str, Any], defaults: set[str], log: JointLog) -> ILICSettings:
    window = o["window_s"]
    if "window_s" in defaults and log.meta.get("window_s"):
        window = float(log.meta["window_s"])  # the window the log was simulated with
    return ILICSettings(window_s=window, cutoff_hz=o["ilic_cutoff"], decimation=o["ilic_decimation"], sigma_max_pct=o["sigma_max"])


def _methods(method: str) -> tuple[str, ...]:
    if method not in RUNNABLE:
        raise IlicError(
            "--method",
            f"{method} does not run on n joints from the command line (it needs the controller's model to simulate the loop): choose ls, ilic, both or all",
        )
    return RUNNABLE[method]


def _parameters(names: tuple[str, ...], theta: np.ndarray, std: np.ndarray, rel: np.ndarray) -> dict[str, dict[str, float | None]]:
    return {n: {"value": finite_or_none(v), "std": finite_or_none(s), "rel_std_pct": finite_or_none(r)} for n, v, s, r in zip(names, theta, std, rel)}


def _friction(parameters: Mapping[str, Any], joints: tuple[str, ...]) -> dict[str, Any]:
    return {f"{p}_{j}": parameters.get(f"{p}_{j}") for j in joints for p in FRICTION}


def identify(log_path: Path, urdf: Path, joints: list[str] | None, min_speed: float, o: Mapping[str, Any], defaults: set[str]) -> None:
    """Run the n-joint identification the options ask for and print its report."""
    methods = _methods(str(o["method"]))
    validate: tuple[Path, ...] = o["validate"]
    if len(validate) > 1:
        raise IlicError("--validate", "one validation log for an arm of n joints")
    robot = load_robot(urdf)
    log = read_log(log_path, robot, joints)
    other = read_log(validate[0], robot, joints) if validate else None
    from ilic_cli.robot.base import base_parameters  # deferred: scipy.linalg and numba only for an arm

    base = base_parameters(robot)
    ls = _ls_settings(o, defaults)
    held = bool(log.meta.get("torque_held", False))
    doc: dict[str, Any] = {
        "log": str(log_path),
        "urdf": robot.path,
        "sha256": robot.sha256,
        "joints": [{"name": j, "type": k} for j, k in zip(robot.joints, robot.kinds)],
        "samples": len(log.t),
        "sample_rate_hz": log.fs_hz,
        "base_parameters": [{"name": n, "combines": dict(base.combination(i))} for i, n in enumerate(base.names)],
        "unidentifiable": list(base.unidentifiable),
        "methods": {},
    }
    if "ls" in methods:
        doc["methods"]["IDIM-WLS"] = _ls(log, other, robot, base, ls, min_speed, held, validate)
    if "ilic" in methods:
        doc["methods"]["IDIM-ILIC"] = _ilic(log, robot, base, _ilic_settings(o, defaults, log), other, (ls, min_speed, held), validate)
    truth = log.provenance.true_parameters
    if truth:
        beta = base.values(robot.parameters(truth))
        doc["true_base_parameters"] = dict(zip(base.names, beta.tolist()))
        if other is not None:  # the yardstick of --validate: the true parameters' error on the same rows
            from ilic_cli.robot.idim import prepare, validation_error_pct  # deferred: numba only for an arm

            system = prepare(other.q.T, other.tau.T, other.fs_hz, robot, base, ls, min_speed=min_speed, torque_held=held)
            doc["true_validation_relative_error_pct"] = finite_or_none(validation_error_pct(beta, system))
    if o["out_format"] == "json":
        click.echo(json.dumps(doc, indent=2))
    else:
        from ilic_cli.commands.robot_report import identify_markdown  # deferred: the Markdown only when asked

        click.echo(identify_markdown(doc), nl=False)


def _ls(
    log: JointLog, other: JointLog | None, robot: Any, base: Any, ls: LSSettings, min_speed: float, held: bool, validate: tuple[Path, ...]
) -> dict[str, Any]:
    from ilic_cli.robot.idim import idim_ls, prepare, validation_error_pct  # deferred: numba only for an arm

    try:
        fit = idim_ls(log.q.T, log.tau.T, log.fs_hz, robot, base, ls, min_speed=min_speed, torque_held=held)
        system = prepare(other.q.T, other.tau.T, other.fs_hz, robot, base, ls, min_speed=min_speed, torque_held=held) if other is not None else None
    except ValueError as exc:
        raise IlicError(log.meta.get("source", "LOG"), str(exc)) from None
    out = fit.to_dict()
    out["friction"] = _friction(out["parameters"], robot.joints)
    if system is not None:
        out["validation"] = {"log": str(validate[0]), "relative_error_pct": finite_or_none(validation_error_pct(fit.theta, system))}
    return out


def _ilic(
    log: JointLog,
    robot: Any,
    base: Any,
    settings: ILICSettings,
    other: JointLog | None,
    validation: tuple[LSSettings, float, bool],
    validate: tuple[Path, ...],
) -> dict[str, Any]:
    """IDIM-ILIC per window of the log's reference (offline: the windows' estimates; the controller's start is the URDF's).

    ``validation``: the IDIM-LS settings, ``min_speed`` and ``torque_held`` of the
    validation log's system (the same rows as IDIM-WLS's validation).
    """
    from ilic_cli.robot.ilic import ilic_step  # deferred: numba only for an arm

    if not log.has_reference:
        raise IlicError(log.meta.get("source", "LOG"), "IDIM-ILIC needs the reference (q_ref, qd_ref, qdd_ref): the log has none; use --method ls")
    assert log.q_ref is not None and log.qd_ref is not None and log.qdd_ref is not None
    win = int(round(settings.window_s * log.fs_hz))
    if win < 2 or len(log.t) < win:
        raise IlicError("--window", f"{settings.window_s:g} s: the log lasts {log.duration_s:.4g} s, less than one window")
    beta = base.values(robot.standard)
    windows = []
    try:
        for k in range(len(log.t) // win):
            s = slice(k * win, (k + 1) * win)
            ref = (log.q_ref[:, s].T, log.qd_ref[:, s].T, log.qdd_ref[:, s].T)
            w = ilic_step(robot, base, settings, log.fs_hz, k + 1, log.t[s], ref, log.tau[:, s].T, beta)
            beta = w.beta
            windows.append(w)
    except ValueError as exc:
        raise IlicError(log.meta.get("source", "LOG"), str(exc)) from None
    last = windows[-1].result
    out: dict[str, Any] = {
        "method": "IDIM-ILIC",
        "window_s": settings.window_s,
        "parameters": _parameters(last.names, last.theta, last.std, last.rel_std_pct),
        "windows": [w.to_dict() for w in windows],
    }
    out["friction"] = _friction(out["parameters"], robot.joints)
    if other is not None:
        from ilic_cli.robot.idim import prepare, validation_error_pct  # deferred: numba only for an arm

        ls, min_speed, held = validation
        system = prepare(other.q.T, other.tau.T, other.fs_hz, robot, base, ls, min_speed=min_speed, torque_held=held)
        out["validation"] = {"log": str(validate[0]), "relative_error_pct": finite_or_none(validation_error_pct(last.theta, system))}
    return out
