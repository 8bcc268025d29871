"""Vectorised reading of ROS 1 bags (format 2.0): the index, the topic overview and every message as columns.

Reading (:func:`collect`) walks the chunks listed in the bag's index, one
decompressed chunk at a time, with :class:`ilic_cli.io.ros1chunks._ChunkWalker`,
which vectorises the runs of message-data records that repeat with a fixed
byte pattern and hands the rest to the per-message sinks of
:mod:`ilic_cli.io.roscollect`.

The chunk's index data must list exactly the records found in the chunk
(connection, time and offset); anything this module does not expect in a
file's structure raises :class:`Fallback`, and the caller reads the whole file
through the ``rosbags`` reader instead, which reports what is wrong with it.
The writer is :mod:`ilic_cli.io.ros1write`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from rosbags.rosbag1.reader import Header, Reader, ReaderError, RecordType, read_bytes, read_uint32

from ilic_cli.io import current_progress, roscollect, rosschema
from ilic_cli.io.ros1chunks import (
    _INDEX_ENTRY,
    _U32,
    KIND_OTHER,
    KIND_POINT,
    KIND_STATE,
    KIND_STRING,
    OP_MSGDATA,
    Fallback,
    _ChunkWalker,
    _Conn,
    _decompress,
    _op,
    _record_header,
)


def _index_data(stream: BinaryIO, count: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Read ``count`` index-data records: connection -> (times ns, offsets)."""
    out: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for _ in range(count):
        header = Header.read(stream, RecordType.IDXDATA)
        if header.get_uint32("ver") != 1:
            raise Fallback
        conn = header.get_uint32("conn")
        entries = header.get_uint32("count")
        size = read_uint32(stream)
        if size != entries * 12 or conn in out:
            raise Fallback
        table = np.frombuffer(read_bytes(stream, size), dtype=_INDEX_ENTRY)
        out[conn] = (table["sec"].astype(np.int64) * 1_000_000_000 + table["nsec"], table["offset"].astype(np.int64))
    return out


_BROKEN = (struct.error, ValueError, OSError, KeyError, AssertionError)
"""What a damaged record raises besides ``rosbags``' ``ReaderError`` (:func:`_reader_errors`)."""


def _reader_errors() -> tuple[type[BaseException], ...]:
    return (ReaderError, *_BROKEN)


def _bag_index(path: Path, stream: BinaryIO) -> tuple[list[Any], list[Any]]:
    """The bag's connections and chunk infos (``rosbags``' records), read from its index section at the end.

    Raises :class:`Fallback` for anything but an indexed, unencrypted bag of
    version 2.0 with one connection per topic and distinct chunks in order.
    """
    shell = Reader(path)
    shell.bio = stream
    try:
        if stream.readline() != b"#ROSBAG V2.0\n":
            raise Fallback
        header = Header.read(stream, RecordType.BAGHEADER)
        index_pos = header.get_uint64("index_pos")
        conn_count = header.get_uint32("conn_count")
        chunk_count = header.get_uint32("chunk_count")
        if "encryptor" in header or index_pos == 0 or chunk_count == 0:
            raise Fallback
        stream.seek(index_pos)
        connections = [shell.read_connection() for _ in range(conn_count)]
        infos = [shell.read_chunk_info() for _ in range(chunk_count)]
    except _reader_errors() as exc:
        raise Fallback from exc
    finally:
        shell.bio = None
    ids = [c.id for c in connections]
    topics = [c.topic for c in connections]
    positions = [info.pos for info in infos]
    if len(set(ids)) != len(ids) or len(set(topics)) != len(topics) or positions != sorted(set(positions)):
        raise Fallback  # several connections per topic, or odd indexes: per message
    return connections, infos


def _chunk_record(stream: BinaryIO, pos: int, size: int, limit: int, *, skip: bool = False) -> tuple[str, int, bytes]:
    """The chunk record at ``pos``: its compression, declared uncompressed size and data (``b""`` with ``skip``); the stream is left after it."""
    try:
        stream.seek(pos)
        chunk_header = Header.read(stream, RecordType.CHUNK)
        compression = chunk_header.get_string("compression")
        declared = chunk_header.get_uint32("size")
        datasize = _U32.unpack(stream.read(4))[0]
        if datasize > size or declared > limit or stream.tell() + datasize > size:
            raise Fallback
        if skip:
            stream.seek(datasize, 1)
            return compression, declared, b""
        data = stream.read(datasize)
    except _reader_errors() as exc:
        raise Fallback from exc
    if len(data) != datasize:
        raise Fallback
    return compression, declared, data


