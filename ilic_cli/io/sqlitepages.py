"""The rows of a ROS 2 bag's ``messages`` table read from the sqlite3 file's pages as NumPy arrays.

sqlite3 hands rows to Python one object each (about 0.6 us a row, 1.1 s for the
1.8M rows of a 600 s, 1 kHz bag), or joined by ``group_concat`` (still about
as much: it formats every number as text). The table is a B-tree of pages
whose layout the sqlite3 file format fixes
(https://www.sqlite.org/fileformat2.html): this module walks the interior pages
of the table in Python (a few hundred) and decodes the cells of all its leaf
pages at once with NumPy (varints, record headers, integers), giving each
row's id, topic id, timestamp and where its blob lies in the file.

Every bound is checked (page numbers, cell pointers, cells and records inside
their page, record headers that add up, ids strictly increasing); a row that is
not the plain case (its payload spills to overflow pages, a value of another
type, an empty blob) is fetched alone with SQL by its id. Anything else about the
file (another schema, a write-ahead log, a page of an unexpected kind, a cycle)
raises :class:`Unusual`, and the caller reads the table with SQL as before.
"""

from __future__ import annotations

import mmap
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import as_strided

COLUMNS = ["id", "topic_id", "timestamp", "data"]
"""The ``messages`` table of ``rosbag2``'s sqlite3 storage (``id INTEGER PRIMARY KEY``: the row id)."""

LEAF, INTERIOR = 0x0D, 0x05
"""Page types of a table B-tree."""

INDEX_LEAF, INDEX_INTERIOR = 0x0A, 0x02
"""Page types of an index B-tree."""


def table_max_local(usable: int) -> int:
    """The largest payload a table leaf cell holds in its page (a larger one spills to overflow pages)."""
    return usable - 35


class Unusual(Exception):
    """A file this module does not read: read the table with SQL."""


@dataclass
class Rows:
    """The rows of the table in id order.

    ``start`` and ``size`` locate each row's blob in ``data`` (the file's
    bytes); a row fetched by SQL has its blob in ``fetched`` instead (and
    ``start`` -1).
    """

    data: Mapped
    rowid: np.ndarray
    topic_id: np.ndarray
    log_ns: np.ndarray
    start: np.ndarray
    size: np.ndarray
    fetched: dict[int, bytes]
    summary: Summary | None = None


MOST_TOPICS = 256
"""Most topics a table may have for its :class:`Summary` (one pass over the rows each)."""


@dataclass(frozen=True)
class Summary:
    """What ``rosbags`` counts when it opens the table, made while it is read.

    Attributes
    ----------
    counts : dict of int to int
        Topic id -> rows (of every topic, not only those read).
    first : dict of int to bytes
        Topic id -> the blob of its first message (least timestamp, then id: the order of ``rosbags``' reader).
    start_ns, end_ns : int
        The least timestamp and the largest plus 1 (``rosbags``' ``start_time`` and ``end_time``).
    """

    counts: dict[int, int]
    first: dict[int, bytes]
    start_ns: int
    end_ns: int


