"""ROS messages <-> RunLog, shared by the MCAP, ROS 1 bag and ROS 2 bag modules.

The container modules only move bytes; everything about *what* is in the
messages lives here, once.

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

Reading: a file with ``/ilic/metadata`` is read back exactly. Any other file is
read from its ``sensor_msgs/JointState`` topic (``Selection.topic``, or the only
one, or ``/joint_states``) for one joint (``Selection.joint`` or the only one):
``q`` from ``position``, ``qd`` from ``velocity``, ``tau`` from ``effort``, ``t``
from ``header.stamp`` (log time when every stamp is zero) relative to the first
sample; the reference from ``Selection.ref_topic`` or ``/joint_reference``
(``JointTrajectoryPoint`` or ``JointState``). Only the built-in message types
are decoded: definitions stored in a file are never compiled or executed.
Container modules stream every message once into a :class:`Collector`, which
decodes it with the ``rosbags`` type store and keeps only NumPy columns of the
values (no Python object per message); :func:`decode` works on those columns.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import ChoiceError, LogError

if TYPE_CHECKING:
    from ilic_cli.io import Selection
    from ilic_cli.runlog import RunLog

TOPIC_STATES = "/joint_states"
TOPIC_REFERENCE = "/joint_reference"
TOPIC_EXTRAS = "/ilic/extras"
TOPIC_METADATA = "/ilic/metadata"

JOINT_STATE = "sensor_msgs/msg/JointState"
TRAJECTORY_POINT = "trajectory_msgs/msg/JointTrajectoryPoint"
STRING = "std_msgs/msg/String"

READ_TYPES = frozenset({JOINT_STATE, TRAJECTORY_POINT, STRING})
"""Message types the readers decode; containers may skip messages of other types."""

TIME_NAME = "t_s"
"""Name of the exact float64 time in ``/ilic/extras``."""

FORMAT_TAG = "ilic-runlog"
FORMAT_VERSION = 1

STATE_FIELDS = {"q": "position", "qd": "velocity", "tau": "effort"}
REFERENCE_FIELDS = {"q_ref": "positions", "qd_ref": "velocities", "qdd_ref": "accelerations"}

ROS2 = "ros2"
ROS1 = "ros1"


# -- JSON helpers (also used by the .mat and CSV modules) -------------------
def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    raise TypeError(f"value of type {type(obj).__name__} cannot be stored as JSON")


def dump_json(obj: Any) -> str:
    """Serialise ``obj`` (metadata, units) to one line of JSON.

    NumPy scalars and arrays become numbers and lists. Raises
    :class:`~ilic_cli.errors.LogError` for values JSON cannot hold.
    """
    try:
        return json.dumps(obj, default=_json_default, ensure_ascii=True)
    except (TypeError, ValueError) as exc:
        raise LogError(None, f"metadata cannot be written: {exc}") from None


def meta_for_writing(meta: Mapping[str, Any]) -> dict[str, Any]:
    """Return the metadata to store in a file: all keys but ``source``.

    ``source`` names the file a log was read from; it is set again on reading.
    """
    return {k: v for k, v in meta.items() if k != "source"}


def parse_json_object(text: str, path: str | Path, what: str) -> dict[str, Any]:
    """Parse ``text`` as a JSON object or raise a one-line :class:`LogError`.

    Parameters
    ----------
    text : str
        The JSON text.
    path : str or Path
        File named in the error.
    what : str
        What the text is (``"metadata"``), for the error message.
    """
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise LogError(path, f"{what} is not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise LogError(path, f"{what} is not a JSON object")
    return value


def parse_units(value: Any, path: str | Path) -> dict[str, str]:
    """Check that ``value`` maps channel names to unit strings."""
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        raise LogError(path, "units must map channel names to strings")
    return dict(value)


# -- type stores -------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def typestore(kind: str) -> Any:
    """Return the ``rosbags`` type store: ROS 2 Humble (``"ros2"``) or ROS 1 Noetic (``"ros1"``)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if kind == ROS1 else Stores.ROS2_HUMBLE)


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