def _index_data_of(stream: BinaryIO, count: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """:func:`_index_data`, a damaged record raising :class:`Fallback`."""
    try:
        return _index_data(stream, count)
    except _reader_errors() as exc:
        raise Fallback from exc


@dataclass(frozen=True)
class BagSummary:
    """What the index of a ROS 1 bag says (as ``rosbags``' reader says it, without an object per message).

    Attributes
    ----------
    connections : list
        ``rosbags`` connections (``msgcount`` 0: see ``counts``).
    counts : dict of int to int
        Connection id -> its index entries (``rosbags``' ``msgcount``).
    start_ns, end_ns : int
        ``rosbags``' ``start_time`` and ``end_time`` (the chunk infos' range, end exclusive).
    first : dict of int to (int, int)
        Connection id -> chunk position and offset in the chunk of its first
        message (least log time, then chunk, then offset: ``rosbags``' order).
    """

    connections: list[Any]
    counts: dict[int, int]
    start_ns: int
    end_ns: int
    first: dict[int, tuple[int, int]]


def summary(path: Path) -> BagSummary:
    """The connections, message counts, time range and first messages of a ROS 1 bag, from its index records.

    Raises :class:`Fallback` when the file is not one :func:`collect` reads.
    """
    size = path.stat().st_size
    with open(path, "rb") as stream:
        connections, infos = _bag_index(path, stream)
        counts = {c.id: 0 for c in connections}
        first: dict[int, tuple[int, int, int]] = {}
        for info in infos:
            _chunk_record(stream, info.pos, size, 2**63, skip=True)
            for cid, (times, offsets) in _index_data_of(stream, len(info.connection_counts)).items():
                if cid not in counts:
                    raise Fallback
                counts[cid] += len(times)
                if len(times):
                    j = int(np.lexsort((offsets, times))[0])
                    here = (int(times[j]), info.pos, int(offsets[j]))
                    first[cid] = min(first.get(cid, here), here)
    start = min(info.start_time for info in infos)
    end = max(info.end_time for info in infos)
    return BagSummary(connections, counts, start, end, {cid: (pos, offset) for cid, (_, pos, offset) in first.items()})


def message_at(path: Path, chunk_pos: int, offset: int, limit: int) -> bytes:
    """The data of the message-data record at ``offset`` of the chunk at ``chunk_pos`` (decompressed to at most ``limit`` bytes)."""
    size = path.stat().st_size
    with open(path, "rb") as stream:
        compression, declared, data = _chunk_record(stream, chunk_pos, size, limit)
    buf = _decompress(data, compression, limit, path)
    if len(buf) != declared:
        raise Fallback
    fields, dstart, dend = _record_header(buf, offset, len(buf))
    if _op(buf, fields) != OP_MSGDATA:
        raise Fallback
    return buf[dstart:dend]


def collect(path: Path, limit: int, declare: Callable[[roscollect.Collector, list[Any]], dict[int, Any]]) -> roscollect.Collected:
    """Read every message of a ROS 1 bag into per-topic columns, vectorised where the layout repeats.

    Parameters
    ----------
    path : Path
        The bag.
    limit : int
        Most bytes a chunk may decompress to.
    declare : callable
        ``declare(collector, connections)`` registers the ``rosbags``
        connections with the collector and returns connection id -> sink
        (for the connections to read), as the per-message path does.

    Returns
    -------
    Collected
        As :meth:`roscollect.Collector.finish`.

    Raises
    ------
    Fallback
        The file is not one this reader handles; read it per message.
    LogError
        A chunk decompresses past ``limit``.
    """
    size = path.stat().st_size
    with open(path, "rb") as stream:
        connections, infos = _bag_index(path, stream)
        collector = roscollect.Collector(path)
        sinks = declare(collector, connections)
        ts = rosschema.typestore(rosschema.ROS1)
        conns: dict[int, _Conn] = {}
        for c in connections:
            sink = sinks.get(c.id)
            msgtype = rosschema.normalize_msgtype(c.msgtype)
            kind = KIND_OTHER
            if sink is not None:
                kind = {rosschema.JOINT_STATE: KIND_STATE, rosschema.TRAJECTORY_POINT: KIND_POINT, rosschema.STRING: KIND_STRING}.get(msgtype, KIND_OTHER)
                if kind == KIND_OTHER:
                    raise Fallback
            conns[c.id] = _Conn(c.id, kind, sink, msgtype)
        last_time: dict[int, int] = {}
        with current_progress(path) as progress:
            for number, info in enumerate(infos):
                compression, declared, data = _chunk_record(stream, info.pos, size, limit)
                index = _index_data_of(stream, len(info.connection_counts))
                buf = _decompress(data, compression, limit, path)
                del data
                if len(buf) != declared:
                    raise Fallback
                found = _ChunkWalker(buf, conns, ts).walk()
                del buf
                index = {cid: entry for cid, entry in index.items() if len(entry[0])}
                if set(index) != set(found.times):
                    raise Fallback
                for cid, (times, offsets) in index.items():
                    got_t = np.concatenate(found.times[cid])
                    got_o = np.concatenate(found.offsets[cid])
                    if not (np.array_equal(times, got_t) and np.array_equal(offsets, got_o)):
                        raise Fallback
                    if len(times) and ((times[1:] < times[:-1]).any() or times[0] < last_time.get(cid, 0)):
                        raise Fallback  # not in time order: the per-message path orders it
                    if len(times):
                        last_time[cid] = int(times[-1])
                if progress is not None:
                    progress(number + 1, len(infos))
    return collector.finish()
