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
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ilic_cli.errors import LogError

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


class RawSource(Protocol):
    """What a container module hands to :func:`decode`."""

    topics: Mapping[str, RawTopic]

    def messages(self, topic: str) -> Iterable[tuple[int, bytes]]:
        """Yield ``(log_time_ns, raw bytes)`` of ``topic`` in log-time order."""
        ...


def _decoder(topic: RawTopic, path: Path) -> Any:
    if topic.kind not in (ROS1, ROS2):
        raise LogError(path, f"topic {topic.name} uses message encoding '{topic.kind}'; only ROS 2 CDR and ROS 1 messages can be read")
    ts = typestore(topic.kind)
    if topic.msgtype not in ts.types:
        raise LogError(path, f"topic {topic.name} has unsupported message type {topic.msgtype}")
    fn = ts.deserialize_ros1 if topic.kind == ROS1 else ts.deserialize_cdr
    msgtype = topic.msgtype

    def decode_one(data: bytes) -> Any:
        return fn(data, msgtype)

    return decode_one


def _iter_decoded(source: RawSource, name: str, path: Path) -> Iterator[tuple[int, int, Any]]:
    topic = source.topics[name]
    decode_one = _decoder(topic, path)
    for index, (log_ns, data) in enumerate(source.messages(name)):
        try:
            msg = decode_one(data)
        except Exception as exc:  # noqa: BLE001 - any decoding failure is bad input
            raise LogError(path, f"message {index} on {name} cannot be decoded as {topic.msgtype} ({type(exc).__name__}: {_short(exc)})") from None
        yield index, int(log_ns), msg


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:160] + ("..." if len(text) > 160 else "")


def _stamp_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _field_value(values: Any, index: int) -> float | None:
    if values is None or len(values) <= index:
        return None
    return float(values[index])


