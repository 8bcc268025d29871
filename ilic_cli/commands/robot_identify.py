"""``ilic identify LOG --urdf ARM.urdf``: the base parameters of an arm by n-joint IDIM-LS (weighted), IDIM-ILIC per window, IDIM-IV and DIDIM.

JSON (``--format json``): the URDF and its hash, the base parameters with the
standard parameters each combines, and per method its parameters (value, std,
%σ), the friction and offsets named ``Fv_<joint>``, ``Fc_<joint>``,
``offset_<joint>``, and with ``--validate`` ``validation.relative_error_pct``.

IDIM-IV and DIDIM (:mod:`ilic_cli.robot.closed_loop`) iterate on replays of
the log's reference through the log's controller (``meta["controller"]``,
:mod:`ilic_cli.robot.replay`; ``--controller pd|ctc`` for a log that records
none, the controller's model then being the URDF's). ``--out DIR`` writes the
report, the model file and a torque plot per joint (:mod:`ilic_cli.commands.robot_files`).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar, cast

import click
import numpy as np

from ilic_cli.commands.common import closed_loop_settings
from ilic_cli.commands.robot import joints_option, load_robot, read_log, recorded_controller, refuse_joint_type, urdf_option
from ilic_cli.errors import IlicError
from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.idim_ls import LSSettings
from ilic_cli.jointlog import JointLog, Parts
from ilic_cli.lsq import finite_or_none
from ilic_cli.method_names import COMPOSITES

F = TypeVar("F", bound=Callable[..., Any])

FRICTION = ("Fv", "Fc", "offset")

ROBOT_LS: dict[str, Any] = {"cutoff": 50.0, "trim": 100}
"""IDIM-LS settings of an arm when the options are left at their 1-DOF defaults (docs/robots.md: the cut-off above the decimation's band).

The decimation is the 1-DOF chain's rule by the log's rate (:func:`ilic_cli.filtering.rows_decimation`) with an arm's band
(:data:`ilic_cli.robot.idim.ROBOT_BAND_HZ`: 20 at 1 kHz), or ``--decimation N`` as given."""

RUNNABLE = ("ls", "ilic", "iv", "didim")
"""The methods that run on n joints (a composite ``--method`` runs its :data:`ilic_cli.method_names.COMPOSITES` entry's)."""


PARTS_RULE = (
    "IDIM-LS filtered and decimated each contiguous part between the log's gaps on its own and stacked their rows, each part leaving "
    "out its edges at a gap (four decimation spans, never fewer samples than its start's trim), a part too short for the filters left out"
)
"""What ``identify --urdf --method ls`` says it did with a log that has gaps (the one-joint chain's rule)."""


def identify_options(func: F) -> F:
    """Add ``--urdf``, ``--joints`` and ``--min-speed`` to ``ilic identify``; with ``--urdf`` the n-joint identification runs instead."""

    @functools.wraps(func)
    def wrapper(log: Path, **options: Any) -> Any:
        urdf, joints, min_speed = options.pop("urdf"), options.pop("robot_joints"), options.pop("min_speed")
        if urdf is None:
            if joints is not None:
                raise IlicError("--joints", "needs --urdf (an arm of n joints; --joint NAME picks one joint of a 1-joint log)")
            return func(log, **options)
        refuse_joint_type(options)
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


def _ls_settings(o: Mapping[str, Any], defaults: set[str], fs_hz: float) -> LSSettings:
    """The IDIM-LS options, with :data:`ROBOT_LS` for those left at their 1-DOF defaults."""
    value = {k: (ROBOT_LS[k] if k in defaults and k in ROBOT_LS else o[k]) for k in ("cutoff", "trim", "order")}
    from ilic_cli.robot.idim import ROBOT_BAND_HZ  # deferred: numba only for an arm

    by_rate = {"band_hz": ROBOT_BAND_HZ} if o["decimation"] is None else {"decimation": o["decimation"], "band_hz": None}  # given: as given; else the rule
    settings = LSSettings(cutoff_hz=value["cutoff"], order=value["order"], trim=value["trim"], matlab=o["filtering"] == "matlab", **by_rate)
    return settings.at_rate(fs_hz)


def _ilic_settings(o: Mapping[str, Any], defaults: set[str], log: JointLog) -> ILICSettings:
    window = o["window_s"]
    if "window_s" in defaults and log.meta.get("window_s"):
        window = float(log.meta["window_s"])  # the window the log was simulated with
    return ILICSettings(window_s=window, cutoff_hz=o["ilic_cutoff"], decimation=o["ilic_decimation"], sigma_max_pct=o["sigma_max"])


def _methods(method: str) -> tuple[str, ...]:
    methods = COMPOSITES[method].methods if method in COMPOSITES else (method,)
    if not set(methods) <= set(RUNNABLE):
        raise IlicError("--method", f"{method} does not run on n joints from the command line: choose ls, ilic, both, iv, didim or all")
    return methods


def _parameters(names: tuple[str, ...], theta: np.ndarray, std: np.ndarray, rel: np.ndarray) -> dict[str, dict[str, float | None]]:
    return {n: {"value": finite_or_none(v), "std": finite_or_none(s), "rel_std_pct": finite_or_none(r)} for n, v, s, r in zip(names, theta, std, rel)}


def _friction(parameters: Mapping[str, Any], joints: tuple[str, ...]) -> dict[str, Any]:
    return {f"{p}_{j}": parameters.get(f"{p}_{j}") for j in joints for p in FRICTION}


def identify(log_path: Path, urdf: Path, joints: list[str] | None, min_speed: float, o: Mapping[str, Any], defaults: set[str]) -> None:
    """Run the n-joint identification the options ask for and print its report (and write it under ``--out``)."""
    methods = _methods(str(o["method"]))
    validate: tuple[Path, ...] = o["validate"]
    if len(validate) > 1:
        raise IlicError("--validate", "one validation log for an arm of n joints")
    out_dir: Path | None = o.get("out_dir")
    if out_dir is not None:
        from ilic_cli.commands.robot_files import refuse_out  # deferred: the report files only with --out

        refuse_out(out_dir, (log_path, urdf, *validate), o.get("plot_format", "png"))
    robot = load_robot(urdf)
    log = read_log(log_path, robot, joints)
    # IDIM-LS takes the parts between gaps, as the one-joint chain; the replays and IDIM-ILIC's windows need one run
    parts = log.parts(log_path) if methods == ("ls",) else ((0, len(log.t)),)
    if len(parts) == 1:
        log = log.contiguous(log_path)
    other = read_log(validate[0], robot, joints) if validate else None
    other_parts = other.parts(validate[0]) if other is not None else ()
    controller = recorded_controller(log, o, "IDIM-IV and DIDIM replay") if {"iv", "didim"} & set(methods) else None
    from ilic_cli.robot.base import base_parameters  # deferred: scipy.linalg and numba only for an arm

    base = base_parameters(robot)
    ls = _ls_settings(o, defaults, log.fs_hz)
    held = bool(log.meta.get("torque_held", False))
    check = _Validation(robot, base, ls, min_speed, held, (other, other_parts), validate)
    doc: dict[str, Any] = {
        "log": str(log_path),
        "urdf": robot.path,
        "sha256": robot.sha256,
        "joints": [{"name": j, "type": k} for j, k in zip(robot.joints, robot.kinds)],
        "samples": len(log.t),
        "sample_rate_hz": log.fs_hz,
        **({"parts": {"count": len(parts), "rule": PARTS_RULE}} if len(parts) > 1 else {}),
        "base_parameters": [{"name": n, "combines": dict(base.combination(i))} for i, n in enumerate(base.names)],
        "unidentifiable": list(base.unidentifiable),
        "methods": {},
    }
    if "ls" in methods:
        doc["methods"]["IDIM-WLS"] = _ls(log, parts, robot, base, ls, min_speed, held, float(o["sigma_max"]))
    if "ilic" in methods:
        doc["methods"]["IDIM-ILIC"] = _ilic(log, robot, base, _ilic_settings(o, defaults, log))
    for m in ("iv", "didim"):
        if m in methods:
            assert controller is not None
            entry = _closed(m, log, robot, base, (ls, min_speed, held), controller, closed_loop_settings(o), float(o["sigma_max"]))
            doc["methods"][entry["method"]] = entry
    for entry in doc["methods"].values():
        entry["friction"] = _friction(entry["parameters"], robot.joints)
        entry |= check(np.array([np.nan if p["value"] is None else p["value"] for p in entry["parameters"].values()], dtype=np.float64))
    truth = log.provenance.true_parameters
    if truth:
        beta = base.values(robot.parameters(truth))
        doc["true_base_parameters"] = dict(zip(base.names, beta.tolist()))
        if other is not None:  # the yardstick of --validate: the true parameters' error on the same rows
            doc["true_validation_relative_error_pct"] = check(beta)["validation"]["relative_error_pct"]
    if out_dir is not None:
        from ilic_cli.commands.robot_files import write_identify  # deferred: the report files only with --out

        write_identify(doc, log, parts, robot, base, out_dir, (ls, str(o["method"]), o.get("plot_format", "png")), (log_path, urdf, *validate))
    if o["out_format"] == "json":
        click.echo(json.dumps(doc, indent=2))
    else:
        from ilic_cli.commands.robot_report import identify_markdown  # deferred: the Markdown only when asked

        click.echo(identify_markdown(doc), nl=False)


class _Validation:
    """``--validate``'s relative error of base parameters on the other log (IDIM-WLS's rows: its settings, ``min_speed`` and ``torque_held``)."""

    def __init__(self, robot: Any, base: Any, ls: LSSettings, min_speed: float, held: bool, other: tuple[JointLog | None, Parts], validate: tuple[Path, ...]):
        self.system, self.where = None, validate[0] if validate else None
        log, parts = other
        if log is not None:
            from ilic_cli.robot.idim import prepare_parts  # deferred: numba only for an arm

            try:
                self.system = prepare_parts(log.q.T, log.tau.T, log.fs_hz, robot, base, parts, ls, min_speed=min_speed, torque_held=held, t=log.t)
            except ValueError as exc:
                raise IlicError(self.where, str(exc)) from None

    def __call__(self, theta: np.ndarray) -> dict[str, Any]:
        if self.system is None:
            return {}
        from ilic_cli.robot.idim import validation_error_pct  # deferred: numba only for an arm

        return {"validation": {"log": str(self.where), "relative_error_pct": finite_or_none(validation_error_pct(theta, self.system))}}


def _ls(log: JointLog, parts: Parts, robot: Any, base: Any, ls: LSSettings, min_speed: float, held: bool, sigma_max: float) -> dict[str, Any]:
    """IDIM-WLS on the log's ``parts`` between gaps, with its essential parameters and the fit of those alone (:func:`ilic_cli.robot.idim.essential_fit`)."""
    from ilic_cli.plausible import driving_friction  # deferred: the effects' vocabulary it reads Z95 from, only for an arm's IDIM-WLS
    from ilic_cli.robot.idim import essential_fit, prepare_parts, solve_system  # deferred: numba only for an arm

    try:
        system = prepare_parts(log.q.T, log.tau.T, log.fs_hz, robot, base, parts, ls, min_speed=min_speed, torque_held=held, t=log.t)
        fit = solve_system(system)
        if (why := driving_friction(fit.names, fit.theta, fit.std, robot.joints)) is not None:
            raise ValueError(why)
        mask, reduced = essential_fit(system, fit, sigma_max)
    except ValueError as exc:
        raise IlicError(log.meta.get("source", "LOG"), str(exc)) from None
    out = fit.to_dict() | _essential(base.names, mask, sigma_max)
    out["essential_fit"] = {"relative_error_pct": finite_or_none(reduced.relative_error_pct), "all_relative_error_pct": finite_or_none(fit.relative_error_pct)}
    return out


def _essential(names: tuple[str, ...], mask: np.ndarray, sigma_max: float) -> dict[str, Any]:
    """The report's essential parameters: ``%sigma <= sigma_max`` (:func:`ilic_cli.idim_ilic.essential_mask`)."""
    return {"sigma_max_pct": sigma_max, "essential": [n for n, e in zip(names, mask, strict=True) if e]}


def _ilic(log: JointLog, robot: Any, base: Any, settings: ILICSettings) -> dict[str, Any]:
    """IDIM-ILIC per window of the log's reference (offline: the windows' estimates; the controller's start is the URDF's)."""
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
    return {
        "method": "IDIM-ILIC",
        "window_s": settings.window_s,
        "parameters": _parameters(last.names, last.theta, last.std, last.rel_std_pct),
        "windows": [w.to_dict() for w in windows],
    } | _essential(base.names, windows[-1].essential, settings.sigma_max_pct)


def _closed(
    method: str,
    log: JointLog,
    robot: Any,
    base: Any,
    prep: tuple[LSSettings, float, bool],
    controller: Mapping[str, Any],
    settings: Mapping[str, Any],
    sigma_max: float,
) -> dict[str, Any]:
    """IDIM-IV or DIDIM of the base parameters on replays of the log's loop (:func:`ilic_cli.robot.closed_loop.closed_loop_identify`)."""
    from ilic_cli.robot.closed_loop import closed_loop_identify  # deferred: numba only for an arm
    from ilic_cli.robot.replay import SampledReference, base_simulator  # deferred: with the loop

    assert log.q_ref is not None and log.qd_ref is not None and log.qdd_ref is not None
    where = log.meta.get("source", "LOG")
    reference = SampledReference(log.q_ref.T.copy(), log.qd_ref.T.copy(), log.qdd_ref.T.copy())
    ls, min_speed, held = prep
    try:
        simulate = base_simulator(robot, base.kept, reference, log.fs_hz, controller, robot.standard)
        res = closed_loop_identify(method, log.q.T, log.tau.T, log.fs_hz, robot, base, simulate, ls, settings[method], min_speed=min_speed, torque_held=held)
    except FloatingPointError:
        raise IlicError(
            where, f"{method}: the loop's replay diverged with an estimate (its inertia matrix is not positive definite); try --method ls"
        ) from None
    except ValueError as exc:
        raise IlicError(where, f"{method}: {exc}") from None
    from ilic_cli.idim_ilic import essential_mask  # deferred: with the estimate

    return res.to_dict() | _essential(base.names, essential_mask(res.result, sigma_max), sigma_max)
