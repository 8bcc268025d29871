"""The cells of a ROS 2 bag's ``messages`` table and ``timestamp_idx`` index as sqlite3 stores them, built with NumPy.

A cell (https://www.sqlite.org/fileformat2.html) is varints (payload size, row
id), a record header (serial types) and the values. Cells are built as a
matrix of one row each, field by field (:func:`join` drops the bytes a
shorter field leaves); the samples' cells, of one layout from one sample to
the next, straight into a flat buffer (:func:`table_cells`). Their pages are
:mod:`ilic_cli.io.sqlitewrite`'s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ilic_cli.io.sqlitepages import INT_WIDTH


@dataclass
class Bulk:
    """Rows of ``messages`` that come sample after sample, one per topic in order, each topic's message of one size.

    Attributes
    ----------
    topic_ids, sizes : list of int
        Each topic's id and message size, in the order of a sample's rows.
    log_ns : ndarray of int64
        Each sample's timestamp.
    rows : callable
        ``rows(k, start, stop)``: the messages of topic ``k`` for samples ``start:stop``, a (samples, size) uint8 array.
    """

    topic_ids: list[int]
    sizes: list[int]
    log_ns: np.ndarray
    rows: Callable[[int, int, int], np.ndarray]


def serial_types(values: np.ndarray) -> np.ndarray:
    """The serial type sqlite3 stores each integer with: the narrowest of 1, 2, 3, 4, 6 or 8 bytes; 0 and 1 as types 8 and 9."""
    v = np.asarray(values, dtype=np.int64)
    u = np.where(v < 0, ~v, v)
    serial = np.full(len(v), 6, dtype=np.int64)
    for kind, top in ((5, 0x7FFF_FFFF_FFFF), (4, 0x7FFF_FFFF), (3, 0x7F_FFFF), (2, 0x7FFF), (1, 0x7F)):
        serial[u <= top] = kind
    serial[v == 0] = 8
    serial[v == 1] = 9
    return serial


WIDTH = np.array([INT_WIDTH.get(kind, 0) for kind in range(10)], dtype=np.int64)
"""Serial type -> bytes of the integer (from :data:`ilic_cli.io.sqlitepages.INT_WIDTH`)."""


def varint_sizes(values: np.ndarray) -> np.ndarray:
    """Bytes of each non-negative value's varint (below 2**56: at most 8)."""
    v = np.asarray(values, dtype=np.int64)
    size = np.ones(len(v), dtype=np.int64)
    for k in range(1, 8):
        size += v >= (np.int64(1) << (7 * k))
    return size


Field = tuple[np.ndarray, np.ndarray]
"""A field of each cell: its bytes, left-aligned in the rows of a (cells, width) uint8 matrix, and their count per cell."""


def varints(values: np.ndarray) -> Field:
    """Each non-negative value as sqlite3's big-endian varint: 7 bits a byte, the high bit set on every byte but the last."""
    v = np.asarray(values, dtype=np.int64)
    size = varint_sizes(v)
    out = np.empty((len(v), max(int(size.max(initial=0)), 1)), dtype=np.uint8)
    for j in range(out.shape[1]):
        shift = 7 * np.maximum(size - 1 - j, 0)
        out[:, j] = ((v >> shift) & 0x7F) | np.where(j < size - 1, 0x80, 0)
    return out, size


def integers(values: np.ndarray, serial: np.ndarray) -> Field:
    """Big-endian two's complement integers of their serial type's width (shifted to the top of 8 bytes: left-aligned)."""
    width = WIDTH[serial]
    top = np.asarray(values, dtype=np.int64) << (8 * (8 - np.maximum(width, 1)))  # a width of 0 keeps no byte
    return top.astype(">i8").view(np.uint8).reshape(-1, 8)[:, : max(int(width.max(initial=0)), 1)], width


def constant(data: bytes, n: int) -> Field:
    """The same bytes ``data`` in each of ``n`` cells (a read-only broadcast, not copied)."""
    return np.broadcast_to(np.frombuffer(data, dtype=np.uint8), (n, len(data))), np.full(n, len(data), dtype=np.int64)


def low_bytes(values: np.ndarray, size: int) -> Field:
    """The low ``size`` bytes of each value, big-endian."""
    be = np.asarray(values, dtype=">i8").view(np.uint8).reshape(-1, 8)
    return be[:, 8 - size :], np.full(len(be), size, dtype=np.int64)


def join(fields: list[Field]) -> tuple[np.ndarray, np.ndarray]:
    """The cells made of ``fields`` back to back (one flat uint8 array) and each cell's size."""
    matrix = np.concatenate([f for f, _ in fields], axis=1)
    keep = np.concatenate([np.arange(f.shape[1])[None, :] < size[:, None] for f, size in fields], axis=1)
    return matrix[keep], sum((size for _, size in fields), np.zeros(len(matrix), dtype=np.int64))


def index_fields(log_ns: np.ndarray, rowid: np.ndarray) -> list[Field]:
    """An index record (timestamp, row id): its payload size, header and the two integers."""
    s_time, s_id = serial_types(log_ns), serial_types(rowid)
    payload = 3 + WIDTH[s_time] + WIDTH[s_id]  # at most 19: a one-byte varint
    n = len(rowid)
    head = np.empty((n, 4), dtype=np.uint8)
    head[:, 0], head[:, 1], head[:, 2], head[:, 3] = payload, 3, s_time, s_id
    return [(head, np.full(n, 4, dtype=np.int64)), integers(log_ns, s_time), integers(rowid, s_id)]


