"""RunLog -> serialised ROS messages (the topics of :mod:`ilic_cli.io.rosschema`)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io.rosjson import dump_json, meta_for_writing
from ilic_cli.io.rosschema import (
    FORMAT_TAG,
    FORMAT_VERSION,
    JOINT_STATE,
    REFERENCE_FIELDS,
    ROS1,
    ROS2,
    STATE_FIELDS,
    STRING,
    TIME_NAME,
    TOPIC_EXTRAS,
    TOPIC_METADATA,
    TOPIC_REFERENCE,
    TOPIC_STATES,
    TRAJECTORY_POINT,
    TopicSpec,
    typestore,
)

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog


def _extra_channels(log: RunLog) -> list[str]:
    taken = {"t", *STATE_FIELDS, *REFERENCE_FIELDS}
    return [name for name in log.channels if name not in taken]


def plan_topics(log: RunLog) -> list[TopicSpec]:
    """Return the topics :func:`encode` writes for ``log``, in registration order."""
    topics = [TopicSpec(TOPIC_METADATA, STRING), TopicSpec(TOPIC_STATES, JOINT_STATE)]
    if any(name in log.channels for name in REFERENCE_FIELDS):
        topics.append(TopicSpec(TOPIC_REFERENCE, TRAJECTORY_POINT))
    topics.append(TopicSpec(TOPIC_EXTRAS, JOINT_STATE))
    return topics


def stamps_ns(t: np.ndarray) -> np.ndarray:
    """Return integer-nanosecond log times for sample times ``t`` (s).

    ``round(t * 1e9)``, shifted by whole seconds when ``t[0] < 0`` so that every
    stamp is non-negative. Raises :class:`LogError` when two samples fall on the
    same nanosecond.
    """
    t = np.asarray(t, dtype=np.float64)
    if not np.isfinite(t).all():
        raise LogError(None, "time stamps must be finite (NaN or infinite time cannot be a ROS time stamp)")
    shift = 0.0 if len(t) == 0 or t[0] >= 0 else float(math.ceil(-t[0]))
    ns = np.rint((t + shift) * 1e9)
    if len(ns) and (ns[-1] >= 2**62 or not np.isfinite(ns).all()):
        raise LogError(None, "time stamps too large for ROS time")
    out = ns.astype(np.int64)
    if len(out) > 1 and (np.diff(out) <= 0).any():
        raise LogError(None, "time steps below 1 ns cannot be stored as ROS time stamps")
    return out


def _metadata_text(log: RunLog, joint: str) -> str:
    payload = {
        "format": FORMAT_TAG,
        "version": FORMAT_VERSION,
        "joint": joint,
        "units": dict(log.units),
        "meta": meta_for_writing(log.meta),
    }
    return dump_json(payload)


def writer_joint(log: RunLog, default: str) -> str:
    """Joint name for writing: the log's ``joint`` metadata, else ``default``."""
    joint = log.meta.get("joint")
    return joint if isinstance(joint, str) and joint else default


def encode(log: RunLog, joint: str, kind: str = ROS2) -> tuple[list[TopicSpec], Iterator[tuple[str, int, bytes]]]:
    """Turn ``log`` into serialised messages.

    Parameters
    ----------
    log : RunLog
        The log to write (needs ``t``, ``q`` and ``tau``).
    joint : str
        Joint name for ``/joint_states``.
    kind : {"ros2", "ros1"}
        CDR (ROS 2 Humble types) or ROS 1 serialisation (Noetic types).

    Returns
    -------
    topics : list of TopicSpec
        Topics to register, in order.
    messages : iterator of (topic, log_time_ns, bytes)
        Messages in log-time order (metadata first, then per sample
        ``/joint_states``, ``/joint_reference``, ``/ilic/extras``).
    """
    log.require("t", "q", "tau")
    if len(log) == 0:
        raise LogError(None, "the log has no samples to write")
    extras = _extra_channels(log)
    if TIME_NAME in extras:
        raise LogError(None, f"channel name '{TIME_NAME}' is reserved in ROS formats; rename the channel")
    topics = plan_topics(log)
    ns = stamps_ns(log.t)
    meta_text = _metadata_text(log, joint)
    return topics, _messages(log, joint, kind, topics, ns, extras, meta_text)


def _messages(log: RunLog, joint: str, kind: str, topics: list[TopicSpec], ns: np.ndarray, extras: list[str], meta_text: str) -> Iterator[tuple[str, int, bytes]]:
    ts = typestore(kind)
    js_cls = ts.types[JOINT_STATE]
    header_cls = ts.types["std_msgs/msg/Header"]
    time_cls = ts.types["builtin_interfaces/msg/Time"]
    duration_cls = ts.types["builtin_interfaces/msg/Duration"]
    point_cls = ts.types[TRAJECTORY_POINT]
    string_cls = ts.types[STRING]

    if kind == ROS1:
        def ser(msg: Any, typ: str) -> bytes:
            return bytes(ts.serialize_ros1(msg, typ))

        def header(i: int, sec: int, nsec: int) -> Any:
            return header_cls(seq=i, stamp=time_cls(sec=sec, nanosec=nsec), frame_id="")
    else:
        def ser(msg: Any, typ: str) -> bytes:
            return bytes(ts.serialize_cdr(msg, typ, little_endian=True))

        def header(i: int, sec: int, nsec: int) -> Any:
            return header_cls(stamp=time_cls(sec=sec, nanosec=nsec), frame_id="")

    empty = np.empty(0, dtype=np.float64)
    ch = log.channels
    q, tau, qd = ch["q"], ch["tau"], ch.get("qd")
    has_ref = any(s.topic == TOPIC_REFERENCE for s in topics)
    ref = [ch.get(name) for name in REFERENCE_FIELDS]
    extra_names = [TIME_NAME, *extras]
    extra_matrix = np.column_stack([log.t, *(ch[name] for name in extras)])
    names = [joint]
    ns_list = ns.tolist()
    yield TOPIC_METADATA, ns_list[0], ser(string_cls(data=meta_text), STRING)
    for i, stamp in enumerate(ns_list):
        sec, nsec = divmod(stamp, 1_000_000_000)
        state = js_cls(
            header=header(i, sec, nsec),
            name=names,
            position=q[i : i + 1].copy(),
            velocity=qd[i : i + 1].copy() if qd is not None else empty,
            effort=tau[i : i + 1].copy(),
        )
        yield TOPIC_STATES, stamp, ser(state, JOINT_STATE)
        if has_ref:
            dsec, dnsec = divmod(stamp - ns_list[0], 1_000_000_000)
            point = point_cls(
                positions=ref[0][i : i + 1].copy() if ref[0] is not None else empty,
                velocities=ref[1][i : i + 1].copy() if ref[1] is not None else empty,
                accelerations=ref[2][i : i + 1].copy() if ref[2] is not None else empty,
                effort=empty,
                time_from_start=duration_cls(sec=dsec, nanosec=dnsec),
            )
            yield TOPIC_REFERENCE, stamp, ser(point, TRAJECTORY_POINT)
        extra = js_cls(header=header(i, sec, nsec), name=extra_names, position=extra_matrix[i].copy(), velocity=empty, effort=empty)
        yield TOPIC_EXTRAS, stamp, ser(extra, JOINT_STATE)