# -- writing ----------------------------------------------------------------
@dataclass(frozen=True)
class TopicSpec:
    """A topic to create: name and message type."""

    topic: str
    msgtype: str


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


# -- reading ----------------------------------------------------------------
BLOCK = 8192
"""Messages buffered as Python values before they are packed into NumPy blocks."""


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


def short_text(exc: BaseException) -> str:
    """The exception's message on one line, cut at 160 characters."""
    text = " ".join(str(exc).split())
    return text[:160] + ("..." if len(text) > 160 else "")


class _Numbers:
    """A growing column of scalars packed into NumPy blocks every :data:`BLOCK` items.

    With ``small=True`` (non-negative counts and indices) a block is stored as
    uint8 when its values allow, else as the given dtype.
    """

    __slots__ = ("dtype", "items", "blocks", "small")

    def __init__(self, dtype: Any, small: bool = False) -> None:
        self.dtype = dtype
        self.items: list[Any] = []
        self.blocks: list[np.ndarray] = []
        self.small = small

    def flush(self) -> None:
        if self.items:
            block = np.asarray(self.items, dtype=self.dtype)
            if self.small and len(block) and int(block.max()) < 256 and int(block.min()) >= 0:
                block = block.astype(np.uint8)
            self.blocks.append(block)
            self.items = []

    def array(self) -> np.ndarray:
        self.flush()
        out = np.concatenate(self.blocks) if self.blocks else np.empty(0, dtype=self.dtype)
        self.blocks = []
        return out


class _Arrays:
    """A growing column of small float arrays (one per message), flattened into NumPy blocks."""

    __slots__ = ("items", "blocks", "counts")

    def __init__(self) -> None:
        self.items: list[Any] = []
        self.blocks: list[np.ndarray] = []
        self.counts = _Numbers(np.int32, small=True)

    def append(self, values: Any) -> None:
        self.items.append(values)
        self.counts.items.append(len(values))

    def flush(self) -> None:
        if self.items:
            try:
                block = np.concatenate(self.items).astype(np.float64, copy=False)
            except (ValueError, TypeError):
                block = np.concatenate([np.asarray(v, dtype=np.float64).reshape(-1) for v in self.items])
            self.blocks.append(block)
            self.items = []
        self.counts.flush()

    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        self.flush()
        flat = np.concatenate(self.blocks) if self.blocks else np.empty(0)
        self.blocks = []
        return flat, self.counts.array()


@dataclass
class Series:
    """Decoded messages of one topic as columns (no per-message Python objects).

    Attributes
    ----------
    topic : RawTopic
        The topic.
    log_ns : ndarray of int64
        Log time of each message, sorted.
    stamp_ns : ndarray of int64 or None
        ``header.stamp`` of each message (JointState).
    name_id : ndarray of int32 or None
        Index into ``names`` of each message's ``name`` list (JointState).
    names : list of tuple of str
        Distinct ``name`` lists, in order of first appearance.
    fields : dict
        Array field -> ``(flat values, count per message)``.
    text : str or None
        Data of the first message (String).
    """

    topic: RawTopic
    log_ns: np.ndarray
    stamp_ns: np.ndarray | None = None
    name_id: np.ndarray | None = None
    names: list[tuple[str, ...]] = field(default_factory=list)
    fields: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    text: str | None = None

    def __len__(self) -> int:
        return len(self.log_ns)

    def values_at(self, fieldname: str, index: np.ndarray | int, keep: np.ndarray | None = None) -> np.ndarray | None:
        """Element ``index[i]`` of ``fieldname`` for the messages ``keep``; None when one is too short."""
        flat, counts = self.fields[fieldname]
        if keep is None and np.ndim(index) == 0 and len(counts):
            # the usual case: every message has the same width -> a strided view, no index arrays
            width = int(counts[0])
            j = int(index)
            if width > j and bool((counts == width).all()):
                return flat if width == 1 else np.ascontiguousarray(flat[j::width])
            if not (counts > j).all():
                return None
        starts = np.cumsum(counts, dtype=np.int64) - counts
        if keep is not None:
            counts, starts = counts[keep], starts[keep]
        if len(counts) == 0 or not (counts > index).all():
            return None
        return flat[starts + index]


