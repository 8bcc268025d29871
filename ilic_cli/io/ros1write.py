"""Vectorised writing of ROS 1 bags (format 2.0).

:func:`write` produces the same bytes as ``rosbags``' ROS 1 ``Writer`` fed with
:func:`ilic_cli.io.rosencode.encode` (uncompressed chunks closed after the
first record past 1 MiB, index data, connection and chunk-info records), but
serialises whole columns at once.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from rosbags.typesys.msg import denormalize_msgtype

from ilic_cli.errors import LogError
from ilic_cli.io import rosencode, rosschema
from ilic_cli.io.ros1chunks import _INDEX_ENTRY, _U32, CHUNK_THRESHOLD, OP_BAGHEADER, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_IDXDATA, OP_MSGDATA
from ilic_cli.runlog import RunLog


def _field(name: bytes, value: bytes) -> bytes:
    return _U32.pack(len(name) + 1 + len(value)) + name + b"=" + value


def _header(op: int | None, fields: list[tuple[bytes, bytes]]) -> bytes:
    """A record header as ``rosbags`` writes it: length, then ``op`` and the fields in order."""
    body = (_field(b"op", bytes([op])) if op else b"") + b"".join(_field(k, v) for k, v in fields)
    return _U32.pack(len(body)) + body


def _time(ns: int) -> bytes:
    return struct.pack("<II", ns // 1_000_000_000, ns % 1_000_000_000)


def _connection_record(cid: int, topic: str, msgtype: str, ts: Any) -> bytes:
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
    templates = _templates(log, joint, conn_of)
    meta_bytes, meta_time_at = _record(conn_of[rosschema.TOPIC_METADATA], [_ros1_string(rosencode.metadata_text(log, joint))])
    meta_record = bytearray(meta_bytes)
    meta_record[meta_time_at : meta_time_at + 8] = _time(int(ns[0]))
    records = _Records(_Rows(templates, ns), bytes(meta_record), conn_of[rosschema.TOPIC_METADATA])

    path.unlink(missing_ok=True)
    with open(path, "xb") as out:
        out.write(b"#ROSBAG V2.0\n")
        out.write(_bag_header(0, 0, 0))
        chunks: list[tuple[int, int, int, list[tuple[int, int]]]] = []  # (pos, start, end, [(conn, count)])
        first = 0
        while first < len(records.sizes):
            last = records.chunk_end(first, len(conn_records) if first == 0 else 0)
            chunks.append(_write_chunk(out, records, first, last, conn_records if first == 0 else b""))
            first = last + 1
        index_pos = out.tell()
        out.write(conn_records)
        for pos, start, end, counts in chunks:
            fields = [(b"ver", _U32.pack(1)), (b"chunk_pos", struct.pack("<Q", pos)), (b"start_time", _time(start)), (b"end_time", _time(end))]
            out.write(_header(OP_CHUNK_INFO, [*fields, (b"count", _U32.pack(len(counts)))]))
            out.write(_U32.pack(len(counts) * 8))
            out.write(b"".join(_U32.pack(c) + _U32.pack(m) for c, m in counts))
        out.seek(13)
        out.write(_bag_header(index_pos, len(topics), len(chunks)))


def _templates(log: RunLog, joint: str, conn_of: dict[str, int]) -> list[_Template]:
    """The record templates of one sample: ``/joint_states``, ``/joint_reference`` (when the log has one) and ``/ilic/extras``."""
    ch = log.channels
    extras = [name for name in ch if name not in {"t", *rosschema.STATE_FIELDS, *rosschema.REFERENCE_FIELDS}]
    templates = [_state_template(conn_of[rosschema.TOPIC_STATES], [joint], [ch["q"], ch.get("qd"), ch["tau"]])]
    if rosschema.TOPIC_REFERENCE in conn_of:
        templates.append(_point_template(conn_of[rosschema.TOPIC_REFERENCE], [ch.get(n) for n in rosschema.REFERENCE_FIELDS]))
    extra_matrix = np.column_stack([log.t, *(ch[name] for name in extras)]).astype(np.float64)
    templates.append(_state_template(conn_of[rosschema.TOPIC_EXTRAS], [rosschema.TIME_NAME, *extras], [extra_matrix, None, None]))
    return templates


class _Records:
    """The bag's message-data records in stream order: record 0 is the metadata, ``1 + i * k + j`` template ``j`` of sample ``i``."""

    def __init__(self, builder: _Rows, meta_record: bytes, meta_conn: int) -> None:
        self.builder = builder
        self.meta_record = meta_record
        self.meta_conn = meta_conn
        self.k = k = len(builder.templates)
        n = len(builder.ns)
        self.sizes = np.empty(1 + n * k, dtype=np.int64)
        self.sizes[0] = len(meta_record)
        self.sizes[1:] = np.tile(np.array(builder.widths, dtype=np.int64), n)
        self.ends = np.cumsum(self.sizes)
        self.starts = np.concatenate([np.zeros(1, dtype=np.int64), self.ends])
        self.conn_seq = np.array([t.conn for t in builder.templates], dtype=np.int64)

    def chunk_end(self, first: int, prefix: int) -> int:
        """The last record of the chunk that starts at record ``first`` after ``prefix`` bytes (closed past :data:`CHUNK_THRESHOLD`)."""
        base = int(self.ends[first - 1]) if first else 0
        last = int(np.searchsorted(self.ends, base - prefix + CHUNK_THRESHOLD, side="right"))
        return min(max(last, first), len(self.sizes) - 1)

    def conns(self, r: np.ndarray) -> np.ndarray:
        return np.where(r == 0, self.meta_conn, self.conn_seq[(np.maximum(r, 1) - 1) % self.k])

    def times(self, r: np.ndarray) -> np.ndarray:
        return self.builder.ns[np.maximum(r - 1, 0) // self.k]


def _write_chunk(out: BinaryIO, records: _Records, first: int, last: int, prefix: bytes) -> tuple[int, int, int, list[tuple[int, int]]]:
    """Write the chunk of records ``first..last`` (after ``prefix``) and its index data; return its chunk info's values."""
    base = int(records.ends[first - 1]) if first else 0
    data = _chunk_bytes(first, last, base, prefix, records.meta_record, records.builder, records.ends, records.k)
    recs = np.arange(first, last + 1, dtype=np.int64)
    rel = records.starts[first : last + 1] - base + len(prefix)
    conns = records.conns(recs)
    times = records.times(recs)
    pos = out.tell()
    out.write(_header(OP_CHUNK, [(b"compression", b"none"), (b"size", _U32.pack(len(data)))]))
    out.write(_U32.pack(len(data)))
    out.write(data)
    del data
    counts = []
    for cid in _first_seen(conns):
        sel = conns == cid
        table = np.empty(int(sel.sum()), dtype=_INDEX_ENTRY)
        table["sec"] = times[sel] // 1_000_000_000
        table["nsec"] = times[sel] % 1_000_000_000
        table["offset"] = rel[sel]
        out.write(_header(OP_IDXDATA, [(b"ver", _U32.pack(1)), (b"conn", _U32.pack(int(cid))), (b"count", _U32.pack(len(table)))]))
        out.write(_U32.pack(len(table) * 12))
        out.write(table.tobytes())
        counts.append((int(cid), len(table)))
    return pos, int(times.min()), int(times.max()), counts


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
