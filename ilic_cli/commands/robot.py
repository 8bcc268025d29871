"""Arms of n joints on the command line: ``--urdf`` and ``--joints`` of ``ilic identify``, ``ilic info`` and ``ilic convert`` (issue 30).

The 1-joint commands hand over to this module when ``--urdf`` (or ``--joints``,
or a wide CSV) is given: :func:`identify_options`, :func:`info_options` and
:func:`convert_options` wrap their command (``ilic convert`` also for a log that
declares its joints: :func:`ilic_cli.io.jointlogs.declares_joints`). The log is an :class:`ilic_cli.jointlog.JointLog` read by
joint name (:mod:`ilic_cli.io.jointlogs`); the numerics are :mod:`ilic_cli.robot`'s.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

import click

from ilic_cli.errors import IlicError, LogError

if TYPE_CHECKING:
    from ilic_cli.jointlog import JointLog

F = TypeVar("F", bound=Callable[..., Any])


JOINTS_HELP = "n-joint log: the joints to read, by name; with --urdf, the log's names of the URDF's joints in its order [default: the URDF's names]."


def joints_option(text: str | None) -> list[str] | None:
    """The names of ``--joints a,b,c`` (None when not given)."""
    if text is None:
        return None
    names = [j.strip() for j in text.split(",") if j.strip()]
    if not names:
        raise IlicError("--joints", "give joint names separated by commas (a,b,c)")
    return names


def urdf_option(func: F) -> F:
    """Add ``--urdf`` and ``--joints`` (the latter reaches the command as ``robot_joints``)."""
    func = click.option("--joints", "robot_joints", default=None, metavar="A,B,...", help=JOINTS_HELP)(func)
    return click.option(
        "--urdf", "urdf", type=click.Path(path_type=Path), default=None, help="An arm of n joints: its URDF (the log is read by joint name; docs/robots.md)."
    )(func)


def load_robot(urdf: Path) -> Any:
    """The URDF's model (pinocchio; a missing file or package is one line)."""
    from ilic_cli.robot.model import load_urdf  # deferred: the robot layer (numba, pinocchio) only for an arm

    if not urdf.exists():
        raise IlicError(urdf, "no such URDF file")
    return load_urdf(urdf)


def read_log(path: Path, robot: Any, joints: list[str] | None, kind: str | None = None) -> JointLog:
    """The log's joints, their types checked against the URDF's.

    ``joints``: without a URDF, the joints to read; with one, the log's names of
    the URDF's moving joints in the URDF's order (default: the URDF's own names).
    ``kind``: the log's format (default: from the path).
    """
    from ilic_cli.io import jointlogs  # deferred: numpy and the readers only for an n-joint log (`ilic info --help` imports this module)

    if robot is None:
        return jointlogs.read(path, joints, kind=kind)
    if joints is not None and len(joints) != robot.n:
        raise IlicError("--joints", f"{len(joints)} names for the {robot.n} joints {robot.path} moves ({', '.join(robot.joints)})")
    names = joints or list(robot.joints)
    log = jointlogs.read(path, names, dict(zip(names, robot.kinds)), kind)
    log = replace(log, joints=tuple(robot.joints))
    wrong = [f"{j} ({k}, the URDF: {u})" for j, k, u in zip(names, log.kinds, robot.kinds) if k != u]
    if wrong:
        raise LogError(path, f"joint types differ from the URDF's: {', '.join(wrong)}")
    return log


def recorded_controller(log: JointLog, o: Mapping[str, Any], purpose: str) -> dict[str, Any]:
    """The loop to replay (``purpose``: who replays it): the log's recorded controller, or ``--controller`` for a log that records none."""
    where = log.meta.get("source", "LOG")
    given = o.get("controller")
    if any(o.get(k) is not None for k in ("kp", "kv", "drive_gain")):
        raise IlicError("--kp", "--kp, --kv and --drive-gain are a 1-joint PD's; an arm's PD gains follow from its model (docs/robots.md)")
    recorded = log.meta.get("controller")
    if recorded and given is not None:
        raise IlicError("--controller", f"{where} records its controller; the option applies only to a log that records none")
    if not log.has_reference:
        raise IlicError(where, f"{purpose} the log's reference (q_ref, qd_ref, qdd_ref): the log has none")
    if not recorded and given is None:
        raise IlicError(where, "the log records no controller: give the loop that ran with --controller pd or --controller ctc (its model: the URDF's)")
    return dict(recorded) if isinstance(recorded, Mapping) else {"kind": given or str(recorded)}


def info_options(func: F) -> F:
    """Add ``--urdf`` and ``--joints`` to ``ilic info``; with either, or for a wide CSV or an arm's ``.mat``, the joints are listed."""

    @functools.wraps(func)
    def wrapper(log_path: Path, **options: Any) -> Any:
        urdf, joints = options.pop("urdf"), options.pop("robot_joints")
        from ilic_cli.io.jointlogs import is_wide_csv  # deferred: numpy and the readers only when a log is read (`ilic info --help`)
        from ilic_cli.io.jointmat import is_joint_mat  # deferred: with the CSV's

        if urdf is None and joints is None and not is_wide_csv(log_path) and not is_joint_mat(log_path):
            return func(log_path, **options)
        summary = joints_summary(log_path, urdf, joints)
        if options["out_format"] == "json":
            click.echo(json.dumps(summary, indent=2, default=str))
        else:
            click.echo(info_markdown(summary), nl=False)
        return None

    return urdf_option(cast(F, wrapper))