class _Sink:
    """Decodes the messages of one topic into columns; the first failure is kept, raised on use."""

    arrays: tuple[str, ...] = ()

    def __init__(self, topic: RawTopic) -> None:
        ts = typestore(topic.kind)
        self.topic = topic
        self.count = 0
        self.error: str | None = None
        self._deserialize = ts.deserialize_ros1 if topic.kind == ROS1 else ts.deserialize_cdr
        self._log_ns = _Numbers(np.int64)
        self._arrays = {name: _Arrays() for name in self.arrays}

    def add(self, log_ns: int, data: bytes | memoryview) -> None:
        """Decode one message (``log_ns``, raw ``data``) into the columns."""
        if self.error is not None:
            return
        try:
            msg = self._deserialize(data, self.topic.msgtype)
            self._take(msg)
        except Exception as exc:  # noqa: BLE001 - any decoding failure is bad input
            self.error = f"message {self.count} on {self.topic.name} cannot be decoded as {self.topic.msgtype} ({type(exc).__name__}: {short_text(exc)})"
            return
        self._log_ns.items.append(log_ns)
        self.count += 1
        if self.count % BLOCK == 0:
            self._flush()

    def _take(self, msg: Any) -> None:
        for name, column in self._arrays.items():
            column.append(getattr(msg, name))

    def _flush(self) -> None:
        self._log_ns.flush()
        for column in self._arrays.values():
            column.flush()

    def finish(self) -> Series:
        """Return the columns, sorted by log time (stable)."""
        series = Series(self.topic, self._log_ns.array())
        for name, column in self._arrays.items():
            series.fields[name] = column.columns()
        self._extra(series)
        _sort(series)
        return series

    def _extra(self, series: Series) -> None:
        pass


class _JointStateSink(_Sink):
    arrays = ("position", "velocity", "effort")

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        self._stamp = _Numbers(np.int64)
        self._name_id = _Numbers(np.int32, small=True)
        self._names: dict[tuple[str, ...], int] = {}

    def _take(self, msg: Any) -> None:
        key = tuple(msg.name)
        nid = self._names.get(key)
        if nid is None:
            nid = self._names[key] = len(self._names)
        stamp = msg.header.stamp
        position, velocity, effort = msg.position, msg.velocity, msg.effort
        self._stamp.items.append(int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec))
        self._name_id.items.append(nid)
        arrays = self._arrays
        arrays["position"].append(position)
        arrays["velocity"].append(velocity)
        arrays["effort"].append(effort)

    def _flush(self) -> None:
        super()._flush()
        self._stamp.flush()
        self._name_id.flush()

    def _extra(self, series: Series) -> None:
        series.stamp_ns = self._stamp.array()
        series.name_id = self._name_id.array()
        series.names = [tuple(str(x) for x in key) for key in self._names]


class _PointSink(_Sink):
    arrays = ("positions", "velocities", "accelerations")


class _StringSink(_Sink):
    """Keeps the data of the first message only (later ones are counted, not decoded)."""

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        self._text: str | None = None

    def add(self, log_ns: int, data: bytes | memoryview) -> None:
        """Decode the first message; count the others."""
        if self.count == 0 and self.error is None:
            try:
                self._text = str(self._deserialize(data, self.topic.msgtype).data)
            except Exception as exc:  # noqa: BLE001
                self.error = f"message 0 on {self.topic.name} cannot be decoded as {self.topic.msgtype} ({type(exc).__name__}: {short_text(exc)})"
                return
        self._log_ns.items.append(log_ns)
        self.count += 1
        if self.count % BLOCK == 0:
            self._flush()

    def _extra(self, series: Series) -> None:
        series.text = self._text