def decode(source: RawSource, selection: Selection, path: Path) -> RunLog:
    """Build a :class:`RunLog` from the messages of a container.

    Parameters
    ----------
    source : RawSource
        Topics and raw messages of the file.
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


def decode_guarded(source: RawSource, selection: Selection, path: Path, container: str) -> RunLog:
    """:func:`decode`, turning any unexpected library failure into a one-line :class:`LogError`.

    Parameters
    ----------
    source, selection, path
        As for :func:`decode`.
    container : str
        Container name for the message (``"MCAP"``, ``"ROS 1 bag"``...).
    """
    try:
        return decode(source, selection, path)
    except LogError:
        raise
    except MemoryError:
        raise LogError(path, f"{container} content needs more memory than available") from None
    except Exception as exc:  # noqa: BLE001 - every failure on file content is bad input
        raise LogError(path, f"cannot read {container} content ({type(exc).__name__}: {_short(exc)})") from None


def _read_metadata(source: RawSource, path: Path) -> dict[str, Any]:
    for _, _, msg in _iter_decoded(source, TOPIC_METADATA, path):
        payload = parse_json_object(msg.data, path, f"{TOPIC_METADATA} message")
        if payload.get("format") != FORMAT_TAG:
            raise LogError(path, f"{TOPIC_METADATA} is not ilic metadata")
        if not isinstance(payload.get("version"), int) or payload["version"] > FORMAT_VERSION:
            raise LogError(path, f"{TOPIC_METADATA} has unsupported version {payload.get('version')!r}; upgrade ilic")
        return payload
    raise LogError(path, f"{TOPIC_METADATA} has no message")


def _decode_ilic(source: RawSource, selection: Selection, path: Path) -> RunLog:
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
    states = _joint_state_series(source, TOPIC_STATES, joint, path, strict=True)
    channels: dict[str, np.ndarray] = {}
    for channel, fieldname in STATE_FIELDS.items():
        if states[fieldname] is not None:
            channels[channel] = states[fieldname]
    n = len(states["log_ns"])
    ref_name = selection.ref_topic or TOPIC_REFERENCE
    if ref_name in source.topics:
        ref = _reference_series(source, ref_name, 0, path)
        if len(ref["log_ns"]) != n:
            raise LogError(path, f"{ref_name} has {len(ref['log_ns'])} messages but {TOPIC_STATES} has {n}")
        for channel, fieldname in REFERENCE_FIELDS.items():
            if ref[fieldname] is not None:
                channels[channel] = ref[fieldname]
    elif selection.ref_topic:
        raise LogError(path, f"no topic {selection.ref_topic} (topics: {', '.join(sorted(source.topics))})")
    t = states["stamp_ns"].astype(np.float64) / 1e9
    if TOPIC_EXTRAS in source.topics:
        extras = _extras_series(source, path)
        if len(extras[TIME_NAME]) != n:
            raise LogError(path, f"{TOPIC_EXTRAS} has {len(extras[TIME_NAME])} messages but {TOPIC_STATES} has {n}")
        t = extras.pop(TIME_NAME)
        channels.update(extras)
    channels["t"] = t
    return RunLog(channels, {k: v for k, v in units.items() if k in channels}, dict(meta))


def _extras_series(source: RawSource, path: Path) -> dict[str, np.ndarray]:
    names: list[str] | None = None
    rows: list[np.ndarray] = []
    for index, _, msg in _iter_decoded(source, TOPIC_EXTRAS, path):
        if names is None:
            names = list(msg.name)
            if TIME_NAME not in names or len(set(names)) != len(names):
                raise LogError(path, f"{TOPIC_EXTRAS} names {names} must be distinct and include '{TIME_NAME}'")
        elif list(msg.name) != names:
            raise LogError(path, f"message {index} on {TOPIC_EXTRAS} changes the channel names")
        if len(msg.position) != len(names):
            raise LogError(path, f"message {index} on {TOPIC_EXTRAS} has {len(msg.position)} values for {len(names)} names")
        rows.append(np.asarray(msg.position, dtype=np.float64))
    if names is None:
        return {TIME_NAME: np.empty(0)}
    matrix = np.vstack(rows)
    return {name: matrix[:, j].copy() for j, name in enumerate(names)}


def _joint_state_series(source: RawSource, topic: str, joint: str | None, path: Path, *, strict: bool) -> dict[str, Any]:
    """Collect one joint's samples from a JointState topic.

    With ``strict`` every message must carry the joint; otherwise messages
    without it are skipped. ``joint=None`` picks the only joint, or raises
    listing the joints.
    """
    decoded = list(_iter_decoded(source, topic, path))
    if not decoded:
        raise LogError(path, f"topic {topic} has no messages")
    if joint is None:
        seen: dict[str, None] = {}
        for _, _, msg in decoded:
            for name in msg.name:
                seen.setdefault(str(name), None)
        joints = list(seen)
        if len(joints) > 1:
            listed = ", ".join(joints[:20]) + (", ..." if len(joints) > 20 else "")
            raise LogError(path, f"topic {topic} has {len(joints)} joints ({listed}); choose one with --joint")
        joint = joints[0] if joints else ""
    log_ns: list[int] = []
    stamp_ns: list[int] = []
    values: dict[str, list[float | None]] = {"position": [], "velocity": [], "effort": []}
    for index, log_time, msg in decoded:
        names = [str(x) for x in msg.name]
        if names:
            if joint not in names:
                if strict:
                    raise LogError(path, f"message {index} on {topic} has no joint '{joint}'")
                continue
            j = names.index(joint)
        elif joint == "" and len(msg.position) == 1:
            j = 0
        else:
            continue
        pos = _field_value(msg.position, j)
        if pos is None:
            raise LogError(path, f"message {index} on {topic}: no position for joint '{joint}'")
        values["position"].append(pos)
        values["velocity"].append(_field_value(msg.velocity, j))
        values["effort"].append(_field_value(msg.effort, j))
        log_ns.append(log_time)
        stamp_ns.append(_stamp_ns(msg))
    if not log_ns:
        available = sorted({str(n) for _, _, m in decoded for n in m.name})
        raise LogError(path, f"topic {topic} has no joint '{joint}' (joints: {', '.join(available) or 'none'})")
    out: dict[str, Any] = {"joint": joint, "log_ns": np.asarray(log_ns, dtype=np.int64), "stamp_ns": np.asarray(stamp_ns, dtype=np.int64)}
    for fieldname, vals in values.items():
        out[fieldname] = None if any(v is None for v in vals) else np.asarray(vals, dtype=np.float64)
    return out


def _reference_series(source: RawSource, topic: str, joint_index: int | None, path: Path, joint: str | None = None) -> dict[str, Any]:
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
    log_ns: list[int] = []
    values: dict[str, list[float | None]] = {"positions": [], "velocities": [], "accelerations": []}
    for index, log_time, msg in _iter_decoded(source, topic, path):
        width = len(msg.positions)
        if width == 1:
            j = 0
        elif joint_index is not None and width > joint_index:
            j = joint_index
        else:
            raise LogError(path, f"message {index} on {topic} has {width} positions; cannot tell which belongs to the joint")
        for fieldname in values:
            values[fieldname].append(_field_value(getattr(msg, fieldname), j))
        log_ns.append(log_time)
    out: dict[str, Any] = {"log_ns": np.asarray(log_ns, dtype=np.int64)}
    for fieldname, vals in values.items():
        out[fieldname] = None if (not vals or any(v is None for v in vals)) else np.asarray(vals, dtype=np.float64)
    return out


def _choose_state_topic(source: RawSource, selection: Selection, path: Path) -> str:
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
    raise LogError(path, f"several {JOINT_STATE} topics ({', '.join(candidates)}); choose one with --topic")


def _decode_foreign(source: RawSource, selection: Selection, path: Path) -> RunLog:
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
        joint_index = _joint_index(source, topic, joint, path)
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


def _joint_index(source: RawSource, topic: str, joint: str, path: Path) -> int | None:
    for _, _, msg in _iter_decoded(source, topic, path):
        names = [str(x) for x in msg.name]
        return names.index(joint) if joint in names else None
    return None
