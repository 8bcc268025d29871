"""Vectorised reading and writing of ROS 1 bags (format 2.0).

Reading (:func:`collect`) walks the chunks listed in the bag's index, one
decompressed chunk at a time, and finds runs of message-data records that
repeat with a fixed byte pattern (for example ``/joint_states``,
``/joint_reference``, ``/ilic/extras`` once per sample). The first period of a
run is parsed record by record and decoded once by ``rosbags``; every later
period must then carry the same bytes everywhere except in the numeric fields
(record time, ``seq``, stamps, float64 arrays, durations), which is checked
through strided NumPy views, and the numbers are taken as views. Records that
do not repeat (layout changes: other string lengths, joint counts) are decoded
one by one with today's per-message sinks of :mod:`ilic_cli.io.roscollect`.

The chunk's index data must list exactly the records found in the chunk
(connection, time and offset); anything this module does not expect in a
file's structure raises :class:`Fallback`, and the caller reads the whole file
through the ``rosbags`` reader instead, which reports what is wrong with it.

Writing (:func:`write`) produces the same bytes as ``rosbags``' ROS 1
``Writer`` fed with :func:`ilic_cli.io.rosencode.encode` (uncompressed chunks
closed after the first record past 1 MiB, index data, connection and
chunk-info records), but serialises whole columns at once.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io import roscollect, rosencode, rosschema

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog

OP_MSGDATA = 2
OP_BAGHEADER = 3
OP_IDXDATA = 4
OP_CHUNK = 5
OP_CHUNK_INFO = 6
OP_CONNECTION = 7

CHUNK_THRESHOLD = 1 << 20
"""A chunk is closed after the first record that takes it past this size (as ``rosbags``)."""

SEARCH = 48
"""Records parsed one by one when looking for a repeating pattern."""

_U32 = struct.Struct("<I")
_INDEX_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])

KIND_STATE = "state"
KIND_POINT = "point"
KIND_STRING = "string"
KIND_OTHER = "other"


class Fallback(Exception):
    """The file's structure is not what the vectorised reader handles; read it per message."""


# -- reading -------------------------------------------------------------------------
@dataclass
class _Conn:
    """A connection being read: its sink (None: not read) and message kind."""

    id: int
    kind: str
    sink: Any = None
    msgtype: str = ""


@dataclass
class _Layout:
    """Where the numbers are in one message-data record (offsets from the record start).

    ``free`` lists ``(start, stop)`` byte ranges whose content may differ
    between periods of a run; every other byte must repeat.
    """

    conn: int
    length: int
    time_at: int
    free: list[tuple[int, int]]
    stamp_at: int = -1
    arrays: dict[str, tuple[int, int]] = field(default_factory=dict)
    names: tuple[str, ...] = ()
    signature: bytes = b""


def _u32(buf: bytes, pos: int) -> int:
    return int(_U32.unpack_from(buf, pos)[0])


def _record_header(buf: bytes, pos: int, end: int) -> tuple[dict[bytes, tuple[int, int]], int, int]:
    """Parse the record at ``pos``: ``(fields -> (value start, stop), data start, data stop)``."""
    if pos + 4 > end:
        raise Fallback
    hlen = _u32(buf, pos)
    hend = pos + 4 + hlen
    if hend + 4 > end:
        raise Fallback
    fields: dict[bytes, tuple[int, int]] = {}
    p = pos + 4
    while p < hend:
        if p + 4 > hend:
            raise Fallback
        flen = _u32(buf, p)
        p += 4
        if p + flen > hend:
            raise Fallback
        eq = buf.find(b"=", p, p + flen)
        if eq < 0:
            raise Fallback
        name = buf[p:eq]
        if name in fields:
            raise Fallback
        fields[name] = (eq + 1, p + flen)
        p += flen
    dstart = hend + 4
    dend = dstart + _u32(buf, hend)
    if dend > end:
        raise Fallback
    return fields, dstart, dend


def _op(buf: bytes, fields: dict[bytes, tuple[int, int]]) -> int:
    where = fields.get(b"op")
    if where is None or where[1] - where[0] != 1:
        raise Fallback
    return buf[where[0]]