_SINKS: dict[str, type[_Sink]] = {JOINT_STATE: _JointStateSink, TRAJECTORY_POINT: _PointSink, STRING: _StringSink}


def _sort(series: Series) -> None:
    """Put the messages of ``series`` in log-time order (stable) when they are not."""
    log_ns = series.log_ns
    if len(log_ns) < 2 or bool((log_ns[1:] >= log_ns[:-1]).all()):
        return
    order = np.argsort(log_ns, kind="stable")
    series.log_ns = log_ns[order]
    if series.stamp_ns is not None:
        series.stamp_ns = series.stamp_ns[order]
    if series.name_id is not None:
        series.name_id = series.name_id[order]
    for name, (flat, counts) in series.fields.items():
        starts = (np.cumsum(counts, dtype=np.int64) - counts)[order]
        counts = counts[order]
        total = int(counts.sum())
        shift = np.repeat(starts - (np.cumsum(counts, dtype=np.int64) - counts), counts)
        series.fields[name] = (flat[np.arange(total, dtype=np.int64) + shift], counts)


class Collector:
    """Streams a container's messages into per-topic columns in one pass.

    Container modules :meth:`declare` every topic (channel, connection) and
    feed the messages of the topics that can matter to the returned sink's
    ``add(log_ns, data)``; :meth:`finish` gives the :class:`Collected` that
    :func:`decode` reads. Only the built-in types of :data:`READ_TYPES` in
    ROS 1 or ROS 2 (CDR) encoding are decoded; memory grows with the decoded
    values (about 60 bytes per JointState message), not with Python objects.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.topics: dict[str, RawTopic] = {}
        self._sinks: dict[str, _Sink | None] = {}

    def declare(self, topic: RawTopic) -> _Sink | None:
        """Register ``topic``; return the sink for its messages, or None when they are not read."""
        known = self.topics.get(topic.name)
        if known is not None and known != topic:
            raise LogError(self.path, f"topic {topic.name} appears with two message types")
        self.topics[topic.name] = topic
        if topic.name not in self._sinks:
            sink_type = _SINKS.get(topic.msgtype)
            self._sinks[topic.name] = sink_type(topic) if sink_type is not None and topic.kind in (ROS1, ROS2) else None
        return self._sinks[topic.name]

    def finish(self) -> Collected:
        """Return the collected columns."""
        data = {name: sink for name, sink in self._sinks.items() if sink is not None}
        self._sinks = {}
        return Collected(self.path, dict(self.topics), data)


class Collected:
    """Topics and their decoded columns (from :meth:`Collector.finish`)."""

    def __init__(self, path: Path, topics: dict[str, RawTopic], sinks: dict[str, _Sink]) -> None:
        self.path = path
        self.topics = topics
        self._sinks = sinks
        self._series: dict[str, Series] = {}

    def series(self, name: str) -> Series:
        """The columns of topic ``name``; raises the topic's first decoding error."""
        if name in self._series:
            return self._series[name]
        topic = self.topics[name]
        if topic.kind not in (ROS1, ROS2):
            raise LogError(self.path, f"topic {topic.name} uses message encoding '{topic.kind}'; only ROS 2 CDR and ROS 1 messages can be read")
        sink = self._sinks.get(name)
        if sink is None:
            raise LogError(self.path, f"topic {topic.name} has unsupported message type {topic.msgtype}")
        if sink.error is not None:
            raise LogError(self.path, sink.error)
        series = self._series[name] = sink.finish()
        del self._sinks[name]
        return series

    def release(self, name: str) -> None:
        """Free the columns of topic ``name``."""
        self._series.pop(name, None)
        self._sinks.pop(name, None)


