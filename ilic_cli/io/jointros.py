"""n-joint logs (:class:`ilic_cli.jointlog.JointLog`) in ROS containers: ROS 2 bag folders and ROS 1 ``.bag`` files, written and read; MCAP files read.

A ROS 2 bag folder has sqlite3 or MCAP storage.

The messages (:mod:`ilic_cli.io.jointlogs`' docstring) are the same in every container
(:func:`ros_messages`): ROS 2 Humble's types in a ROS 2 bag, ROS 1 Noetic's in a
ROS 1 bag (whose headers carry a sequence number), each written by rosbags' own
writer. Reading goes through rosbags' ``AnyReader`` (a bag folder, a ROS 1 bag)
or the ``mcap`` reader (an MCAP file); joints are read by name. A ROS 2 bag of one
sqlite3 file whose topics each keep one layout is read as columns (:func:`_sqlite_columns`).
"""

from __future__ import annotations

import contextlib
import json
import struct
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io import cdrcols, rosschema
from ilic_cli.io.jointparts import METADATA, REFERENCE, STATES, is_joints_metadata, joint_log, joint_types, stored_metadata
from ilic_cli.io.rosschema import JOINT_STATE, STRING, TRAJECTORY
from ilic_cli.jointlog import REFERENCES, JointLog


def ros_messages(log: JointLog, path: Path, ts: Any, ros1: bool) -> tuple[list[tuple[str, str]], Any]:
    """The topics ``(name, msgtype)`` of ``log`` written to ``path`` and an iterator of its messages ``(topic, log time ns, message)`` in the type store ``ts``.

    ``ros1``: the headers carry a sequence number (ROS 1 Noetic's ``std_msgs/Header``).
    """
    JointState, Header, Time = ts.types[JOINT_STATE], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    Trajectory, Point, Duration = ts.types[TRAJECTORY], ts.types["trajectory_msgs/msg/JointTrajectoryPoint"], ts.types["builtin_interfaces/msg/Duration"]
    topics = [(STATES, JOINT_STATE)] + ([(REFERENCE, TRAJECTORY)] if log.has_reference else []) + [(METADATA, STRING)]
    stamps = np.round(log.t * 1e9).astype(np.int64)
    if stamps[0] < 0:
        raise LogError(path, f"time starts at {log.t[0]:g} s: a ROS time stamp is unsigned")
    names = list(log.joints)
    zeros = np.zeros(log.n)

    def messages() -> Any:
        yield METADATA, int(stamps[0]), ts.types[STRING](data=json.dumps(stored_metadata(log), sort_keys=True, default=str))
        for k, ns in enumerate(stamps.tolist()):
            stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
            header = Header(seq=k, stamp=stamp, frame_id="") if ros1 else Header(stamp=stamp, frame_id="")
            yield STATES, ns, JointState(header=header, name=names, position=log.q[:, k].copy(), velocity=zeros, effort=log.tau[:, k].copy())
            if log.has_reference:
                assert log.q_ref is not None and log.qd_ref is not None and log.qdd_ref is not None
                point = Point(
                    positions=log.q_ref[:, k].copy(),
                    velocities=log.qd_ref[:, k].copy(),
                    accelerations=log.qdd_ref[:, k].copy(),
                    effort=np.zeros(0),
                    time_from_start=Duration(sec=0, nanosec=0),
                )
                yield REFERENCE, ns, Trajectory(header=header, joint_names=names, points=[point])

    return topics, messages()


def write_bag(log: JointLog, path: Path, storage: str) -> None:
    """A ROS 2 bag folder (``storage``: ``sqlite3`` or ``mcap``) written message by message with rosbags' writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer  # deferred: rosbags' writer is needed only to write a bag

    ts = rosschema.typestore(rosschema.ROS2)  # Humble's types that ilic writes
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    topics, messages = ros_messages(log, path, ts, ros1=False)
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {topic: (writer.add_connection(topic, msgtype, typestore=ts), msgtype) for topic, msgtype in topics}
        for topic, ns, msg in messages:
            connection, msgtype = connections[topic]
            writer.write(connection, ns, ts.serialize_cdr(msg, msgtype))


def write_bag1(log: JointLog, path: Path) -> None:
    """A ROS 1 bag (``.bag``, ROS 1 Noetic types) written message by message with rosbags' writer (uncompressed chunks)."""
    from rosbags.rosbag1 import Writer  # deferred: rosbags' writer is needed only to write a bag

    ts = rosschema.typestore(rosschema.ROS1)
    topics, messages = ros_messages(log, path, ts, ros1=True)
    if int(np.round(log.t[-1] * 1e9)) // 1_000_000_000 > 2**31 - 1:
        raise LogError(path, "time stamps too large for ROS 1 time (beyond 2038)")
    with Writer(path) as writer:
        connections = {topic: (writer.add_connection(topic, msgtype, typestore=ts), msgtype) for topic, msgtype in topics}
        for topic, ns, msg in messages:
            connection, msgtype = connections[topic]
            writer.write(connection, ns, ts.serialize_ros1(msg, msgtype))


