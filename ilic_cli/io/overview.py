"""What a container holds: its topics, message types, counts, rates and joints (``ilic info``'s overview).

Like ``ros2 bag info`` or ``mcap info``: from the container's summary and
indexes (``mcap``; a ROS 1 bag's index records; the counts of the read of an
sqlite3 bag just made; else ``rosbags``), plus the first message of each
``JointState``, controller-state and ``JointTrajectory`` topic for its joint names. Only called on a file that the
reader has already parsed with every check (:func:`ilic_cli.io.read_log`,
or the reader's refusal to choose a joint), so that nothing here meets an
unchecked chunk.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ilic_cli.io.rosschema import CONTROLLER_LAYOUTS, CONTROLLER_STATE, JOINT_STATE, ROS1, ROS2, TRAJECTORY, controller_typestore, normalize_msgtype, typestore

NAMED = (JOINT_STATE, CONTROLLER_STATE, TRAJECTORY)
"""Message types whose joint names the overview lists."""


@dataclass(frozen=True)
class TopicOverview:
    """One topic of a container.

    Attributes
    ----------
    topic, msgtype : str
        Its name and message type (``sensor_msgs/msg/JointState``).
    count : int
        Messages on it.
    rate_hz : float or None
        Messages per second over the container's time span.
    joints : tuple of str or None
        The joint names of its first message (``JointState``, controller-state and ``JointTrajectory`` topics).
    """

    topic: str
    msgtype: str
    count: int
    rate_hz: float | None
    joints: tuple[str, ...] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "topic": self.topic,
            "type": self.msgtype,
            "count": self.count,
            "rate_hz": self.rate_hz,
            "joints": None if self.joints is None else list(self.joints),
        }


def _rate(count: int, start_ns: int, end_ns: int) -> float | None:
    return (count - 1) / ((end_ns - start_ns) / 1e9) if count > 1 and end_ns > start_ns else None


def _joints(data: bytes, msgtype: str, kind: str) -> tuple[str, ...] | None:
    if msgtype not in NAMED:
        return None
    if kind == ROS1:
        msg = typestore(kind).deserialize_ros1(data, msgtype)
    elif msgtype != CONTROLLER_STATE:
        msg = typestore(kind).deserialize_cdr(data, msgtype)
    else:
        for layout in CONTROLLER_LAYOUTS:
            try:
                msg = controller_typestore(layout).deserialize_cdr(data, msgtype)
                break
            except Exception:  # noqa: BLE001, S112 - not this layout
                continue
        else:
            return None
    return tuple(str(n) for n in (msg.name if msgtype == JOINT_STATE else msg.joint_names))


def overview(path: Path, fmt: str) -> list[TopicOverview]:
    """The topics of an MCAP file or a ROS 1 / ROS 2 bag (an empty list for ``.mat`` and CSV)."""
    if fmt == "mcap":
        return _mcap(path)
    if fmt == "rosbag1":
        return _bag1(path)
    if fmt == "rosbag2":
        return _bag2(path)
    return []


def _mcap(path: Path) -> list[TopicOverview]:
    from mcap.reader import make_reader  # mcap (some 45 ms) deferred: `ilic info` on a bag, .mat or CSV does not load it

    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            return []
        stats = summary.statistics
        out = []
        for cid, channel in sorted(summary.channels.items()):
            schema = summary.schemas.get(channel.schema_id)
            msgtype = normalize_msgtype(schema.name) if schema is not None else "(no schema)"
            count = int(stats.channel_message_counts.get(cid, 0))
            joints = None
            if msgtype in NAMED and count:
                ids = {other for other, c in summary.channels.items() if c.topic == channel.topic}
                data = _first_data(stream, summary, ids, path)
                if data is None:  # the indexes do not say: the reader's own walk
                    first = next(iter(reader.iter_messages(topics=[channel.topic])), None)
                    data = None if first is None else bytes(first[2].data)
                joints = None if data is None else _joints(data, msgtype, ROS2)
            out.append(TopicOverview(channel.topic, msgtype, count, _rate(count, stats.message_start_time, stats.message_end_time), joints))
    return out


MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")
"""A message index record's opcode, length, channel id and length of its entries (each a log time and an offset, ``<u8`` both)."""