def decode(source: Collected, selection: Selection, path: Path) -> RunLog:
    """Build a :class:`RunLog` from the collected messages of a container.

    Parameters
    ----------
    source : Collected
        Topics and decoded columns of the file.
    selection : Selection
        Topic, reference topic and joint to read (see the module docstring).
    path : Path
        The file, named in errors.

    Returns
    -------
    RunLog
        Not yet validated (``read_log`` validates).
    """
    topics = source.topics
    meta_topic = topics.get(TOPIC_METADATA)
    if meta_topic is not None and meta_topic.msgtype == STRING and selection.topic in (None, TOPIC_STATES):
        return _decode_ilic(source, selection, path)
    return _decode_foreign(source, selection, path)


def guarded(path: Path, container: str) -> Any:
    """Context manager turning any unexpected library failure into a one-line :class:`LogError`.

    Parameters
    ----------
    path : Path
        The file named in the error.
    container : str
        Container name for the message (``"MCAP"``, ``"ROS 1 bag"``...).
    """
    import contextlib

    @contextlib.contextmanager
    def guard() -> Iterator[None]:
        try:
            yield
        except LogError:
            raise
        except MemoryError:
            raise LogError(path, f"{container} content needs more memory than available") from None
        except Exception as exc:  # noqa: BLE001 - every failure on file content is bad input
            raise LogError(path, f"cannot read {container} content ({type(exc).__name__}: {short_text(exc)})") from None

    return guard()


def decode_guarded(source: Collected, selection: Selection, path: Path, container: str) -> RunLog:
    """:func:`decode`, turning any unexpected library failure into a one-line :class:`LogError`.

    Parameters
    ----------
    source, selection, path
        As for :func:`decode`.
    container : str
        Container name for the message (``"MCAP"``, ``"ROS 1 bag"``...).
    """
    with guarded(path, container):
        return decode(source, selection, path)


def _read_metadata(source: Collected, path: Path) -> dict[str, Any]:
    series = source.series(TOPIC_METADATA)
    if len(series) == 0 or series.text is None:
        raise LogError(path, f"{TOPIC_METADATA} has no message")
    payload = parse_json_object(series.text, path, f"{TOPIC_METADATA} message")
    if payload.get("format") != FORMAT_TAG:
        raise LogError(path, f"{TOPIC_METADATA} is not ilic metadata")
    if not isinstance(payload.get("version"), int) or payload["version"] > FORMAT_VERSION:
        raise LogError(path, f"{TOPIC_METADATA} has unsupported version {payload.get('version')!r}; upgrade ilic")
    return payload


def _decode_ilic(source: Collected, selection: Selection, path: Path) -> RunLog:
    from ilic_cli.runlog import RunLog

    payload = _read_metadata(source, path)
    joint = payload.get("joint")
    if not isinstance(joint, str):
        raise LogError(path, f"{TOPIC_METADATA} has no joint name")
    if selection.joint is not None and selection.joint != joint:
        raise LogError(path, f"no joint '{selection.joint}' (joints: {joint})")
    units = parse_units(payload.get("units", {}), path)
    meta = payload.get("meta", {})
    if not isinstance(meta, dict):
        raise LogError(path, f"{TOPIC_METADATA}: meta is not a JSON object")
    if TOPIC_STATES not in source.topics or source.topics[TOPIC_STATES].msgtype != JOINT_STATE:
        raise LogError(path, f"no {TOPIC_STATES} topic of type {JOINT_STATE}")
    ref_name = selection.ref_topic or TOPIC_REFERENCE
    states = _joint_state_series(source, TOPIC_STATES, joint, path, strict=True)
    if ref_name != TOPIC_STATES:
        source.release(TOPIC_STATES)
    channels: dict[str, np.ndarray] = {}
    for channel, fieldname in STATE_FIELDS.items():
        if states[fieldname] is not None:
            channels[channel] = states[fieldname]
    n = len(states["log_ns"])
    if ref_name in source.topics:
        ref = _reference_series(source, ref_name, 0, path)
        source.release(ref_name)
        if len(ref["log_ns"]) != n:
            raise LogError(path, f"{ref_name} has {len(ref['log_ns'])} messages but {TOPIC_STATES} has {n}")
        for channel, fieldname in REFERENCE_FIELDS.items():
            if ref[fieldname] is not None:
                channels[channel] = ref[fieldname]
    elif selection.ref_topic:
        raise LogError(path, f"no topic {selection.ref_topic} (topics: {', '.join(sorted(source.topics))})")
    stamp_ns = states["stamp_ns"]
    del states
    if TOPIC_EXTRAS in source.topics:
        extras = _extras_series(source, path)
        source.release(TOPIC_EXTRAS)
        if len(extras[TIME_NAME]) != n:
            raise LogError(path, f"{TOPIC_EXTRAS} has {len(extras[TIME_NAME])} messages but {TOPIC_STATES} has {n}")
        t = extras.pop(TIME_NAME)
        channels.update(extras)
    else:
        t = stamp_ns.astype(np.float64) / 1e9
    del stamp_ns
    source.release(TOPIC_STATES)
    channels["t"] = t
    return RunLog(channels, {k: v for k, v in units.items() if k in channels}, dict(meta))