def _be(u8: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """Unsigned big-endian integers of ``width`` bytes at ``at``."""
    out = np.zeros(len(at), dtype=np.int64)
    for k in range(width):
        out = (out << 8) | u8[at + k]
    return out


WINDOW = 48
"""Bytes of a cell decoded as one row of a matrix: its varints, record header and integers (a row whose fields go beyond is fetched alone)."""

BLOCK = 1 << 18
"""Cells decoded at a time (the matrix of their first bytes stays small)."""


class _Cells:
    """The first :data:`WINDOW` bytes of a block of cells as a matrix, read field by field at per-row offsets."""

    def __init__(self, u8: np.ndarray, cell: np.ndarray) -> None:
        top = len(u8) - WINDOW
        self.inside = cell <= top
        windows = as_strided(u8, shape=(top + 1, WINDOW), strides=(1, 1), writeable=False)
        self.w = windows[np.minimum(cell, top)].reshape(-1)  # one copy, row after row
        self.rows = np.arange(len(cell)) * WINDOW
        self.at = np.zeros(len(cell), dtype=np.int64)

    def byte(self, rows: np.ndarray, at: np.ndarray) -> np.ndarray:
        """Byte ``at`` of each row (``rows``: row offsets in the flat matrix)."""
        return self.w[rows + np.minimum(at, WINDOW - 1)].astype(np.int64)

    def varint(self) -> np.ndarray:
        """The varint at each row's offset (which moves past it)."""
        at = self.at
        first = self.byte(self.rows, at)
        values = first & 0x7F
        length = np.ones(len(at), dtype=np.int64)
        going = np.flatnonzero(first >= 0x80)
        for k in range(1, 9):
            if not len(going):
                break
            b = self.byte(self.rows[going], at[going] + k)
            if k < 8:
                values[going] = (values[going] << 7) | (b & 0x7F)
                length[going] = k + 1
                going = going[b >= 0x80]
            else:
                values[going] = (values[going] << 8) | b
                length[going] = 9
        self.at = at + length
        return values

    def integer(self, serial: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The integer of serial type ``serial`` at each row's offset (which moves past it); and its width (-1: not an integer)."""
        out = np.zeros(len(serial), dtype=np.int64)
        width = np.full(len(serial), -1, dtype=np.int64)
        for kind, size in INT_WIDTH.items():
            rows = np.flatnonzero(serial == kind)
            if not len(rows):
                continue
            width[rows] = size
            if kind == 9:
                out[rows] = 1
                continue
            value = np.zeros(len(rows), dtype=np.int64)
            for k in range(size):
                value = (value << 8) | self.byte(self.rows[rows], self.at[rows] + k)
            if 0 < size < 8:  # two's complement of `size` bytes
                sign = np.int64(1) << (8 * size - 1)
                value = (value ^ sign) - sign
            out[rows] = value
        self.at = self.at + np.maximum(width, 0)
        return out, width


INT_WIDTH = {1: 1, 2: 2, 3: 3, 4: 4, 5: 6, 6: 8, 8: 0, 9: 0}
"""Serial types of integers -> bytes of their value (8 and 9: the constants 0 and 1)."""


def _schema_ok(db: sqlite3.Connection) -> int:
    """The root page of ``messages`` when the table is ``rosbag2``'s (its columns in order, the id its row id); else :class:`Unusual`."""
    found = db.execute("SELECT rootpage, sql FROM sqlite_master WHERE type = 'table' AND name = 'messages'").fetchall()
    if len(found) != 1 or not isinstance(found[0][0], int) or "WITHOUT ROWID" in str(found[0][1]).upper():
        raise Unusual
    info = db.execute("PRAGMA table_info(messages)").fetchall()
    if [row[1] for row in info] != COLUMNS or [str(row[2]).upper() for row in info][:1] != ["INTEGER"] or [row[5] for row in info] != [1, 0, 0, 0]:
        raise Unusual
    if any(origin == "pk" for _, _, _, origin, *_ in db.execute("PRAGMA index_list(messages)").fetchall()):
        raise Unusual
    return int(found[0][0])


def _leaves(u8: np.ndarray, root: int, page_size: int, pages: int) -> np.ndarray:
    """The table's leaf pages in key order (a depth-first walk of its interior pages)."""
    leaves: list[int] = []
    seen = set()
    stack = [root]
    while stack:
        page = stack.pop()
        if not 2 <= page <= pages or page in seen:  # page 1 holds the schema; a page twice is a cycle
            raise Unusual
        seen.add(page)
        base = (page - 1) * page_size
        kind = int(u8[base])
        if kind == LEAF:
            leaves.append(page)
            continue
        if kind != INTERIOR:
            raise Unusual
        count = int(_be(u8, np.array([base + 3]), 2)[0])
        if 12 + 2 * count > page_size:
            raise Unusual
        pointers = _be(u8, base + 12 + 2 * np.arange(count, dtype=np.int64), 2)
        if count and (pointers.min() < 12 + 2 * count or pointers.max() + 4 > page_size):
            raise Unusual
        children = _be(u8, base + pointers, 4).tolist()
        right = int(_be(u8, np.array([base + 8]), 4)[0])
        stack.extend(reversed([*children, right]))  # popped in order: the cells' children, then the rightmost
    return np.array(leaves, dtype=np.int64)


class Mapped(np.ndarray):
    """The file's bytes, mapped read-only; :meth:`release` lets the process's resident pages go (they stay in the page cache).

    Decoding touches every page of the table: without the release the whole
    file (245 MB for a 600 s, 1 kHz bag) would count in the process's peak
    resident memory; after it, a page read again is a minor fault.
    """

    mm: Any = None

    def release(self, start: int = 0, stop: int | None = None) -> None:
        """Let the resident pages of bytes ``start`` to ``stop`` go (the whole file by default; widened to whole pages)."""
        if self.mm is None or not hasattr(mmap, "MADV_DONTNEED"):
            return
        stop = len(self) if stop is None else min(int(stop), len(self))
        start = max(int(start), 0) // mmap.PAGESIZE * mmap.PAGESIZE
        if stop > start:
            self.mm.madvise(mmap.MADV_DONTNEED, start, stop - start)


def _mapped(path: Path) -> Mapped:
    with open(path, "rb") as stream:
        if not path.stat().st_size:
            raise Unusual
        mm = mmap.mmap(stream.fileno(), 0, flags=mmap.MAP_SHARED, prot=mmap.PROT_READ)
    out = np.frombuffer(mm, dtype=np.uint8).view(Mapped)
    out.mm = mm
    return out


def read(path: Path, db: sqlite3.Connection, wanted: set[int]) -> Rows:
    """The rows of ``messages`` whose topic id is in ``wanted``, in id order, from the file's pages.

    ``db`` is a read-only connection to ``path`` (for the schema, and the rows fetched alone).
    """
    for suffix in ("-wal", "-journal"):
        side = path.with_name(path.name + suffix)
        if side.exists() and side.stat().st_size:
            raise Unusual  # rows may live outside the main file
    db.execute("PRAGMA mmap_size = 0")  # sqlite3's own reads (the count, the rows fetched alone) through its small page cache, not a mapping of the file
    root = _schema_ok(db)
    u8 = _mapped(path)
    if len(u8) < 100 or bytes(u8[:16]) != b"SQLite format 3\x00":
        raise Unusual
    page_size = int(_be(u8, np.array([16]), 2)[0])
    page_size = 65536 if page_size == 1 else page_size
    usable = page_size - int(u8[20])
    if page_size < 512 or page_size & (page_size - 1) or usable < 480 or len(u8) % page_size:
        raise Unusual
    pages = len(u8) // page_size
    leaves = _leaves(u8, root, page_size, pages)
    base = (leaves - 1) * page_size
    counts = _be(u8, base + 3, 2)
    if (8 + 2 * counts > usable).any():
        raise Unusual
    width = 8 + 2 * int(counts.max()) if len(counts) else 8
    heads = u8[: pages * page_size].reshape(pages, page_size)[leaves - 1, :width].astype(np.int64)  # leaf headers and cell pointers
    slot = np.arange((width - 8) // 2)
    pointer = (heads[:, 8::2] << 8) | heads[:, 9::2]
    used = slot[None, :] < counts[:, None]
    if (used & ((pointer < 8 + 2 * counts[:, None]) | (pointer + 4 > usable))).any():
        raise Unusual
    cell = (base[:, None] + pointer)[used]  # row-major: page after page, each in its pointers' order
    del heads, pointer, used
    page_end = np.repeat(base + usable, counts)
    rowid, topic_id, log_ns, start, size = (np.empty(len(cell), dtype=np.int64) for _ in range(5))
    plain = np.empty(len(cell), dtype=bool)
    for a in range(0, len(cell), BLOCK):
        b = min(a + BLOCK, len(cell))
        rowid[a:b], topic_id[a:b], log_ns[a:b], start[a:b], size[a:b], plain[a:b] = _decode(u8, cell[a:b], page_end[a:b], usable)
        u8.release(int(cell[a:b].min()), int(page_end[a:b].max()))  # the block's pages, touched by the leaf headers' pass and its decoding
    del cell, page_end
    if len(rowid) > 1 and (np.diff(rowid) <= 0).any():
        raise Unusual  # a table's keys increase through its leaves
    if db.execute("SELECT count(*) FROM messages").fetchone()[0] != len(rowid):
        raise Unusual  # every row of the table was found
    fetched: dict[int, bytes] = {}
    for j in np.flatnonzero(~plain).tolist():
        got = db.execute("SELECT topic_id, timestamp, data FROM messages WHERE id = ?", (int(rowid[j]),)).fetchall()
        if len(got) != 1 or not all(isinstance(v, int) for v in got[0][:2]) or not isinstance(got[0][2], bytes):
            raise Unusual
        topic_id[j], log_ns[j], size[j], start[j] = got[0][0], got[0][1], len(got[0][2]), -1
        fetched[j] = got[0][2]
    summary = _summary(u8, topic_id, log_ns, start, size, fetched)
    keep = np.zeros(len(topic_id), dtype=bool)
    for tid in wanted:  # a few topics: one comparison each
        keep |= topic_id == tid
    if keep.all():  # every topic is read: the columns as they are, not a copy
        return Rows(u8, rowid, topic_id, log_ns, start, size, fetched, summary)
    order = np.flatnonzero(keep)
    fetched = {int(np.searchsorted(order, j)): blob for j, blob in fetched.items() if keep[j]}
    return Rows(u8, rowid[order], topic_id[order], log_ns[order], start[order], size[order], fetched, summary)


def _summary(u8: np.ndarray, topic_id: np.ndarray, log_ns: np.ndarray, start: np.ndarray, size: np.ndarray, fetched: dict[int, bytes]) -> Summary | None:
    """Each topic's rows and first message, and the time range (None for an empty table or more than :data:`MOST_TOPICS` topics)."""
    if not len(topic_id):
        return None
    ids = np.unique(topic_id[:: max(1, len(topic_id) // 4096)])  # the topics of a sample of rows; all are checked below
    if len(ids) > MOST_TOPICS:
        return None
    counts: dict[int, int] = {}
    first: dict[int, bytes] = {}
    for tid in ids.tolist():
        mine = np.flatnonzero(topic_id == tid)
        j = int(mine[int(np.argmin(log_ns[mine]))])  # the first of the least timestamps: the least id among them
        counts[tid] = len(mine)
        first[tid] = fetched[j] if j in fetched else bytes(u8[start[j] : start[j] + size[j]])
    if sum(counts.values()) != len(topic_id):  # a topic the sample missed
        return None
    return Summary(counts, first, int(log_ns.min()), int(log_ns.max()) + 1)


def _decode(u8: np.ndarray, cell: np.ndarray, page_end: np.ndarray, usable: int) -> tuple[np.ndarray, ...]:
    """Row id, topic id, timestamp, blob start and size of each cell, and whether it is plain (else fetched alone by its id)."""
    cells = _Cells(u8, cell)
    payload = cells.varint()
    rowid = cells.varint()
    record = cell + cells.at
    plain = cells.inside & (payload <= table_max_local(usable))  # else the payload spills to overflow pages
    if (plain & (record + payload > page_end)).any():
        raise Unusual  # a cell past its page
    head_at = cells.at
    head = cells.varint()
    s_id, s_topic, s_time, s_data = (cells.varint() for _ in COLUMNS)
    plain &= cells.at == head_at + head
    plain &= (s_id == 0) & (s_data >= 14) & (s_data % 2 == 0)  # id NULL (the row id), data a blob of at least a byte
    topic_id, w_topic = cells.integer(s_topic)
    log_ns, w_time = cells.integer(s_time)
    size = (s_data - 12) // 2
    plain &= (w_topic >= 0) & (w_time >= 0) & (cells.at <= WINDOW) & (head + w_topic + w_time + size == payload)
    start = np.where(plain, cell + cells.at, -1)
    return rowid, topic_id, log_ns, start, size, plain
