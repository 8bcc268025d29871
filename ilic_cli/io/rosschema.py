"""What ilic writes into ROS containers: topics, message types, type stores, definitions.

Topics written (message types from the ``rosbags`` type stores, ROS 2 Humble
for CDR and ROS 1 Noetic for ROS 1 serialisation):

``/joint_states`` -- ``sensor_msgs/msg/JointState``
    ``header.stamp`` = sample time, ``name`` = ``[joint]``, ``position`` =
    ``[q]``, ``velocity`` = ``[qd]`` (empty without ``qd``), ``effort`` = ``[tau]``.
``/joint_reference`` -- ``trajectory_msgs/msg/JointTrajectoryPoint``
    ``positions`` = ``[q_ref]``, ``velocities`` = ``[qd_ref]``,
    ``accelerations`` = ``[qdd_ref]`` (empty where missing), ``time_from_start``
    = time since the first sample. Only written when the log has a reference.
``/ilic/extras`` -- ``sensor_msgs/msg/JointState``
    ``name`` = ``["t_s", <other channels>...]``, ``position`` = their values;
    ``t_s`` is the exact float64 time, so ``t`` round-trips bit for bit.
``/ilic/metadata`` -- ``std_msgs/msg/String``
    One message, JSON ``{"format": "ilic-runlog", "version": 1, "joint": ...,
    "units": {...}, "meta": {...}}``.

Message log time = sample time in integer nanoseconds (shifted by whole
seconds when ``t`` starts below zero). Nothing depends on the wall clock.

Read, never written: ros2_control's ``control_msgs/msg/JointTrajectoryControllerState``
in each of its layouts (:data:`CONTROLLER_LAYOUTS`), whose definitions are
built in here because the ``rosbags`` type stores do not ship ``control_msgs``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

TOPIC_STATES = "/joint_states"
TOPIC_REFERENCE = "/joint_reference"
TOPIC_EXTRAS = "/ilic/extras"
TOPIC_METADATA = "/ilic/metadata"

JOINT_STATE = "sensor_msgs/msg/JointState"
TRAJECTORY_POINT = "trajectory_msgs/msg/JointTrajectoryPoint"
STRING = "std_msgs/msg/String"
CONTROLLER_STATE = "control_msgs/msg/JointTrajectoryControllerState"
TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"

READ_TYPES = frozenset({JOINT_STATE, TRAJECTORY_POINT, STRING, CONTROLLER_STATE, TRAJECTORY})
"""Message types the readers decode; containers may skip messages of other types."""

TIME_NAME = "t_s"
"""Name of the exact float64 time in ``/ilic/extras``."""

FORMAT_TAG = "ilic-runlog"
FORMAT_VERSION = 1

STATE_FIELDS = {"q": "position", "qd": "velocity", "tau": "effort"}
REFERENCE_FIELDS = {"q_ref": "positions", "qd_ref": "velocities", "qdd_ref": "accelerations"}

ROS2 = "ros2"
ROS1 = "ros1"


CONTROLLER_LAYOUTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    # control_msgs <= 4.0 (Foxy, Galactic, early Humble), as ROS 1's (Noetic)
    "desired/actual": (("desired", "actual", "error"), ()),
    # control_msgs 4.x (Humble): the new fields, then the deprecated ones kept
    "reference/feedback+desired/actual": (
        ("reference", "feedback", "error", "output", "desired", "actual"),
        ("reference", "feedback", "error", "output", "desired", "actual"),
    ),
    # control_msgs >= 5 (Jazzy and later)
    "reference/feedback": (("reference", "feedback", "error", "output"), ("reference", "feedback", "error", "output")),
}
"""ROS 2 layouts of :data:`CONTROLLER_STATE`: name -> (its ``trajectory_msgs/JointTrajectoryPoint`` fields, after ``header`` and
``joint_names``; its ``multi_dof_*`` ``MultiDOFJointTrajectoryPoint`` fields, after ``multi_dof_joint_names``). CDR carries no
field names, so a message is decoded with the first layout whose size matches it exactly. ROS 1's is ``desired/actual`` (MD5
``10817c60c2486ef6b33e97dcd87f4474``)."""


def _controller_fields(layout: str, kind: str) -> dict[str, Any]:
    """:data:`CONTROLLER_STATE` in ``layout`` as a ``rosbags`` type definition, built field by field (no definition text is parsed)."""
    from rosbags.interfaces import Nodetype  # rosbags deferred: `ilic info --help` imports this module

    points, multi = CONTROLLER_LAYOUTS[layout]
    names = (Nodetype.SEQUENCE, ((Nodetype.BASE, ("string", 0)), 0))
    fields: list[tuple[str, Any]] = [("header", (Nodetype.NAME, "std_msgs/msg/Header")), ("joint_names", names)]
    fields += [(p, (Nodetype.NAME, "trajectory_msgs/msg/JointTrajectoryPoint")) for p in points]
    if multi and kind == ROS2:
        fields.append(("multi_dof_joint_names", names))
        fields += [(f"multi_dof_{p}", (Nodetype.NAME, "trajectory_msgs/msg/MultiDOFJointTrajectoryPoint")) for p in multi]
    return {CONTROLLER_STATE: ([], fields)}


# -- type stores -------------------------------------------------------------
@functools.cache
def typestore(kind: str) -> Any:
    """Return the ``rosbags`` type store: ROS 2 Humble's types that ilic writes and reads (``"ros2"``)
    or ROS 1 Noetic (``"ros1"``, with ROS 1's :data:`CONTROLLER_STATE`).

    The ROS 2 store holds :func:`ros2_types` only, registered in an empty
    store: the same definitions as Humble's (tested), without importing the
    module of Humble's some 200 types (0.05-0.08 s, every read of a ROS 2 bag or MCAP file).
    """
    from rosbags.typesys import Stores, get_typestore  # rosbags deferred: `ilic info --help` imports this module

    if kind == ROS1:
        ts = get_typestore(Stores.ROS1_NOETIC)
        ts.register(_controller_fields("desired/actual", ROS1))
        return ts
    ts = get_typestore(Stores.EMPTY)
    ts.register(ros2_types())
    return ts


def ros2_types() -> dict[str, Any]:
    """The definitions (``rosbags``' field trees) of the ROS 2 types of :func:`typestore`:
    JointState, JointTrajectory, JointTrajectoryPoint, String and the types in them."""
    from rosbags.interfaces import Nodetype  # rosbags deferred: `ilic info --help` imports this module

    f64s = (Nodetype.SEQUENCE, ((Nodetype.BASE, ("float64", 0)), 0))
    strings = (Nodetype.SEQUENCE, ((Nodetype.BASE, ("string", 0)), 0))
    time = [("sec", (Nodetype.BASE, ("int32", 0))), ("nanosec", (Nodetype.BASE, ("uint32", 0)))]
    header = ("header", (Nodetype.NAME, "std_msgs/msg/Header"))
    return {
        "builtin_interfaces/msg/Time": ([], time),
        "builtin_interfaces/msg/Duration": ([], list(time)),
        "std_msgs/msg/Header": ([], [("stamp", (Nodetype.NAME, "builtin_interfaces/msg/Time")), ("frame_id", (Nodetype.BASE, ("string", 0)))]),
        STRING: ([], [("data", (Nodetype.BASE, ("string", 0)))]),
        JOINT_STATE: ([], [header, ("name", strings), ("position", f64s), ("velocity", f64s), ("effort", f64s)]),
        TRAJECTORY_POINT: (
            [],
            [
                ("positions", f64s),
                ("velocities", f64s),
                ("accelerations", f64s),
                ("effort", f64s),
                ("time_from_start", (Nodetype.NAME, "builtin_interfaces/msg/Duration")),
            ],
        ),
        TRAJECTORY: ([], [header, ("joint_names", strings), ("points", (Nodetype.SEQUENCE, ((Nodetype.NAME, TRAJECTORY_POINT), 0)))]),
    }


@functools.cache
def controller_typestore(layout: str) -> Any:
    """Return a ROS 2 Humble type store with :data:`CONTROLLER_STATE` in ``layout`` (a key of :data:`CONTROLLER_LAYOUTS`)."""
    from rosbags.typesys import Stores, get_typestore  # rosbags deferred: `ilic info --help` imports this module

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(_controller_fields(layout, ROS2))
    return ts


def message_definition(msgtype: str, kind: str = ROS2) -> tuple[str, str]:
    """Return ``(definition text, hash)`` of a built-in message type.

    For ``"ros2"`` the text is the ``ros2msg`` concatenated definition that MCAP
    viewers decode and the hash is RIHS01; for ``"ros1"`` it is the ROS 1
    definition and its MD5 sum.
    """
    ts = typestore(kind)
    if kind == ROS1:
        text, digest = ts.generate_msgdef(msgtype)
    else:
        text, _ = ts.generate_msgdef(msgtype, ros_version=2)
        digest = ts.hash_rihs01(msgtype)
    return text, digest


def normalize_msgtype(name: str) -> str:
    """Return ``pkg/msg/Type`` for ``pkg/Type`` or ``pkg/msg/Type``."""
    parts = name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name.strip()


@dataclass(frozen=True)
class TopicSpec:
    """A topic to create: name and message type."""

    topic: str
    msgtype: str


@dataclass(frozen=True)
class RawTopic:
    """A topic in a container, as the container module reports it.

    Attributes
    ----------
    name : str
        Topic name.
    msgtype : str
        Message type, normalised to ``pkg/msg/Type``.
    kind : str
        ``"ros2"`` (CDR) or ``"ros1"`` serialisation; anything else cannot be decoded.
    """

    name: str
    msgtype: str
    kind: str