def _messages(path: Path) -> tuple[list[tuple[str, str]], Any]:
    """The topics ``(name, msgtype)`` and an iterator of ``(topic, msgtype, log time ns, message)`` of a bag folder, a ROS 1 bag or an MCAP file."""
    from rosbags.typesys import Stores, get_typestore  # deferred: rosbags' type store, only to read ROS logs

    ts = get_typestore(Stores.ROS2_HUMBLE)
    if path.is_dir() or path.suffix.lower() == ".bag":  # a ROS 1 bag's types are its own (rosbags converts its messages)
        from rosbags.highlevel import AnyReader  # deferred: with the type store

        reader = AnyReader([path], default_typestore=ts)
        reader.open()
        topics = [(c.topic, c.msgtype) for c in reader.connections]

        def bag() -> Any:
            try:
                for c, ns, raw in reader.messages():
                    yield c.topic, c.msgtype, ns, reader.deserialize(raw, c.msgtype)
            finally:
                reader.close()

        return topics, bag()
    from mcap.reader import make_reader  # deferred: an MCAP file only

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None:
        raise LogError(path, "an MCAP file without a summary")
    topics = [(ch.topic, summary.schemas[ch.schema_id].name) for ch in summary.channels.values()]

    def mcap() -> Any:
        with path.open("rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
                if schema is not None:  # a channel without a schema holds no ROS message
                    yield channel.topic, schema.name, message.log_time, ts.deserialize_cdr(message.data, schema.name)

    return topics, mcap()


def _unreadable(path: Path, exc: Exception) -> LogError:
    """A ROS log that rosbags or mcap cannot read, in one line."""
    return LogError(path, f"cannot read the ROS log: {str(exc).strip() or type(exc).__name__}")


def read_ros(path: Path, kinds: Mapping[str, str] | None = None, joints: Sequence[str] | None = None) -> JointLog:
    """A JointState log (see the module's docstring); ``joints``: the names wanted (checked on the first message).

    A ROS 2 bag folder of one sqlite3 file whose topics each keep one message layout is read as columns
    (:func:`_sqlite_columns`); any other log message by message.
    """
    if path.is_dir():
        fast = _sqlite_columns(path, kinds, joints)
        if fast is not None:
            return fast
    try:
        topics, messages = _messages(path)
    except LogError:
        raise
    except Exception as exc:  # rosbags and mcap raise their own error types for a damaged file
        raise _unreadable(path, exc) from None
    state_topics = [t for t, m in topics if m == JOINT_STATE]
    if not state_topics:
        raise LogError(path, "no sensor_msgs/msg/JointState topic")
    topic = STATES if STATES in state_topics else state_topics[0]
    if len(state_topics) > 1 and topic != STATES:
        raise LogError(path, f"several JointState topics ({', '.join(state_topics)}) and none is {STATES}")
    t: list[int] = []
    q: list[np.ndarray] = []
    tau: list[np.ndarray] = []
    ref: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    names: list[str] = []
    meta: dict[str, Any] = {}
    order: np.ndarray | None = None
    try:
        for tp, _, ns, msg in messages:
            if tp == METADATA:
                meta = json.loads(msg.data)
            elif tp == topic:
                if order is None:
                    names = list(joints) if joints is not None else list(msg.name)
                    missing = [j for j in names if j not in msg.name]
                    if missing:
                        raise LogError(path, f"no joint {', '.join(missing)} in {topic} (it has {', '.join(msg.name)})")
                    order = np.array([list(msg.name).index(j) for j in names])
                if len(msg.effort) < len(msg.name):
                    raise LogError(path, f"{topic} has no effort for its joints (a log without effort)")
                t.append(ns if msg.header.stamp is None else msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
                q.append(msg.position[order])
                tau.append(msg.effort[order])
            elif tp == REFERENCE and msg.points:
                p = msg.points[0]
                idx = [list(msg.joint_names).index(j) for j in names] if names and set(names) <= set(msg.joint_names) else None
                if idx is not None:
                    ref.append((p.positions[idx], p.velocities[idx], p.accelerations[idx]))
    except LogError:
        raise
    except Exception as exc:  # a damaged message or chunk past the index, metadata that is not JSON
        raise _unreadable(path, exc) from None
    if order is None:
        raise LogError(path, f"{topic} holds no message")
    if not isinstance(meta, dict):
        raise LogError(path, f"{METADATA} is not a JSON object")
    refs: dict[str, np.ndarray | None] = dict.fromkeys(REFERENCES)
    if len(ref) == len(t):
        refs = {r: np.array([x[i] for x in ref]).T for i, r in enumerate(REFERENCES)}
    types, kept = joint_types(names, dict(meta.get("joints") or []), kinds, meta.get("meta") or {})
    found = {"q": dict(zip(names, np.array(q).T)), "tau": dict(zip(names, np.array(tau).T))}
    return joint_log(path, np.array(t, dtype=np.float64) * 1e-9, names, types, found, refs, kept)


def declares_joints(path: Path) -> bool:
    """True when the ROS log's ``/ilic/metadata`` declares its joints (:func:`ilic_cli.io.jointparts.is_joints_metadata`); else False, readable or not.

    Its first message is read raw (a ``std_msgs/String``'s length and bytes), without rosbags' type store: telling a
    one-joint log apart costs the one-joint chain little.
    """
    try:
        text = _metadata_text(path)
        payload = None if text is None else json.loads(text)
    except Exception:  # noqa: BLE001 - an unreadable log is not an n-joint one: its reader says what is wrong
        return False
    return isinstance(payload, dict) and is_joints_metadata(payload)


def _metadata_text(path: Path) -> str | None:
    """The text of the first ``/ilic/metadata`` message of an MCAP file, a ROS 1 bag or a ROS 2 bag folder (None: it has none)."""
    if path.is_dir():
        dbs, mcaps = sorted(path.glob("*.db3")), sorted(path.glob("*.mcap"))
        if len(dbs) + len(mcaps) == 1:  # one uncompressed storage file: read directly (rosbags' metadata.yaml parse costs 10-20 ms)
            return _sqlite_metadata(dbs[0]) if dbs else _mcap_metadata(mcaps[0])
        from rosbags.rosbag2 import Reader as Reader2  # deferred: a bag folder only

        with Reader2(path) as bag:
            connections = [c for c in bag.connections if c.topic == METADATA and c.msgtype == STRING]
            return next((cdr_string(raw) for _, _, raw in bag.messages(connections=connections)), None) if connections else None
    if path.suffix.lower() == ".bag":
        from rosbags.rosbag1 import Reader as Reader1  # deferred: a ROS 1 bag only

        with Reader1(path) as bag:
            connections = [c for c in bag.connections if c.topic == METADATA and c.msgtype == STRING]
            for _, _, raw in bag.messages(connections=connections) if connections else ():
                (length,) = struct.unpack_from("<I", raw)
                return bytes(raw[4 : 4 + length]).decode()
            return None
    return _mcap_metadata(path)


def _mcap_metadata(path: Path) -> str | None:
    """The text of the first ``/ilic/metadata`` message of an MCAP file (None: it has none)."""
    from mcap.reader import make_reader  # deferred: an MCAP file only

    with path.open("rb") as f:
        return next((cdr_string(m.data) for _, _, m in make_reader(f).iter_messages(topics=[METADATA])), None)


def _sqlite_metadata(path: Path) -> str | None:
    """The text of the first ``/ilic/metadata`` message of a ROS 2 bag's sqlite3 storage (None: it has none)."""
    import sqlite3  # deferred: a ROS 2 sqlite3 bag only (its reader imports it too)

    with contextlib.closing(sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)) as db:
        return _sqlite_metadata_in(db)


def _sqlite_metadata_in(db: Any) -> str | None:
    """The text of the first ``/ilic/metadata`` message in an open ROS 2 sqlite3 storage (None: it has none)."""
    query = "SELECT m.data FROM messages m JOIN topics t ON m.topic_id = t.id WHERE t.name = ? AND t.type = ? ORDER BY m.timestamp, m.id LIMIT 1"
    row = db.execute(query, (METADATA, STRING)).fetchone()
    return None if row is None else cdr_string(bytes(row[0]))


def cdr_string(raw: bytes) -> str:
    """A ``std_msgs/msg/String`` in CDR: the encapsulation header (its second byte: 1 little endian), the length with the NUL, the bytes."""
    (length,) = struct.unpack_from("<I" if raw[1] & 1 else ">I", raw, 4)
    return bytes(raw[8 : 8 + length - 1]).decode()


def _sqlite_columns(path: Path, kinds: Mapping[str, str] | None, joints: Sequence[str] | None) -> JointLog | None:
    """A ROS 2 sqlite3 bag read as columns: the same log as :func:`read_ros`'s message by message, or None.

    Each topic's messages are fetched in one query; when they all have the first one's size and its bytes wherever
    it holds no value (:func:`ilic_cli.io.cdrcols.layout`: the names, lengths, padding), the stamps and values are strided views of the
    joined blobs (a 10-minute 6-joint bag: some 40 times faster). None for anything else (several storage files, another
    layout, a topic the per-message reader would refuse or read otherwise): that reader takes it and says what is wrong.
    """
    try:
        return _sqlite_read(path, kinds, joints)
    except Exception:  # noqa: BLE001 - the per-message reader reads it again and names the problem in one line
        return None


def _sqlite_read(path: Path, kinds: Mapping[str, str] | None, joints: Sequence[str] | None) -> JointLog | None:
    import sqlite3  # deferred: a ROS 2 sqlite3 bag only (its reader imports it too)

    dbs = sorted(path.glob("*.db3"))
    if len(dbs) != 1 or any(path.glob("*.mcap")) or any(path.glob("*.zstd")):
        return None
    with contextlib.closing(sqlite3.connect(f"{dbs[0].resolve().as_uri()}?mode=ro", uri=True)) as db:
        topics = {name: (tid, kind) for tid, name, kind in db.execute("SELECT id, name, type FROM topics")}
        states = [name for name, (_, kind) in topics.items() if kind == JOINT_STATE]
        if STATES in states:
            states = [STATES]
        if len(states) != 1:
            return None

        def rows(name: str) -> tuple[np.ndarray, np.ndarray] | None:
            got = db.execute("SELECT timestamp, data FROM messages WHERE topic_id = ? ORDER BY timestamp, id", (topics[name][0],)).fetchall()
            sizes = {len(d) for _, d in got}
            if not got or len(sizes) != 1:
                return None
            return np.array([ts for ts, _ in got], dtype=np.int64), np.frombuffer(b"".join(d for _, d in got), dtype=np.uint8).reshape(len(got), -1)

        state = rows(states[0])
        text = _sqlite_metadata_in(db)
        reference = rows(REFERENCE) if topics.get(REFERENCE, (0, ""))[1] == TRAJECTORY else None
    if state is None:
        return None
    log_ns, buf = state
    lay = _one_layout(buf, JOINT_STATE)
    if lay is None:
        return None
    name = lay.strings["name"]
    names = list(joints) if joints is not None else list(name)
    (p_at, p_n), (e_at, e_n) = lay.arrays["position"], lay.arrays["effort"]
    if any(j not in name for j in names) or e_n < len(name) or p_n < len(name):
        return None
    order = np.array([name.index(j) for j in names], dtype=np.intp)
    meta = json.loads(text) if text is not None else {}
    if not isinstance(meta, dict):
        return None
    refs: dict[str, np.ndarray | None] = dict.fromkeys(REFERENCES)
    if reference is not None and len(reference[0]) == len(log_ns) and reference[0][0] >= log_ns[0]:
        ref_lay = _one_layout(reference[1], TRAJECTORY)
        if ref_lay is None or not set(names) <= set(ref_lay.strings["joint_names"]):
            return None
        idx = np.array([list(ref_lay.strings["joint_names"]).index(j) for j in names], dtype=np.intp)
        refs = {r: _values(reference[1], *ref_lay.arrays[f])[:, idx].T.copy() for r, f in zip(REFERENCES, ("positions", "velocities", "accelerations"))}
    ns = cdrcols.times_ns(buf.reshape(-1), lay.times["stamp"], lay.size, len(buf))
    found = {"q": dict(zip(names, _values(buf, p_at, p_n)[:, order].T)), "tau": dict(zip(names, _values(buf, e_at, e_n)[:, order].T))}
    types, kept = joint_types(names, dict(meta.get("joints") or []), kinds, meta.get("meta") or {})
    return joint_log(path, ns.astype(np.float64) * 1e-9, names, types, found, refs, kept)


def _values(buf: np.ndarray, at: int, n: int) -> np.ndarray:
    """The ``n`` float64 values at byte ``at`` of every message (rows of ``buf``), as a (messages, n) view."""
    return cdrcols.column(buf.reshape(-1), at, buf.shape[1], len(buf), "<f8", n, copy=False)


def _one_layout(buf: np.ndarray, msgtype: str) -> cdrcols.Layout | None:
    """The first message's layout (:func:`ilic_cli.io.cdrcols.layout`) when every message (row of ``buf``) keeps it, else None."""
    lay = cdrcols.layout(bytes(buf[0]), msgtype)
    return lay if lay is not None and cdrcols.matching_rows(buf.reshape(-1), 0, buf.shape[1], len(buf), lay) == len(buf) else None