class _Cursor:
    """Bounds-checked reading of ROS 1 serialised fields in ``buf[start:stop]``."""

    def __init__(self, buf: bytes, start: int, stop: int) -> None:
        self.buf, self.pos, self.stop = buf, start, stop

    def skip(self, size: int) -> int:
        at = self.pos
        if size < 0 or at + size > self.stop:
            raise ValueError("message too short")
        self.pos = at + size
        return at

    def count(self) -> int:
        return _u32(self.buf, self.skip(4))

    def string(self) -> None:
        self.skip(self.count())

    def floats(self) -> tuple[int, int]:
        n = self.count()
        return self.skip(8 * n), n


def _message_layout(buf: bytes, pos: int, dstart: int, dend: int, conn: _Conn, ts: Any) -> _Layout | None:
    """Layout of the record at ``pos`` whose message is ``buf[dstart:dend]``; None when not vectorisable."""
    fields, _, _ = _record_header(buf, pos, dend)
    time_at = fields[b"time"][0] - pos
    free = [(time_at, time_at + 8)]
    layout = _Layout(conn.id, dend - pos, time_at, free)
    if conn.kind in (KIND_STRING, KIND_OTHER):
        free.append((dstart - pos, dend - pos))
    else:
        cur = _Cursor(buf, dstart, dend)
        try:
            if conn.kind == KIND_STATE:
                seq = cur.skip(4)
                layout.stamp_at = cur.skip(8) - pos
                free.append((seq - pos, seq - pos + 12))
                cur.string()  # frame_id
                for _ in range(cur.count()):
                    cur.string()
                names: tuple[str, ...] = ("position", "velocity", "effort")
            else:
                names = ("positions", "velocities", "accelerations", "effort")
            for name in names:
                at, n = cur.floats()
                layout.arrays[name] = (at - pos, n)
                free.append((at - pos, at - pos + 8 * n))
            if conn.kind == KIND_POINT:
                at = cur.skip(8)  # time_from_start
                free.append((at - pos, at - pos + 8))
        except (ValueError, struct.error):
            return None
        if cur.pos != dend:
            return None
        # the fixed part decodes the same for every period: check it once with rosbags
        try:
            msg = ts.deserialize_ros1(buf[dstart:dend], conn.msgtype)
        except Exception:  # noqa: BLE001 - decoded per message, which records the error
            return None
        for name, (_, n) in layout.arrays.items():
            if len(getattr(msg, name)) != n:
                return None
        if conn.kind == KIND_STATE:
            layout.names = tuple(str(x) for x in msg.name)
    raw = bytearray(buf[pos:dend])
    for a, b in free:
        raw[a:b] = bytes(b - a)
    layout.signature = bytes(raw)
    return layout


@dataclass
class _ChunkRecords:
    """Times and offsets of the message records found in one chunk, per connection."""

    times: dict[int, list[np.ndarray]] = field(default_factory=dict)
    offsets: dict[int, list[np.ndarray]] = field(default_factory=dict)

    def add(self, conn: int, times: np.ndarray, offsets: np.ndarray) -> None:
        self.times.setdefault(conn, []).append(times)
        self.offsets.setdefault(conn, []).append(offsets)


def _inject(sink: Any, layout: _Layout, log_ns: np.ndarray, stamp: np.ndarray | None, arrays: dict[str, np.ndarray]) -> None:
    """Append ``len(log_ns)`` messages of one layout to a per-message sink (:meth:`roscollect._Sink.add_columns`)."""
    m = len(log_ns)
    blocks = {name: values.reshape(m, layout.arrays[name][1]) for name, values in arrays.items()}
    sink.add_columns(log_ns, blocks, stamp, layout.names if stamp is not None else None)


