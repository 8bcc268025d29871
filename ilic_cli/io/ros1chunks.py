"""The records of a ROS 1 bag (format 2.0) and the walk over one decompressed chunk.

:class:`_ChunkWalker` finds runs of message-data records that repeat with a
fixed byte pattern (for example ``/joint_states``, ``/joint_reference``,
``/ilic/extras`` once per sample). The first period of a run is parsed record
by record and decoded once by ``rosbags``; every later period must then carry
the same bytes everywhere except in the numeric fields (record time, ``seq``,
stamps, float64 arrays, durations), which is checked through strided NumPy
views, and the numbers are taken as views. Records that do not repeat are
decoded one by one with the per-message sinks of :mod:`ilic_cli.io.roscollect`.
Anything unexpected in the structure raises :class:`Fallback`.
"""

from __future__ import annotations

import bz2
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import lz4.frame
import numpy as np

from ilic_cli.errors import LogError

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
        out = bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
    elif compression == "lz4":
        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
    else:
        raise Fallback
    if len(out) > limit:
        raise LogError(path, f"a bag chunk decompresses to more than {limit} bytes; file is corrupt or hostile")
    return out