def _first(mask: np.ndarray) -> int | None:
    """Index of the first True in ``mask``, or None."""
    hits = np.flatnonzero(mask)
    return int(hits[0]) if len(hits) else None


def _extras_series(source: Collected, path: Path) -> dict[str, np.ndarray]:
    series = source.series(TOPIC_EXTRAS)
    if len(series) == 0:
        return {TIME_NAME: np.empty(0)}
    assert series.name_id is not None
    names = list(series.names[int(series.name_id[0])])
    if TIME_NAME not in names or len(set(names)) != len(names):
        raise LogError(path, f"{TOPIC_EXTRAS} names {names} must be distinct and include '{TIME_NAME}'")
    flat, counts = series.fields["position"]
    changed = _first(series.name_id != series.name_id[0])
    wrong = _first(counts != len(names))
    if changed is not None and (wrong is None or changed <= wrong):
        raise LogError(path, f"message {changed} on {TOPIC_EXTRAS} changes the channel names")
    if wrong is not None:
        raise LogError(path, f"message {wrong} on {TOPIC_EXTRAS} has {int(counts[wrong])} values for {len(names)} names")
    if len(names) == 1:
        return {names[0]: flat}
    matrix = flat.reshape(len(series), len(names))
    return {name: matrix[:, j].copy() for j, name in enumerate(names)}


def _joint_state_series(source: Collected, topic: str, joint: str | None, path: Path, *, strict: bool) -> dict[str, Any]:
    """Collect one joint's samples from a JointState topic.

    With ``strict`` every message must carry the joint; otherwise messages
    without it are skipped. ``joint=None`` picks the only joint, or raises
    listing the joints.
    """
    series = source.series(topic)
    if len(series) == 0:
        raise LogError(path, f"topic {topic} has no messages")
    assert series.name_id is not None and series.stamp_ns is not None
    # name lists in order of first appearance (in log-time order)
    if len(series.names) == 1:
        in_order = list(series.names)
    else:
        ids, first_at = np.unique(series.name_id, return_index=True)
        in_order = [series.names[int(i)] for i in ids[np.argsort(first_at, kind="stable")]]
    if joint is None:
        seen: dict[str, None] = {}
        for names in in_order:
            for name in names:
                seen.setdefault(name, None)
        joints = list(seen)
        if len(joints) > 1:
            listed = ", ".join(joints[:20]) + (", ..." if len(joints) > 20 else "")
            raise ChoiceError(path, f"topic {topic} has {len(joints)} joints ({listed}); choose one", "joint")
        joint = joints[0] if joints else ""
    # per name list: index of the joint, -1 when named without it, -2 when unnamed
    table = np.array([names.index(joint) if joint in names else (-1 if names else -2) for names in series.names], dtype=np.int64)
    pos_counts = series.fields["position"][1]
    if len(table) == 1 and table[0] >= 0:
        # one name list for every message, with the joint: no per-message index arrays
        jj = int(table[0])
        no_position = _first(pos_counts <= jj)
        if no_position is not None:
            raise LogError(path, f"message {no_position} on {topic}: no position for joint '{joint}'")
        out = {"joint": joint, "log_ns": series.log_ns, "stamp_ns": series.stamp_ns}
        for fieldname in ("position", "velocity", "effort"):
            out[fieldname] = series.values_at(fieldname, jj)
        return out
    j = table[series.name_id]
    j = np.where((j == -2) & (joint == "") & (pos_counts == 1), 0, j)
    missing_joint = _first(j == -1) if strict else None
    keep = j >= 0
    no_position = _first(keep & (pos_counts <= j))
    if missing_joint is not None and (no_position is None or missing_joint < no_position):
        raise LogError(path, f"message {missing_joint} on {topic} has no joint '{joint}'")
    if no_position is not None:
        raise LogError(path, f"message {no_position} on {topic}: no position for joint '{joint}'")
    if not keep.any():
        available = sorted({name for names in series.names for name in names})
        raise LogError(path, f"topic {topic} has no joint '{joint}' (joints: {', '.join(available) or 'none'})")
    all_kept = bool(keep.all())
    mask = None if all_kept else keep
    jk = j if all_kept else j[keep]
    out: dict[str, Any] = {
        "joint": joint,
        "log_ns": series.log_ns if all_kept else series.log_ns[keep],
        "stamp_ns": series.stamp_ns if all_kept else series.stamp_ns[keep],
    }
    for fieldname in ("position", "velocity", "effort"):
        out[fieldname] = series.values_at(fieldname, jk, mask)
    return out