def _first_data(stream: Any, summary: Any, ids: set[int], path: Path) -> bytes | None:
    """The data of the first message of channels ``ids`` as ``mcap``'s reader yields it (least log time, then chunk, then place in it).

    The reader breaks a whole chunk into one object per record to find it
    (some 0.2 s a topic for a 1 kHz log); here the chunks are taken in the
    reader's order from the chunk indexes, the channels' message indexes give
    the candidates, and the one chunk holding the first is decompressed and
    read at that offset. None when a record is not as its index says (the
    caller asks the reader instead).
    """
    from mcap.data_stream import ReadDataStream  # mcap deferred, as in _mcap
    from mcap.records import Chunk  # the same

    # the MCAP reader imports mcap, zstandard and lz4: deferred so that `ilic info` on another format does not load them
    from ilic_cli.io.mcaplog import MAX_CHUNK_BYTES, MAX_EXPANSION, _decompress

    chunks = sorted((ci for ci in summary.chunk_indexes if ids & set(ci.message_index_offsets)), key=lambda ci: (ci.message_start_time, ci.chunk_start_offset))
    best: tuple[int, int, int, Any] | None = None  # log time, chunk offset, offset in the chunk, its chunk index
    for ci in chunks:
        if best is not None and (ci.message_start_time, ci.chunk_start_offset) > best[:2]:
            break  # every message of this chunk and the ones after comes later
        for cid in sorted(ids & set(ci.message_index_offsets)):
            stream.seek(ci.message_index_offsets[cid])
            head = stream.read(MESSAGE_INDEX_HEAD.size)
            if len(head) != MESSAGE_INDEX_HEAD.size:
                return None
            opcode, length, channel_id, size = MESSAGE_INDEX_HEAD.unpack(head)
            if opcode != 0x07 or channel_id != cid or size % 16 or length != 6 + size or size > ci.message_index_length:
                return None
            body = stream.read(size)
            if len(body) != size:
                return None
            if not size:
                continue
            log_ns, offset = min(struct.iter_unpack("<QQ", body))  # a chunk's entries: a few thousand
            candidate = (log_ns, ci.chunk_start_offset, offset, ci)
            if best is None or candidate[:3] < best[:3]:
                best = candidate
    if best is None:
        return None
    log_ns, chunk_offset, offset, ci = best
    stream.seek(chunk_offset + 1 + 8)
    records = _decompress(Chunk.read(ReadDataStream(stream)), min(MAX_CHUNK_BYTES, MAX_EXPANSION * max(path.stat().st_size, 1)), path)
    if offset + 31 > len(records):
        return None
    opcode, length, channel_id, _, log_time = struct.unpack_from("<BQHIQ", records, offset)
    if opcode != 0x05 or channel_id not in ids or log_time != log_ns or offset + 9 + length > len(records) or length < 22:
        return None
    return bytes(records[offset + 31 : offset + 9 + length])


def _bag1(path: Path) -> list[TopicOverview]:
    """A ROS 1 bag's topics from its index records (:func:`ilic_cli.io.ros1fast.summary`); through ``rosbags`` when that reader does not take the file.

    ``rosbags``' reader builds an object per message when it opens a bag
    (some 5 s of a 600 s, 1 kHz log); the summary reads the same counts,
    time range and first messages from the index without them.
    """
    # the ROS 1 reader imports rosbags at its top: deferred so that `ilic info` on another format does not load rosbags
    from ilic_cli.io import ros1fast
    from ilic_cli.io.rosbag1 import MAX_CHUNK_BYTES, MAX_EXPANSION

    try:
        bag = ros1fast.summary(path)
    except ros1fast.Fallback:
        return _bag(path)
    limit = min(MAX_CHUNK_BYTES, MAX_EXPANSION * max(path.stat().st_size, 1))
    out = []
    for conn in sorted(bag.connections, key=lambda c: (c.topic, c.id)):
        msgtype = normalize_msgtype(conn.msgtype)
        count = bag.counts[conn.id]
        joints = None
        if msgtype in NAMED and count:
            try:
                joints = _joints(ros1fast.message_at(path, *bag.first[conn.id], limit), msgtype, ROS1)
            except ros1fast.Fallback:
                return _bag(path)
        out.append(TopicOverview(conn.topic, msgtype, count, _rate(count, bag.start_ns, bag.end_ns), joints))
    return out


