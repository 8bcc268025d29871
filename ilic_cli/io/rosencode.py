"""RunLog -> serialised ROS messages (the topics of :mod:`ilic_cli.io.rosschema`)."""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io import cdrcols
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


def stamps_ns(t: np.ndarray, start_ns: int = 0) -> np.ndarray:
    """Return integer-nanosecond log times for sample times ``t`` (s) after ``start_ns``.

    ``start_ns + round(t * 1e9)``: a log read from a robot's recording keeps
    its absolute stamps (``meta["start_time_ns"]``), so that a converted file
    lines up with the robot's other recordings. Without a start, shifted by
    whole seconds when ``t[0] < 0`` so that every stamp is non-negative.
    Raises :class:`LogError` when two samples fall on the same nanosecond.
    """
    t = np.asarray(t, dtype=np.float64)
    if not np.isfinite(t).all():
        raise LogError(None, "time stamps must be finite (NaN or infinite time cannot be a ROS time stamp)")
    shift = 0.0 if len(t) == 0 or t[0] >= 0 or start_ns else float(math.ceil(-t[0]))
    ns = np.rint((t + shift) * 1e9)
    if len(ns) and (ns[-1] + start_ns >= 2**62 or ns[0] + start_ns < 0 or not np.isfinite(ns).all()):
        raise LogError(None, "time stamps out of the range of ROS time")
    out = ns.astype(np.int64) + np.int64(start_ns)
    if len(out) > 1 and (np.diff(out) <= 0).any():
        raise LogError(None, "time steps below 1 ns cannot be stored as ROS time stamps")
    return out


def log_stamps_ns(log: RunLog) -> np.ndarray:
    """:func:`stamps_ns` of ``log``'s samples, from its recorded start (``meta["start_time_ns"]``) when it has one."""
    start = log.meta.get("start_time_ns")
    return stamps_ns(log.t, int(start) if isinstance(start, (int, float)) and not isinstance(start, bool) and start >= 0 else 0)


def metadata_text(log: RunLog, joint: str) -> str:
    """The JSON of the ``/ilic/metadata`` message (format, version, joint, units, metadata)."""
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
    return log.sensor.joint or default


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
    ns = log_stamps_ns(log)
    meta_text = metadata_text(log, joint)
    return topics, _messages(log, joint, kind, topics, ns, extras, meta_text)


def _messages(
    log: RunLog, joint: str, kind: str, topics: list[TopicSpec], ns: np.ndarray, extras: list[str], meta_text: str
) -> Iterator[tuple[str, int, bytes]]:
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


# -- whole columns at once ------------------------------------------------------
@dataclass
class Columns:
    """A log's ROS 2 messages as templates filled column by column (see :func:`encode_columns`).

    Attributes
    ----------
    topics : list of TopicSpec
        Topics in registration order (as :func:`encode`).
    metadata : bytes
        The ``/ilic/metadata`` message.
    log_ns : ndarray of int64
        Log time of each sample.
    sizes : dict
        Topic -> message size (bytes); every message of a sample topic has this size.
    """

    topics: list[TopicSpec]
    metadata: bytes
    log_ns: np.ndarray
    sizes: dict[str, int]
    _fill: dict[str, Callable[[int, int], np.ndarray]]

    def sample_topics(self) -> list[str]:
        """The topics with one message per sample, in the order they are written for each sample."""
        return [spec.topic for spec in self.topics if spec.topic != TOPIC_METADATA]

    def rows(self, topic: str, start: int, stop: int) -> np.ndarray:
        """The messages of samples ``start:stop`` on ``topic``, as a (samples, size) uint8 array."""
        return self._fill[topic](start, stop)


def encode_columns(log: RunLog, joint: str) -> Columns | None:
    """Prepare ``log``'s ROS 2 messages for writing in bulk, bit-identical to :func:`encode`'s.

    The first sample's messages, serialised by ``rosbags``, are the templates;
    their layouts (:func:`ilic_cli.io.cdrcols.layout`) say where each column's
    values go. Returns None when a template cannot be walked or a time stamp
    does not fit CDR's int32 seconds; callers then use :func:`encode`, which
    reports the problem.
    """
    topics, messages = encode(log, joint, ROS2)
    first = {topic: data for topic, _, data in itertools.islice(messages, len(topics))}
    ns = log_stamps_ns(log)
    sec, nsec = np.divmod(ns, 1_000_000_000)
    since = ns - ns[0]
    dsec, dnsec = np.divmod(since, 1_000_000_000)
    if int(sec.max()) >= 2**31 or int(dsec.max()) >= 2**31:
        return None
    layouts = {spec.topic: cdrcols.layout(first[spec.topic], spec.msgtype) for spec in topics}
    if any(lay is None for lay in layouts.values()):
        return None
    ch = log.channels
    extras = _extra_channels(log)
    wanted: dict[str, dict[str, np.ndarray | None]] = {
        TOPIC_STATES: {"position": ch["q"], "velocity": ch.get("qd"), "effort": ch["tau"]},
        TOPIC_REFERENCE: {field: ch.get(name) for name, field in REFERENCE_FIELDS.items()},
        TOPIC_EXTRAS: {},
    }
    fills: dict[str, Callable[[int, int], np.ndarray]] = {}
    for spec in topics:
        lay = layouts[spec.topic]
        assert lay is not None
        if spec.topic == TOPIC_METADATA:
            continue
        columns: list[tuple[int, np.ndarray]] = []
        for field, values in wanted[spec.topic].items():
            offset, count = lay.arrays[field]
            if count != (0 if values is None else 1):
                return None
            if values is not None:
                columns.append((offset, np.asarray(values, dtype=np.float64)))
        if spec.topic == TOPIC_EXTRAS:
            offset, count = lay.arrays["position"]
            if count != 1 + len(extras):
                return None
            columns.append((offset, np.column_stack([log.t, *(ch[name] for name in extras)]).astype(np.float64, copy=False)))
        times = [(lay.times[name], s, n) for name, s, n in (("stamp", sec, nsec), ("time_from_start", dsec, dnsec)) if name in lay.times]
        fills[spec.topic] = functools.partial(_fill_rows, first[spec.topic], columns, times)
    sizes = {topic: len(data) for topic, data in first.items()}
    return Columns(topics, first[TOPIC_METADATA], ns, sizes, fills)


def _fill_rows(template: bytes, columns: list[tuple[int, np.ndarray]], times: list[tuple[int, np.ndarray, np.ndarray]], start: int, stop: int) -> np.ndarray:
    rows = cdrcols.fill_rows(template, stop - start)
    for offset, sec, nsec in times:
        cdrcols.put(rows, offset, "<i4", sec[start:stop].astype(np.int32))
        cdrcols.put(rows, offset + 4, "<u4", nsec[start:stop].astype(np.uint32))
    for offset, values in columns:
        cdrcols.put(rows, offset, "<f8", values[start:stop])
    return rows