def convert_options(func: F) -> F:
    """Add ``--urdf`` and ``--joints`` to ``ilic convert``; with either, or for a log that declares its joints, the arm's log is converted whole.

    ``--joint NAME`` alone keeps the one-joint conversion (one joint of an arm's log).
    """

    @functools.wraps(func)
    def wrapper(source: Path, target: Path, **options: Any) -> Any:
        urdf, joints = options.pop("urdf"), options.pop("robot_joints")
        from ilic_cli.io import bag_folder  # deferred: with the readers (`ilic convert --help`)

        kind, path = options["input_format"], bag_folder(source, options["input_format"])  # a bag folder's storage file or metadata.yaml: the folder
        if urdf is None and joints is None:
            from ilic_cli.io.jointlogs import declares_joints, kind_of  # deferred: the readers only when a log is read (`ilic convert --help`)

            if not declares_joints(path, kind):
                return func(source, target, **options)
            if options["joint"] is not None:
                if (kind or kind_of(path)) not in ("csv", "mat"):
                    return func(source, target, **options)  # one joint of an arm's ROS log: the one-joint log, by the one-joint chain
                raise IlicError("--joint", f"{source} is an arm's log: --joints {options['joint']} converts that joint (as an arm's log)")
        return convert_joints(path, target, urdf, joints, options)

    return urdf_option(cast(F, wrapper))


JOINT_TYPE_OPTIONS = {"--load-joint": "load_joint", "--gear-ratio": "gear_ratio", "--torque-constant": "torque_constant"}
"""``identify``'s and ``replay``'s options that declare a one-joint log's joint (refused with ``--urdf``, :func:`refuse_joint_type`)."""


def refuse_joint_type(o: Mapping[str, Any]) -> None:
    """Refuse a one-joint declaration given with ``--urdf`` (an arm's joints take their types and units from its URDF), never ignore it."""
    given = [option for option, name in JOINT_TYPE_OPTIONS.items() if o.get(name) is not None]
    if given:
        raise IlicError(given[0], "declares a one-joint log's joint; an arm's joints take their types and units from its URDF (--urdf)")


ONE_JOINT_OPTIONS = {"--joint": "joint", "--topic": "topic", "--ref-topic": "ref_topic", "--columns": "columns", "--resample": "resample_hz"}
"""``ilic convert``'s options that read or resample a one-joint log (an arm's log is converted whole, as recorded)."""


def convert_joints(source: Path, target: Path, urdf: Path | None, joints: str | None, o: Mapping[str, Any]) -> None:
    """``ilic convert`` of an n-joint log: every joint, its reference, types and metadata, as recorded (:mod:`ilic_cli.io.jointlogs`)."""
    # deferred: numpy, the readers and the writers only to convert an arm's log (`ilic convert --help` imports this module)
    from ilic_cli.commands.common import note
    from ilic_cli.io import detect_format, jointlogs
    from ilic_cli.io.atomic import same_path

    given = [option for option, name in ONE_JOINT_OPTIONS.items() if o.get(name) is not None]
    if click.get_current_context().meta.get("ilic_effort") is not None:
        given.append("--effort")
    if given:
        raise IlicError(given[0], f"applies to a one-joint log; {source} is an arm's log, converted whole as recorded (docs/robots.md)")
    if same_path(source, target):
        raise LogError(target, "output would overwrite the input; choose another output path")
    fmt = detect_format(target, o["out_format"], for_writing=True)
    robot = load_robot(urdf) if urdf is not None else None
    log = read_log(source, robot, joints_option(joints), o["input_format"])
    jointlogs.write(log, target, fmt, o["storage"])
    storage = f", {o['storage']} storage" if fmt == "rosbag2" else ""
    note(
        f"ilic: wrote {target} ({fmt}{storage}): {len(log.t)} samples at {log.fs_hz:g} Hz, {log.duration_s:.6g} s, "
        f"{log.n} joint{'s' if log.n != 1 else ''} {', '.join(log.joints)}{', with reference' if log.has_reference else ''}"
    )


def joints_summary(log_path: Path, urdf: Path | None, joints: str | None) -> dict[str, Any]:
    """``ilic info`` of an n-joint log: its joints with their types and ranges (and the URDF read with it).

    Also what ``ilic info`` gives, without ``--urdf`` or ``--joints``, for a JointState log of several joints.
    """
    robot = load_robot(urdf) if urdf is not None else None
    log = read_log(log_path, robot, joints_option(joints))
    summary = log.to_dict() | {"file": str(log_path)}
    if robot is not None:
        summary["urdf"] = {"path": robot.path, "sha256": robot.sha256}
    return summary


def info_markdown(summary: Mapping[str, Any]) -> str:
    """The joints of an n-joint log as a Markdown table."""
    lines = [
        f"# {summary['file']}",
        "",
        f"- {summary['samples']} samples, {summary['duration_s']:.6g} s at {summary['sample_rate_hz']:.6g} Hz",
        f"- reference: {'yes' if summary['reference'] else 'no'}",
    ]
    if "urdf" in summary:
        lines.append(f"- URDF: {summary['urdf']['path']} (sha256 {summary['urdf']['sha256'][:12]})")
    lines += ["", "| joint | type | q min | q max | effort min | effort max |", "| --- | --- | --- | --- | --- | --- |"]
    for j in summary["joints"]:
        qu, tu = j["position_unit"], j["effort_unit"]
        kind = f"{j['type']} (assumed)" if j.get("type_assumed") else j["type"]
        lines.append(f"| {j['name']} | {kind} | {j['q_min']:.6g} {qu} | {j['q_max']:.6g} {qu} | {j['tau_min']:.6g} {tu} | {j['tau_max']:.6g} {tu} |")
    if any(j.get("type_assumed") for j in summary["joints"]):
        lines += ["", "The log gives no joint type: (assumed) ones are read as revolute; --urdf ARM.urdf gives the types."]
    return "\n".join(lines) + "\n"