def _bag2(path: Path) -> list[TopicOverview]:
    """A ROS 2 bag's topics: of an sqlite3 bag just read off its pages, from that read's counts; else ``rosbags``.

    The counts are :func:`~ilic_cli.io.ros2sqlite.table_summary`.

    ``rosbags`` counts each topic's messages when it opens an sqlite3 bag (a
    scan of the table: some 0.9 s of a 600 s, 1 kHz bag); the read counted them.
    """
    # rosbags.rosbag2 (some 0.3 s) and the sqlite3 reader, deferred: `ilic info` on another format does not load them
    from rosbags.rosbag2 import Reader

    from ilic_cli.io import ros2sqlite  # imports rosbags' sqlite3 storage at its top: deferred as rosbags.rosbag2 is

    files = sorted(path.glob("*.db3"))
    summary = ros2sqlite.table_summary(files[0]) if len(files) == 1 else None
    if summary is None:
        return _bag(path)
    reader = Reader(path)
    with ros2sqlite.rosbags_sqlite_settings(uncounted=True):  # the topics only: the counts are the read's
        reader.open()
    try:
        storage = ros2sqlite.single_sqlite(reader)
        if storage is None or storage.path.resolve() != files[0].resolve():
            return _bag(path)
        out = []
        for conn in sorted(reader.connections, key=lambda c: (c.topic, c.id)):
            msgtype = normalize_msgtype(conn.msgtype)
            count = summary.counts.get(int(conn.id), 0)
            joints = _joints(summary.first[int(conn.id)], msgtype, ROS2) if msgtype in NAMED and count else None
            out.append(TopicOverview(conn.topic, msgtype, count, _rate(count, summary.start_ns, summary.end_ns), joints))
    finally:
        reader.close()
    return out


def _bag(path: Path) -> list[TopicOverview]:
    from rosbags.highlevel import AnyReader  # rosbags deferred: only a bag the fast summaries do not take reads through it

    with AnyReader([path]) as reader:
        kind = ROS1 if reader.is2 is False else ROS2
        firsts = _mcap_storage_firsts(path) if kind == ROS2 else None
        out = []
        for conn in sorted(reader.connections, key=lambda c: (c.topic, c.id)):
            msgtype = normalize_msgtype(conn.msgtype)
            joints = None
            if msgtype in NAMED and conn.msgcount:
                data = None if firsts is None else firsts(conn.topic)
                if data is None:  # rosbags' walk: a chunk broken into its records
                    first = next(iter(reader.messages(connections=[conn])), None)
                    data = None if first is None else bytes(first[2])
                joints = None if data is None else _joints(data, msgtype, kind)
            out.append(TopicOverview(conn.topic, msgtype, int(conn.msgcount), _rate(int(conn.msgcount), reader.start_time, reader.end_time), joints))
    return out


def _mcap_storage_firsts(path: Path) -> Any:
    """For a ROS 2 bag folder whose only storage file is one ``.mcap``: ``first(topic)`` -> its first message's data (:func:`_first_data`), or None.

    ``rosbags``' MCAP storage yields a topic's messages in the order of
    ``mcap``'s reader (log time, then chunk, then place in the chunk); it
    finds the first by breaking a whole chunk into its records (some 0.1 s a
    topic for a 1 kHz bag). None (``rosbags`` is asked) for another folder,
    or a topic on more than one channel of the file.
    """
    from mcap.reader import make_reader  # mcap deferred, as in _mcap

    files = sorted(path.glob("*.mcap")) if path.is_dir() else []
    if len(files) != 1 or sorted(path.glob("*.db3")):
        return None
    with open(files[0], "rb") as stream:
        summary = make_reader(stream).get_summary()
    if summary is None:
        return None
    by_topic: dict[str, set[int]] = {}
    for cid, channel in summary.channels.items():
        by_topic.setdefault(channel.topic, set()).add(cid)

    def first(topic: str) -> bytes | None:
        ids = by_topic.get(topic, set())
        if len(ids) != 1:
            return None
        with open(files[0], "rb") as stream:
            return _first_data(stream, summary, ids, files[0])

    return first