def _reference_series(source: Collected, topic: str, joint_index: int | None, path: Path, joint: str | None = None) -> dict[str, Any]:
    info = source.topics[topic]
    if info.msgtype == JOINT_STATE:
        states = _joint_state_series(source, topic, joint, path, strict=False)
        return {
            "log_ns": states["log_ns"],
            "positions": states["position"],
            "velocities": states["velocity"],
            "accelerations": None,
        }
    if info.msgtype != TRAJECTORY_POINT:
        raise LogError(path, f"reference topic {topic} has type {info.msgtype}; expected {TRAJECTORY_POINT} or {JOINT_STATE}")
    series = source.series(topic)
    width = series.fields["positions"][1]
    j = np.where(width == 1, 0, -1)
    if joint_index is not None:
        j = np.where((width != 1) & (width > joint_index), joint_index, j)
    bad = _first(j < 0)
    if bad is not None:
        raise LogError(path, f"message {bad} on {topic} has {int(width[bad])} positions; cannot tell which belongs to the joint")
    out: dict[str, Any] = {"log_ns": series.log_ns}
    for fieldname in ("positions", "velocities", "accelerations"):
        out[fieldname] = series.values_at(fieldname, j)
    return out


def _choose_state_topic(source: Collected, selection: Selection, path: Path) -> str:
    topics = source.topics
    if selection.topic is not None:
        if selection.topic not in topics:
            raise LogError(path, f"no topic {selection.topic} (topics: {', '.join(sorted(topics)) or 'none'})")
        if topics[selection.topic].msgtype != JOINT_STATE:
            raise LogError(path, f"topic {selection.topic} has type {topics[selection.topic].msgtype}, not {JOINT_STATE}")
        return selection.topic
    candidates = sorted(name for name, info in topics.items() if info.msgtype == JOINT_STATE and name != TOPIC_EXTRAS)
    if len(candidates) == 1:
        return candidates[0]
    if TOPIC_STATES in candidates:
        return TOPIC_STATES
    if not candidates:
        listed = ", ".join(f"{n} ({i.msgtype})" for n, i in sorted(topics.items())) or "none"
        raise LogError(path, f"no {JOINT_STATE} topic (topics: {listed})")
    raise ChoiceError(path, f"several {JOINT_STATE} topics ({', '.join(candidates)}); choose one", "topic")


