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

READ_TYPES = frozenset({JOINT_STATE, TRAJECTORY_POINT, STRING, CONTROLLER_STATE})
"""Message types the readers decode; containers may skip messages of other types."""

TIME_NAME = "t_s"
"""Name of the exact float64 time in ``/ilic/extras``."""

FORMAT_TAG = "ilic-runlog"
FORMAT_VERSION = 1

STATE_FIELDS = {"q": "position", "qd": "velocity", "tau": "effort"}
REFERENCE_FIELDS = {"q_ref": "positions", "qd_ref": "velocities", "qdd_ref": "accelerations"}

ROS2 = "ros2"
ROS1 = "ros1"


_POINT = "trajectory_msgs/JointTrajectoryPoint"
_MULTI = "trajectory_msgs/MultiDOFJointTrajectoryPoint"


def _controller_text(header: str, points: tuple[str, ...], multi: tuple[str, ...] = ()) -> str:
    lines = [f"{header} header", "string[] joint_names", *(f"{_POINT} {p}" for p in points)]
    if multi:
        lines += ["string[] multi_dof_joint_names", *(f"{_MULTI} multi_dof_{p}" for p in multi)]
    return "\n".join(lines) + "\n"


CONTROLLER_LAYOUTS: dict[str, str] = {
    # control_msgs <= 4.0 (Foxy, Galactic, early Humble) and ROS 1 (Noetic)
    "desired/actual": _controller_text("std_msgs/Header", ("desired", "actual", "error")),
    # control_msgs 4.x (Humble): the new fields, then the deprecated ones kept
    "reference/feedback+desired/actual": _controller_text(
        "std_msgs/Header",
        ("reference", "feedback", "error", "output", "desired", "actual"),
        ("reference", "feedback", "error", "output", "desired", "actual"),
    ),
    # control_msgs >= 5 (Jazzy and later)
    "reference/feedback": _controller_text("std_msgs/Header", ("reference", "feedback", "error", "output"), ("reference", "feedback", "error", "output")),
}
"""ROS 2 layouts of :data:`CONTROLLER_STATE` (name -> ``.msg`` text), tried in this order; CDR carries no field names, so a
message is decoded with the first layout whose size matches it exactly."""

CONTROLLER_ROS1 = _controller_text("Header", ("desired", "actual", "error"))
"""ROS 1's :data:`CONTROLLER_STATE` (Noetic's ``control_msgs``; MD5 ``10817c60c2486ef6b33e97dcd87f4474``)."""


# -- type stores -------------------------------------------------------------
@functools.cache
def typestore(kind: str) -> Any:
    """Return the ``rosbags`` type store: ROS 2 Humble (``"ros2"``) or ROS 1 Noetic (``"ros1"``, with :data:`CONTROLLER_ROS1`)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if kind == ROS1:
        ts = get_typestore(Stores.ROS1_NOETIC)
        ts.register(get_types_from_msg(CONTROLLER_ROS1, CONTROLLER_STATE))
        return ts
    return get_typestore(Stores.ROS2_HUMBLE)


@functools.cache
def controller_typestore(layout: str) -> Any:
    """Return a ROS 2 Humble type store with :data:`CONTROLLER_STATE` in ``layout`` (a key of :data:`CONTROLLER_LAYOUTS`)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(CONTROLLER_LAYOUTS[layout], CONTROLLER_STATE))
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