def table_cell_sizes(bulk: Bulk, first_rowid: int, start: int, stop: int) -> np.ndarray:
    """Bytes of the leaf cells (payload size, row id, record) of the rows of samples ``start:stop``, in order."""
    k = len(bulk.topic_ids)
    n = stop - start
    w_time = WIDTH[serial_types(bulk.log_ns[start:stop])]
    out = np.empty((n, k), dtype=np.int64)
    for j, (tid, size) in enumerate(zip(bulk.topic_ids, bulk.sizes)):
        head = 4 + int(varint_sizes(np.array([2 * size + 12]))[0])
        payload = head + int(WIDTH[serial_types(np.array([tid]))[0]]) + w_time + size
        rowid = first_rowid + (start + np.arange(n, dtype=np.int64)) * k + j
        out[:, j] = varint_sizes(payload) + varint_sizes(rowid) + payload
    return out.reshape(-1)


def max_payload(bulk: Bulk) -> int:
    """The largest record of the bulk rows (its timestamps at their widest)."""
    head = [4 + int(varint_sizes(np.array([2 * size + 12]))[0]) for size in bulk.sizes]
    return max(h + int(WIDTH[serial_types(np.array([tid]))[0]]) + 8 + size for h, tid, size in zip(head, bulk.topic_ids, bulk.sizes))


def table_cells(bulk: Bulk, first_rowid: int, start: int, stop: int, out: np.ndarray) -> int:
    """Write the leaf cells of samples ``start:stop`` back to back at the start of ``out``; their bytes.

    Samples whose cells have the same layout (the widths of the row ids'
    varints and of the timestamp) are a matrix of one row each, filled
    field by field: a column of constant bytes, of varints, of integers,
    then the messages.
    """
    k = len(bulk.topic_ids)
    n = stop - start
    log_ns = bulk.log_ns[start:stop]
    s_time = serial_types(log_ns)
    rowid = first_rowid + (start + np.arange(n, dtype=np.int64))[:, None] * k + np.arange(k)
    r_size = varint_sizes(rowid.reshape(-1)).reshape(n, k)
    layout = np.column_stack([s_time, r_size])
    edges = [0, *(np.flatnonzero((layout[1:] != layout[:-1]).any(axis=1)) + 1).tolist(), n]
    blobs = [bulk.rows(j, start, stop) for j in range(k)]
    s_topic = [int(serial_types(np.array([tid]))[0]) for tid in bulk.topic_ids]
    blob_serial = [varints(np.array([2 * size + 12])) for size in bulk.sizes]
    used = 0
    for a, b in zip(edges[:-1], edges[1:]):
        m = b - a
        fields: list[list[Field]] = []
        for j, (tid, size) in enumerate(zip(bulk.topic_ids, bulk.sizes)):
            head = 4 + int(blob_serial[j][1][0])
            payload = head + int(WIDTH[s_topic[j]]) + int(WIDTH[s_time[a]]) + size
            p_bytes, p_size = varints(np.array([payload]))
            record = bytes([head, 0, s_topic[j], int(s_time[a])]) + blob_serial[j][0][0, : head - 4].tobytes()
            fields.append(
                [
                    constant(p_bytes[0, : p_size[0]].tobytes(), 1),
                    varints(rowid[a:b, j]),
                    constant(record, 1),
                    integers(np.array([tid]), np.array([s_topic[j]])),
                    integers(log_ns[a:b], s_time[a:b]),
                ]
            )
        width = sum(int(size[0]) for topic in fields for _, size in topic) + sum(bulk.sizes)
        matrix = out[used : used + m * width].reshape(m, width)
        col = 0
        for j, topic in enumerate(fields):
            col = fill(matrix, col, topic)
            matrix[:, col : col + bulk.sizes[j]] = blobs[j][a:b]
            col += bulk.sizes[j]
        used += m * width
    return used


def fill(matrix: np.ndarray, col: int, fields: list[Field]) -> int:
    """Write ``fields``, each of one width in every row (or one row for all), into the columns of ``matrix`` from ``col``; the column after them."""
    for values, size in fields:
        width = int(size[0])
        matrix[:, col : col + width] = values[:, :width]
        col += width
    return col


def index_cells(log_ns: np.ndarray, rowid: np.ndarray, out: np.ndarray) -> int:
    """Write the index leaf cells of the entries (``log_ns``, ``rowid``) back to back at the start of ``out``; their bytes (runs of one layout as matrices)."""
    if not len(rowid):
        return 0
    s_time, s_id = serial_types(log_ns), serial_types(rowid)
    key = s_time * 16 + s_id
    edges = [0, *(np.flatnonzero(key[1:] != key[:-1]) + 1).tolist(), len(key)]
    used = 0
    for a, b in zip(edges[:-1], edges[1:]):
        fields = index_fields(log_ns[a : a + 1], rowid[a : a + 1])
        head = fields[0]
        width = sum(int(size[0]) for _, size in fields)
        matrix = out[used : used + (b - a) * width].reshape(b - a, width)
        fill(matrix, 0, [head, integers(log_ns[a:b], s_time[a:b]), integers(rowid[a:b], s_id[a:b])])
        used += (b - a) * width
    return used