def _decode_foreign(source: Collected, selection: Selection, path: Path) -> RunLog:
    from ilic_cli.quality import nominal_rate_hz
    from ilic_cli.runlog import RunLog

    topic = _choose_state_topic(source, selection, path)
    states = _joint_state_series(source, topic, selection.joint, path, strict=False)
    joint = states["joint"]
    stamps = states["stamp_ns"]
    time_source = "header.stamp"
    if not stamps.any():
        stamps = states["log_ns"]
        time_source = "log_time"
    order = np.argsort(stamps, kind="stable")
    stamps = stamps[order]
    start = int(stamps[0])
    t = (stamps - start).astype(np.float64) / 1e9
    channels: dict[str, np.ndarray] = {"t": t}
    for channel, fieldname in STATE_FIELDS.items():
        if states[fieldname] is not None:
            channels[channel] = states[fieldname][order]
    ref_name = selection.ref_topic or (TOPIC_REFERENCE if TOPIC_REFERENCE in source.topics else None)
    if ref_name is not None:
        if ref_name not in source.topics:
            raise LogError(path, f"no topic {ref_name} (topics: {', '.join(sorted(source.topics))})")
        joint_index = _joint_index(source, topic, joint)
        ref = _reference_series(source, ref_name, joint_index, path, joint=joint)
        log_ns = states["log_ns"][order]
        for channel, fieldname in REFERENCE_FIELDS.items():
            values = ref[fieldname]
            if values is None:
                continue
            if len(values) == len(log_ns):
                channels[channel] = values[np.argsort(ref["log_ns"], kind="stable")]
            elif len(values) >= 2:
                ref_order = np.argsort(ref["log_ns"], kind="stable")
                channels[channel] = np.interp(log_ns.astype(np.float64), ref["log_ns"][ref_order].astype(np.float64), values[ref_order])
    meta: dict[str, Any] = {"joint": joint, "topic": topic, "start_time_ns": start, "time_source": time_source}
    if ref_name is not None:
        meta["ref_topic"] = ref_name
    rate = nominal_rate_hz(t)
    if rate:
        meta["sample_rate_hz"] = rate
    return RunLog(channels, {}, meta)


def _joint_index(source: Collected, topic: str, joint: str) -> int | None:
    series = source.series(topic)
    if len(series) == 0 or series.name_id is None:
        return None
    names = series.names[int(series.name_id[0])]
    return names.index(joint) if joint in names else None


def feed_sinks(reader: Any, wanted: list[Any], sinks: dict[int, Any], path: Path) -> None:
    """Stream a ``rosbags`` reader's messages of the ``wanted`` connections into their sinks.

    Drives the read's progress display (if any) every 65536 messages.
    """
    from ilic_cli.io import current_progress

    total = sum(int(getattr(conn, "msgcount", 0) or 0) for conn in wanted) or 1
    with current_progress(path) as progress:
        for done, (conn, log_ns, data) in enumerate(reader.messages(connections=wanted) if wanted else (), start=1):
            sinks[conn.id].add(log_ns, data)
            if progress is not None and done % 65536 == 0:
                progress(done, total)
        if progress is not None:
            progress(total, total)


def close_quietly(reader: Any) -> None:
    """Close a ``rosbags`` reader; a broken one's close error must not mask the real error."""
    try:
        reader.close()
    except Exception:  # noqa: BLE001, S110
        pass


def write_bag(writer: Any, log: RunLog, joint: str, kind: str) -> None:
    """Write ``log``'s messages with a not yet opened ``rosbags`` writer (ROS 1 or ROS 2).

    The writer is aborted on any failure, so that no half-written bag is closed.
    """
    topics, messages = encode(log, joint, kind)
    ts = typestore(kind)
    writer.open()
    try:
        connections = {spec.topic: writer.add_connection(spec.topic, spec.msgtype, typestore=ts) for spec in topics}
        for topic, log_ns, data in messages:
            writer.write(connections[topic], log_ns, data)
    except BaseException:
        writer.abort()
        raise
    writer.close()