class _ChunkWalker:
    """Walks the records of one decompressed chunk, vectorising repeating runs."""

    def __init__(self, buf: bytes, conns: dict[int, _Conn], ts: Any) -> None:
        self.buf = buf
        self.conns = conns
        self.ts = ts
        self.found = _ChunkRecords()
        self.u8 = np.frombuffer(buf, dtype=np.uint8)

    def walk(self) -> _ChunkRecords:
        buf, end, pos = self.buf, len(self.buf), 0
        while pos < end:
            recs: list[tuple[int, int, int, int, int]] = []  # (pos, conn, dstart, dend, time ns)
            layouts: list[_Layout | None] = []
            p = pos
            while p < end and len(recs) < SEARCH:
                fields, dstart, dend = _record_header(buf, p, end)
                op = _op(buf, fields)
                if op == OP_CONNECTION:
                    if recs:
                        break  # handled on the next turn
                    p = pos = dend
                    continue
                if op != OP_MSGDATA or set(fields) != {b"op", b"conn", b"time"}:
                    raise Fallback
                conn_at, time_at = fields[b"conn"], fields[b"time"]
                if conn_at[1] - conn_at[0] != 4 or time_at[1] - time_at[0] != 8:
                    raise Fallback
                cid = _u32(buf, conn_at[0])
                conn = self.conns.get(cid)
                if conn is None:
                    raise Fallback
                sec, nsec = struct.unpack_from("<II", buf, time_at[0])
                recs.append((p, cid, dstart, dend, sec * 1_000_000_000 + nsec))
                layouts.append(_message_layout(buf, p, dstart, dend, conn, self.ts))
                p = dend
                period = self._period(layouts)
                if period:
                    break
            if not recs:
                continue
            period = self._period(layouts)
            if period:
                pos = self._run(pos, [lay for lay in layouts[:period] if lay is not None])
                continue
            # no repeating pattern here: the first records one by one
            take = len(recs) if p >= end or len(recs) < SEARCH else max(1, len(recs) // 2)
            for rp, cid, dstart, dend, time_ns in recs[:take]:
                self._one(rp, cid, dstart, dend, time_ns)
            pos = recs[take - 1][3]
        return self.found

    @staticmethod
    def _period(layouts: list[_Layout | None]) -> int:
        """Smallest P such that the last 2P layouts (from the start) repeat with period P; 0 if none."""
        n = len(layouts)
        if n < 2 or n % 2 or layouts[0] is None:
            return 0
        half = n // 2
        for j in range(half):
            a, b = layouts[j], layouts[j + half]
            if a is None or b is None or a.signature != b.signature:
                return 0
        # the same connection twice in a period must keep one layout
        seen: dict[int, bytes] = {}
        for lay in layouts[:half]:
            assert lay is not None
            if seen.setdefault(lay.conn, lay.signature) != lay.signature:
                return 0
        return half

    def _one(self, pos: int, cid: int, dstart: int, dend: int, time_ns: int) -> None:
        """Decode one record per message (today's path)."""
        conn = self.conns[cid]
        self.found.add(cid, np.array([time_ns], dtype=np.int64), np.array([pos], dtype=np.int64))
        if conn.sink is not None:
            conn.sink.add(time_ns, self.buf[dstart:dend])

    def _run(self, pos: int, period: list[_Layout]) -> int:
        """Check and take the run of periods starting at ``pos``; return the position after it."""
        buf, u8 = self.buf, self.u8
        width = sum(lay.length for lay in period)
        rows = (len(buf) - pos) // width
        matrix = u8[pos : pos + rows * width].reshape(rows, width)
        fixed = np.ones(width, dtype=bool)
        start = 0
        for lay in period:
            for a, b in lay.free:
                fixed[start + a : start + b] = False
            start += lay.length
        # compare in growing blocks of rows: a short run costs little, memory stays bounded
        m, block = 0, 64
        while m < rows:
            part = matrix[m : m + block]
            differs = part != matrix[0]
            differs &= fixed
            bad = np.flatnonzero(differs.any(axis=1))
            if len(bad):
                m += int(bad[0])
                break
            m += len(part)
            block = min(4 * block, 16384)
        del matrix
        by_conn: dict[int, list[int]] = {}
        starts = []
        start = 0
        for j, lay in enumerate(period):
            by_conn.setdefault(lay.conn, []).append(j)
            starts.append(start)
            start += lay.length
        base = np.arange(m, dtype=np.int64) * width + pos
        for cid, js in by_conn.items():
            lay = period[js[0]]

            def column(at: int, dtype: str, count: int = 1, js: list[int] = js) -> np.ndarray:
                parts = [np.ndarray((m, count), dtype=dtype, buffer=buf, offset=pos + starts[j] + at, strides=(width, np.dtype(dtype).itemsize)) for j in js]
                out = parts[0] if len(parts) == 1 else np.stack(parts, axis=1)
                return np.ascontiguousarray(out).reshape(m * len(parts), count)

            sec = column(lay.time_at, "<u4").astype(np.int64)[:, 0]
            nsec = column(lay.time_at + 4, "<u4")[:, 0]
            log_ns = sec * 1_000_000_000 + nsec
            offsets = (base[:, None] + np.array([starts[j] for j in js], dtype=np.int64)[None, :]).reshape(-1)
            self.found.add(cid, log_ns, offsets)
            sink = self.conns[cid].sink
            if sink is None or sink.error is not None:
                continue
            if not sink.fields and sink.count == 0:  # a String topic: its first message is decoded (and is the only one kept)
                # the first String message is decoded (and the only one)
                first = pos + starts[js[0]]
                _, dstart, dend = _record_header(buf, first, len(buf))
                sink.add(int(log_ns[0]), buf[dstart:dend])
                _inject(sink, lay, log_ns[1:], None, {})
                continue
            stamp = None
            if lay.stamp_at >= 0:
                stamp = column(lay.stamp_at, "<i4").astype(np.int64)[:, 0] * 1_000_000_000 + column(lay.stamp_at + 4, "<u4")[:, 0]
            wanted = sink.fields
            arrays = {name: column(at, "<f8", n).astype(np.float64) for name, (at, n) in lay.arrays.items() if name in wanted}
            _inject(sink, lay, log_ns, stamp, arrays)
        return pos + m * width


def _decompress(data: bytes, compression: str, limit: int, path: Path) -> bytes:
    """Decompress one chunk in one call, never to more than ``limit`` bytes."""
    if compression == "none":
        out = data
    elif compression == "bz2":
        import bz2

        out = bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
    elif compression == "lz4":
        import lz4.frame

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
    else:
        raise Fallback
    if len(out) > limit:
        raise LogError(path, f"a bag chunk decompresses to more than {limit} bytes; file is corrupt or hostile")
    return out


def _index_data(stream: BinaryIO, count: int) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Read ``count`` index-data records: connection -> (times ns, offsets)."""
    from rosbags.rosbag1.reader import Header, RecordType, read_bytes, read_uint32

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
    from rosbags.rosbag1.reader import ReaderError

    return (ReaderError, *_BROKEN)


def _bag_index(path: Path, stream: BinaryIO) -> tuple[list[Any], list[Any]]:
    """The bag's connections and chunk infos (``rosbags``' records), read from its index section at the end.

    Raises :class:`Fallback` for anything but an indexed, unencrypted bag of
    version 2.0 with one connection per topic and distinct chunks in order.
    """
    from rosbags.rosbag1.reader import Header, Reader, RecordType

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
    from rosbags.rosbag1.reader import Header, RecordType

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
    from ilic_cli.io import current_progress

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


# -- writing -------------------------------------------------------------------------
def _field(name: bytes, value: bytes) -> bytes:
    return _U32.pack(len(name) + 1 + len(value)) + name + b"=" + value


def _header(op: int | None, fields: list[tuple[bytes, bytes]]) -> bytes:
    """A record header as ``rosbags`` writes it: length, then ``op`` and the fields in order."""
    body = (_field(b"op", bytes([op])) if op else b"") + b"".join(_field(k, v) for k, v in fields)
    return _U32.pack(len(body)) + body


def _time(ns: int) -> bytes:
    return struct.pack("<II", ns // 1_000_000_000, ns % 1_000_000_000)


def _connection_record(cid: int, topic: str, msgtype: str, ts: Any) -> bytes:
    from rosbags.typesys.msg import denormalize_msgtype

    msgdef, md5 = ts.generate_msgdef(msgtype)
    first = _header(OP_CONNECTION, [(b"conn", _U32.pack(cid)), (b"topic", topic.encode())])
    second = _header(
        None,
        [(b"topic", topic.encode()), (b"type", denormalize_msgtype(msgtype).encode()), (b"md5sum", md5.encode()), (b"message_definition", msgdef.encode())],
    )
    return first + second


def _ros1_string(text: str) -> bytes:
    raw = text.encode()
    return _U32.pack(len(raw)) + raw


@dataclass
class _Template:
    """One message-data record per sample: template bytes and where the varying numbers go."""

    conn: int
    raw: bytes
    time_at: int
    seq_at: int = -1
    stamp_at: int = -1
    duration_at: int = -1
    floats: list[tuple[int, np.ndarray]] = field(default_factory=list)


def _record(conn: int, data_parts: list[bytes]) -> tuple[bytes, int]:
    """A message-data record around ``data_parts``; return it and the offset of its time value."""
    head = _header(OP_MSGDATA, [(b"conn", _U32.pack(conn)), (b"time", bytes(8))])
    data = b"".join(data_parts)
    return head + _U32.pack(len(data)) + data, len(head) - 8


def _state_template(conn: int, names: list[str], columns: list[np.ndarray | None]) -> _Template:
    """A JointState record with one value per name in each non-None column (position, velocity, effort)."""
    parts = [bytes(12), _ros1_string(""), _U32.pack(len(names)), *(_ros1_string(n) for n in names)]
    floats = []
    offset = sum(len(p) for p in parts)
    for col in columns:
        width = 0 if col is None else (col.shape[1] if col.ndim == 2 else 1)
        parts.append(_U32.pack(width) + bytes(8 * width))
        if col is not None:
            floats.append((offset + 4, col))
        offset += 4 + 8 * width
    raw, time_at = _record(conn, parts)
    data_at = time_at + 8 + 4
    tpl = _Template(conn, raw, time_at, seq_at=data_at, stamp_at=data_at + 4)
    tpl.floats = [(data_at + at, col) for at, col in floats]
    return tpl


def _point_template(conn: int, columns: list[np.ndarray | None]) -> _Template:
    parts = []
    floats = []
    offset = 0
    for col in columns:
        width = 0 if col is None else 1
        parts.append(_U32.pack(width) + bytes(8 * width))
        if col is not None:
            floats.append((offset + 4, col))
        offset += 4 + 8 * width
    parts.append(_U32.pack(0))  # effort: empty
    offset += 4
    parts.append(bytes(8))  # time_from_start
    raw, time_at = _record(conn, parts)
    data_at = time_at + 8 + 4
    tpl = _Template(conn, raw, time_at, duration_at=data_at + offset)
    tpl.floats = [(data_at + at, col) for at, col in floats]
    return tpl


def _put(rows: np.ndarray, at: int, values: np.ndarray, dtype: str) -> None:
    """Write ``values`` (one or more per row) into every row of ``rows`` at byte ``at``."""
    values = np.ascontiguousarray(np.asarray(values).astype(dtype, copy=False))
    width = 1 if values.ndim == 1 else values.shape[1]
    size = np.dtype(dtype).itemsize * width
    rows[:, at : at + size] = values.reshape(len(rows), width).view(np.uint8).reshape(len(rows), size)


class _Rows:
    """Serialised records of a range of samples (one row of bytes per sample)."""

    def __init__(self, templates: list[_Template], ns: np.ndarray) -> None:
        self.templates = templates
        self.ns = ns
        self.widths = [len(t.raw) for t in templates]
        self.width = sum(self.widths)
        self.row = np.frombuffer(b"".join(t.raw for t in templates), dtype=np.uint8)
        self.sec = (ns // 1_000_000_000).astype(np.int64)
        self.nsec = (ns % 1_000_000_000).astype(np.int64)
        rel = ns - ns[0]
        self.dsec = rel // 1_000_000_000
        self.dnsec = rel % 1_000_000_000

    def build(self, a: int, b: int) -> np.ndarray:
        """Rows of samples ``a..b-1``, shape ``(b - a, width)``."""
        rows = np.empty((b - a, self.width), dtype=np.uint8)
        rows[:] = self.row
        start = 0
        sl = slice(a, b)
        for tpl, width in zip(self.templates, self.widths):
            _put(rows, start + tpl.time_at, self.sec[sl], "<u4")
            _put(rows, start + tpl.time_at + 4, self.nsec[sl], "<u4")
            if tpl.seq_at >= 0:
                _put(rows, start + tpl.seq_at, np.arange(a, b), "<u4")
            if tpl.stamp_at >= 0:
                _put(rows, start + tpl.stamp_at, self.sec[sl], "<i4")
                _put(rows, start + tpl.stamp_at + 4, self.nsec[sl], "<u4")
            if tpl.duration_at >= 0:
                _put(rows, start + tpl.duration_at, self.dsec[sl], "<i4")
                _put(rows, start + tpl.duration_at + 4, self.dnsec[sl], "<u4")
            for at, col in tpl.floats:
                _put(rows, start + at, col[sl], "<f8")
            start += width
        return rows


def write(log: RunLog, joint: str, path: Path) -> None:
    """Write ``log`` as a ROS 1 bag, byte for byte as the per-message writer does.

    Parameters
    ----------
    log : RunLog
        The log (needs ``t``, ``q`` and ``tau``).
    joint : str
        Joint name for ``/joint_states``.
    path : Path
        Destination file (replaced).
    """
    topics, _ = rosencode.encode(log, joint, rosschema.ROS1)  # checks the log; its message iterator is not used
    ns = rosencode.log_stamps_ns(log)
    if int(ns[-1]) // 1_000_000_000 > 2**31 - 1:
        raise LogError(None, "time stamps too large for ROS 1 time (beyond 2038)")
    ts = rosschema.typestore(rosschema.ROS1)
    conn_of = {spec.topic: cid for cid, spec in enumerate(topics)}
    conn_records = b"".join(_connection_record(cid, spec.topic, spec.msgtype, ts) for cid, spec in enumerate(topics))
    ch = log.channels
    extras = [name for name in ch if name not in {"t", *rosschema.STATE_FIELDS, *rosschema.REFERENCE_FIELDS}]
    templates = [_state_template(conn_of[rosschema.TOPIC_STATES], [joint], [ch["q"], ch.get("qd"), ch["tau"]])]
    if rosschema.TOPIC_REFERENCE in conn_of:
        templates.append(_point_template(conn_of[rosschema.TOPIC_REFERENCE], [ch.get(n) for n in rosschema.REFERENCE_FIELDS]))
    extra_matrix = np.column_stack([log.t, *(ch[name] for name in extras)]).astype(np.float64)
    templates.append(_state_template(conn_of[rosschema.TOPIC_EXTRAS], [rosschema.TIME_NAME, *extras], [extra_matrix, None, None]))
    meta_payload = rosencode.metadata_text(log, joint)
    meta_bytes, meta_time_at = _record(conn_of[rosschema.TOPIC_METADATA], [_ros1_string(meta_payload)])
    meta_record = bytearray(meta_bytes)
    meta_record[meta_time_at : meta_time_at + 8] = _time(int(ns[0]))

    builder = _Rows(templates, ns)
    n, k = len(ns), len(templates)
    # record r: 0 = metadata, 1 + i * k + j = template j of sample i
    sizes = np.empty(1 + n * k, dtype=np.int64)
    sizes[0] = len(meta_record)
    sizes[1:] = np.tile(np.array(builder.widths, dtype=np.int64), n)
    ends = np.cumsum(sizes)
    starts_all = np.concatenate([np.zeros(1, dtype=np.int64), ends])
    conn_seq = np.array([t.conn for t in templates], dtype=np.int64)

    def record_conn(r: np.ndarray) -> np.ndarray:
        return np.where(r == 0, conn_of[rosschema.TOPIC_METADATA], conn_seq[(np.maximum(r, 1) - 1) % k])

    def record_time(r: np.ndarray) -> np.ndarray:
        return ns[np.maximum(r - 1, 0) // k]

    path.unlink(missing_ok=True)
    with open(path, "xb") as out:
        out.write(b"#ROSBAG V2.0\n")
        out.write(_bag_header(0, 0, 0))
        chunks: list[tuple[int, int, int, list[tuple[int, int]]]] = []  # (pos, start, end, [(conn, count)])
        first = 0
        while first < len(sizes):
            prefix = conn_records if first == 0 else b""
            base = int(ends[first - 1]) if first else 0
            last = int(np.searchsorted(ends, base - len(prefix) + CHUNK_THRESHOLD, side="right"))
            last = min(max(last, first), len(sizes) - 1)
            data = _chunk_bytes(first, last, base, prefix, bytes(meta_record), builder, ends, k)
            recs = np.arange(first, last + 1, dtype=np.int64)
            rel = starts_all[first : last + 1] - base + len(prefix)
            conns = record_conn(recs)
            times = record_time(recs)
            pos = out.tell()
            out.write(_header(OP_CHUNK, [(b"compression", b"none"), (b"size", _U32.pack(len(data)))]))
            out.write(_U32.pack(len(data)))
            out.write(data)
            del data
            order = _first_seen(conns)
            counts = []
            for cid in order:
                sel = conns == cid
                table = np.empty(int(sel.sum()), dtype=_INDEX_ENTRY)
                table["sec"] = times[sel] // 1_000_000_000
                table["nsec"] = times[sel] % 1_000_000_000
                table["offset"] = rel[sel]
                out.write(_header(OP_IDXDATA, [(b"ver", _U32.pack(1)), (b"conn", _U32.pack(int(cid))), (b"count", _U32.pack(len(table)))]))
                out.write(_U32.pack(len(table) * 12))
                out.write(table.tobytes())
                counts.append((int(cid), len(table)))
            chunks.append((pos, int(times.min()), int(times.max()), counts))
            first = last + 1
        index_pos = out.tell()
        out.write(conn_records)
        for pos, start, end, counts in chunks:
            out.write(
                _header(
                    OP_CHUNK_INFO,
                    [
                        (b"ver", _U32.pack(1)),
                        (b"chunk_pos", struct.pack("<Q", pos)),
                        (b"start_time", _time(start)),
                        (b"end_time", _time(end)),
                        (b"count", _U32.pack(len(counts))),
                    ],
                )
            )
            out.write(_U32.pack(len(counts) * 8))
            out.write(b"".join(_U32.pack(c) + _U32.pack(m) for c, m in counts))
        out.seek(13)
        out.write(_bag_header(index_pos, len(topics), len(chunks)))


def _first_seen(values: np.ndarray) -> list[int]:
    """Distinct values in order of first appearance."""
    uniq, first = np.unique(values, return_index=True)
    return [int(v) for v in uniq[np.argsort(first)]]


def _bag_header(index_pos: int, conn_count: int, chunk_count: int) -> bytes:
    head = _header(
        OP_BAGHEADER, [(b"index_pos", struct.pack("<Q", index_pos)), (b"conn_count", _U32.pack(conn_count)), (b"chunk_count", _U32.pack(chunk_count))]
    )
    pad = 4096 - 4 - len(head)
    return head + _U32.pack(pad) + b" " * pad


def _chunk_bytes(first: int, last: int, base: int, prefix: bytes, meta_record: bytes, builder: _Rows, ends: np.ndarray, k: int) -> bytes:
    """Bytes of records ``first..last`` (stream offsets from ``base``), after ``prefix``."""
    parts = [prefix]
    stop = int(ends[last])
    if first == 0:
        parts.append(meta_record)
        first = 1
    if last >= first:
        a = (first - 1) // k
        b = (last - 1) // k + 1
        rows = builder.build(a, b)
        origin = len(meta_record) + a * builder.width  # stream offset of sample a's first record
        lo = (int(ends[first - 1]) if first else 0) - origin
        parts.append(rows.reshape(-1)[lo : stop - origin].tobytes())
    return b"".join(parts)
