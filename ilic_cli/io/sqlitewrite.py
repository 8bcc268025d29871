"""The ``messages`` table of a ROS 2 bag's sqlite3 file and its ``timestamp_idx`` index written as B-tree pages with NumPy.

sqlite3 builds both B-trees row by row (0.8-1 s for the 900k rows of a 300 s,
1 kHz log). This module writes their pages itself, per the sqlite3 file format
(https://www.sqlite.org/fileformat2.html), the inverse of
:mod:`ilic_cli.io.sqlitepages`: the cells come from
:mod:`ilic_cli.io.sqlitecells` a block of samples at a time, are cut into full
leaf pages of each tree as they come (a Python loop over pages, not rows),
and the interior levels are written at the end.

sqlite3 creates the file, the schema, the small tables and the rows written
before the bulk (the bag's metadata message, whose cell, spilling to overflow
pages, is copied as it is); :func:`write_trees` then puts the pages of both
trees after the file's last page, each tree's top page at its root page
(``sqlite_master``'s ``rootpage``, which does not move), and updates the
header (database size, file change counter and the version-valid-for
number). Pages are filled as full as their cells allow; no page is left
free. The index's entries are taken in row id order, so the timestamps must
not decrease (the caller inserts the rows with SQL otherwise).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ilic_cli.io.sqlitecells import WIDTH, Bulk, index_cells, index_fields, join, low_bytes, serial_types, table_cell_sizes, table_cells, varints
from ilic_cli.io.sqlitepages import INDEX_INTERIOR, INDEX_LEAF, INTERIOR, LEAF, table_max_local

if TYPE_CHECKING:
    from concurrent.futures import Future

HEADER = {LEAF: 8, INDEX_LEAF: 8, INTERIOR: 12, INDEX_INTERIOR: 12}
"""Bytes of a page's header by page type (an interior page's ends with its right-most child)."""

SAMPLES_PER_BLOCK = 16384
"""Samples whose cells are built at a time (in buffers of a few MB, reused)."""

SCHEMA_FORMAT = 4
"""The schema format number (header byte 44) whose records store the integers 0 and 1 as serial types 8 and 9."""


class NotWritten(Exception):
    """A file whose trees this module does not write (its root pages are not leaves, a header it does not expect): insert with SQL."""


def pack(sizes: np.ndarray, capacity: int, separators: bool, final: bool = True) -> list[tuple[int, int]]:
    """Runs ``[a, b)`` of cells, each filling a page (``capacity`` bytes for cells and their pointers), in order.

    With ``separators`` (index pages, interior pages) the cell after each run
    goes up to the parent page, not into a page, and the last run keeps at
    least one cell. Not ``final``: more cells follow, and only the pages that
    they cannot change are given (the cells after them wait).

    Each page is as full as it can be: a page starting at cell ``a`` ends at
    ``end[a]`` (one search for every cell at once), and the next starts at
    ``end[a]`` (or after it, the separator); the chain of starts from cell 0
    is followed by doubling (the starts so far, then where each of them
    leads twice as many pages on), not page by page.
    """
    n = len(sizes)
    if not n:
        return []
    cum = np.concatenate([[0], np.cumsum(np.asarray(sizes, dtype=np.int64) + 2)])
    end = np.searchsorted(cum, cum[:-1] + capacity, side="right") - 1
    step = end + 1 if separators else end
    jump = np.minimum(np.append(np.maximum(step, np.arange(1, n + 1)), n), n)  # cell n: past the last, where every chain stops
    chain = np.zeros(1, dtype=np.int64)
    while chain[-1] < n:
        chain = np.concatenate([chain, jump[chain]])
        jump = jump[jump]
    starts = chain[chain < n]
    ends = end[starts]
    if (ends[:-1] <= starts[:-1]).any():
        raise NotWritten  # a cell that does not fit a page
    runs = list(zip(starts[:-1].tolist(), ends[:-1].tolist()))
    a, b = int(starts[-1]), int(ends[-1])  # only the last page can reach the end
    if b >= n:
        runs += [(a, n)] if final else []
    elif separators and b == n - 1 and final:
        if b - 1 <= a or end[n - 1] < n:
            raise NotWritten
        runs += [(a, b - 1), (n - 1, n)]  # the separator would be the last cell, leaving the last page empty: one cell fewer
    elif not separators or b != n - 1:
        raise NotWritten  # a cell that does not fit a page
    return runs


def build(out: np.ndarray, kind: int, usable: int, flat: np.ndarray, starts: np.ndarray, runs: list[tuple[int, int]], rights: np.ndarray | None) -> None:
    """Fill the pages ``out`` (one row each, zeros) with runs of cells.

    Page ``i`` holds cells ``runs[i][0]:runs[i][1]``; cell ``j``'s bytes are
    ``flat[starts[j] - s:starts[j + 1] - s]``, ``s`` the start of the first
    run's first cell. The cells go back to back at the end of the page, in
    order, their pointers after the page's header; ``rights``: the interior
    pages' right-most children.
    """
    head = HEADER[kind]
    a = np.array([r[0] for r in runs], dtype=np.int64)
    b = np.array([r[1] for r in runs], dtype=np.int64)
    count = b - a
    content = usable - (starts[b] - starts[a])
    out[:, 0] = kind
    out[:, 3], out[:, 4] = count >> 8, count & 0xFF
    out[:, 5], out[:, 6] = (content >> 8) & 0xFF, content & 0xFF  # below 65536: pages of at most 32768 bytes
    if rights is not None:
        out[:, 8:12] = np.asarray(rights, dtype=">u4").view(np.uint8).reshape(-1, 4)
    page = np.repeat(np.arange(len(runs)), count)
    slot = np.arange(len(page)) - np.repeat(np.cumsum(count) - count, count)
    cell = a[page] + slot
    pointer = content[page] + starts[cell] - starts[a[page]]
    at = head + 2 * slot
    out[page, at], out[page, at + 1] = pointer >> 8, pointer & 0xFF
    base = int(starts[a[0]])
    lo, hi = (starts[a] - base).tolist(), (starts[b] - base).tolist()
    for i, c in enumerate(content.tolist()):
        out[i, c:usable] = flat[lo[i] : hi[i]]


@dataclass(frozen=True)
class Before:
    """What sqlite3 wrote of the two trees before the bulk: the rows (row id, timestamp) and the table's leaf cells, as they are."""

    rowid: np.ndarray
    log_ns: np.ndarray
    cells: bytes
    sizes: np.ndarray


def _be(data: bytes | bytearray, at: int, width: int) -> int:
    return int.from_bytes(bytes(data[at : at + width]), "big")


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = 0
    for k in range(9):
        byte = data[at + k]
        if k == 8:
            return (value << 8) | byte, at + 9
        value = (value << 7) | (byte & 0x7F)
        if byte < 0x80:
            return value, at + k + 1
    raise AssertionError  # unreachable


def header(path: Path) -> tuple[int, int, bytearray]:
    """The file's page size, usable page size and its first 100 bytes; :class:`NotWritten` for a header not expected."""
    with open(path, "rb") as stream:
        head = bytearray(stream.read(100))
    if len(head) < 100 or bytes(head[:16]) != b"SQLite format 3\x00":
        raise NotWritten
    page_size = _be(head, 16, 2)
    page_size = 65536 if page_size == 1 else page_size
    usable = page_size - head[20]
    if page_size < 512 or page_size > 32768 or page_size & (page_size - 1) or usable < 480:
        raise NotWritten
    if _be(head, 44, 4) != SCHEMA_FORMAT or _be(head, 52, 4) or head[18] != 1 or head[19] != 1:
        raise NotWritten  # another record format, auto-vacuum (pointer-map pages), a write-ahead log
    return page_size, usable, head


def before(path: Path, table_root: int, index_root: int, rowid: np.ndarray, log_ns: np.ndarray) -> Before:
    """The table's cells of the rows ``rowid`` (all of the table) from its root page, which must be a leaf, as must the index's root."""
    page_size, usable, _ = header(path)
    with open(path, "rb") as stream:
        stream.seek((table_root - 1) * page_size)
        page = stream.read(page_size)
        stream.seek((index_root - 1) * page_size)
        index = stream.read(page_size)
    if len(page) != page_size or len(index) != page_size or page[0] != LEAF or index[0] != INDEX_LEAF:
        raise NotWritten
    count = _be(page, 3, 2)
    if count != len(rowid) or _be(index, 3, 2) != len(rowid):
        raise NotWritten
    cells, sizes = [], []
    most = table_max_local(usable)
    for j in range(count):
        at = _be(page, 8 + 2 * j, 2)
        payload, after = _varint(page, at)
        key, after = _varint(page, after)
        if key != int(rowid[j]):
            raise NotWritten
        local = payload
        if payload > most:  # the payload's part in the page, then the first overflow page's number
            least = (usable - 12) * 32 // 255 - 23
            local = least + (payload - least) % (usable - 4)
            local = (local if local <= most else least) + 4
        if after + local > usable:
            raise NotWritten
        cells.append(page[at : after + local])
        sizes.append(after + local - at)
    return Before(rowid, log_ns, b"".join(cells), np.array(sizes, dtype=np.int64))


def write_trees(path: Path, table_root: int, index_root: int, prior: Before, bulk: Bulk) -> None:
    """Write the table and index B-trees of the rows ``prior`` then ``bulk`` (row ids following) into the closed file ``path``.

    A block of samples at a time, the rows' cells are cut into full leaf
    pages of each tree, written after the file's last page (the cells of a
    page not yet full wait for the next block); then the interior levels,
    each tree's top page at its root page; then the header. The index's
    entries are the rows in id order: the timestamps must not decrease
    (:class:`NotWritten` before anything is written, else).
    """
    page_size, usable, head = header(path)
    pages = path.stat().st_size // page_size
    if path.stat().st_size % page_size or (_be(head, 92, 4) == _be(head, 24, 4) and _be(head, 28, 4) != pages):
        raise NotWritten
    if not nondecreasing(prior.log_ns, bulk.log_ns):
        raise NotWritten
    first_rowid = int(prior.rowid.max()) + 1 if len(prior.rowid) else 1
    with open(path, "r+b") as stream:
        out = _Out(stream.fileno(), page_size, pages + 1)
        try:
            _trees(out, usable, table_root, index_root, prior, bulk, first_rowid)
        finally:
            out.close()
        counter = (_be(head, 24, 4) + 1) & 0xFFFF_FFFF  # one more change, and the size valid for it
        head[24:28] = counter.to_bytes(4, "big")
        head[28:32] = (out.next - 1).to_bytes(4, "big")
        head[92:96] = counter.to_bytes(4, "big")
        stream.seek(0)
        stream.write(head)


def _trees(out: _Out, usable: int, table_root: int, index_root: int, prior: Before, bulk: Bulk, first_rowid: int) -> None:
    """The pages of both trees: the leaves a block of samples at a time, then the interior levels."""
    k = len(bulk.topic_ids)
    n = len(bulk.log_ns)
    table = _Tree(out, LEAF, usable, table_root)
    index = _Tree(out, INDEX_LEAF, usable, index_root)
    table.space(len(prior.cells))[:] = np.frombuffer(prior.cells, dtype=np.uint8)
    table.add(prior.sizes, prior.log_ns, prior.rowid, final=n == 0)
    index.add_entries(prior.log_ns, prior.rowid, final=n == 0)
    for s in range(0, n, SAMPLES_PER_BLOCK):
        stop = min(s + SAMPLES_PER_BLOCK, n)
        sizes = table_cell_sizes(bulk, first_rowid, s, stop)
        table_cells(bulk, first_rowid, s, stop, table.space(int(sizes.sum())))
        log_ns = np.repeat(bulk.log_ns[s:stop], k)
        rowid = first_rowid + np.arange(s * k, stop * k, dtype=np.int64)
        table.add(sizes, log_ns, rowid, final=stop == n)
        index.add_entries(log_ns, rowid, final=stop == n)
    table.finish()
    index.finish()


def nondecreasing(prior: np.ndarray, log_ns: np.ndarray) -> bool:
    """Whether the timestamps of the rows before the bulk, then the bulk's samples', never decrease."""
    both = np.concatenate([prior, log_ns[:1]]) if len(log_ns) else prior
    return not ((np.diff(both) < 0).any() or (np.diff(log_ns) < 0).any())


class _Out:
    """Pages built in buffers taken in turn, written at their page numbers by a thread while the next pages are built.

    New pages are numbered from ``first``. A buffer is built again only once
    its write is done; the bytes written and where do not depend on the
    thread's timing.
    """

    BUFFERS = 2

    def __init__(self, fd: int, page_size: int, first: int) -> None:
        from concurrent.futures import ThreadPoolExecutor  # the writes overlap the building (os.pwrite lets the GIL go)

        self.fd, self.page_size, self.next = fd, page_size, first
        self.buffers = [np.zeros(0, dtype=np.uint8) for _ in range(self.BUFFERS)]
        self.writes: list[Future[None] | None] = [None] * self.BUFFERS
        self.turn = 0
        self.pool = ThreadPoolExecutor(1)

    def pages(self, count: int) -> np.ndarray:
        """``count`` pages of zeros, in the next buffer (for :meth:`put`)."""
        self.turn = (self.turn + 1) % self.BUFFERS
        self._wait(self.turn)
        size = count * self.page_size
        if len(self.buffers[self.turn]) < size:
            self.buffers[self.turn] = np.zeros(size, dtype=np.uint8)
        out = self.buffers[self.turn][:size].reshape(count, self.page_size)
        out[:] = 0
        return out

    def numbers(self, count: int, root: int | None) -> np.ndarray:
        """Numbers for ``count`` pages: the next new ones, or the root page for a tree's top page."""
        if root is not None:
            return np.array([root], dtype=np.int64)
        self.next += count
        return np.arange(self.next - count, self.next, dtype=np.int64)

    def put(self, numbers: np.ndarray, pages: np.ndarray) -> None:
        """Write ``pages`` (the last :meth:`pages`) at page numbers ``numbers`` (consecutive, or one page)."""
        self.writes[self.turn] = self.pool.submit(_write_at, self.fd, memoryview(pages.reshape(-1)), (int(numbers[0]) - 1) * self.page_size)  # type: ignore[arg-type]  # numpy's stubs give ndarray the buffer protocol only for Python >= 3.12

    def _wait(self, turn: int) -> None:
        write, self.writes[turn] = self.writes[turn], None
        if write is not None:
            write.result()  # its error, if any, raised here

    def close(self) -> None:
        """Wait for every write (raising the first error); stop the thread."""
        try:
            for turn in range(self.BUFFERS):
                self._wait(turn)
        finally:
            self.pool.shutdown(wait=True, cancel_futures=True)


def _write_at(fd: int, data: memoryview, offset: int) -> None:
    while len(data):
        done = os.pwrite(fd, data, offset)
        data, offset = data[done:], offset + done


class _Tree:
    """A table's (``LEAF``) or an index's (``INDEX_LEAF``) B-tree: leaf pages written as their cells come, the interior levels at the end.

    The cells not yet in a page wait at the start of a buffer, with their
    sizes, timestamps and row ids. A table's page is keyed by its last row
    id; between two index pages, an entry goes up to their parent.
    """

    def __init__(self, out: _Out, kind: int, usable: int, root: int) -> None:
        self.out, self.kind, self.usable, self.root = out, kind, usable, root
        self.separators = kind == INDEX_LEAF
        self.buffer = np.empty(0, dtype=np.uint8)
        self.held = 0
        self.sizes = np.zeros(0, dtype=np.int64)
        self.log_ns = np.zeros(0, dtype=np.int64)
        self.rowid = np.zeros(0, dtype=np.int64)
        self.children: list[np.ndarray] = []  # the leaf pages' numbers
        self.key_time: list[np.ndarray] = []  # the entries between them (a table: only the row ids count)
        self.key_rowid: list[np.ndarray] = []

    def space(self, size: int) -> np.ndarray:
        """Room for ``size`` bytes of cells after those waiting."""
        if len(self.buffer) < self.held + size:
            grown = np.empty(self.held + size + self.usable, dtype=np.uint8)
            grown[: self.held] = self.buffer[: self.held]
            self.buffer = grown
        return self.buffer[self.held : self.held + size]

    def add_entries(self, log_ns: np.ndarray, rowid: np.ndarray, final: bool) -> None:
        """Add index entries (``log_ns``, ``rowid``), in order."""
        sizes = 4 + WIDTH[serial_types(log_ns)] + WIDTH[serial_types(rowid)]  # payload size, a header of 3 bytes, the two integers
        index_cells(log_ns, rowid, self.space(int(sizes.sum())))
        self.add(sizes, log_ns, rowid, final)

    def add(self, sizes: np.ndarray, log_ns: np.ndarray, rowid: np.ndarray, final: bool) -> None:
        """Take the cells just written into :meth:`space` (``sizes`` bytes each); write the pages they fill."""
        self.held += int(sizes.sum())
        sizes = np.concatenate([self.sizes, sizes])
        log_ns = np.concatenate([self.log_ns, log_ns])
        rowid = np.concatenate([self.rowid, rowid])
        runs = pack(sizes, self.usable - HEADER[self.kind], self.separators, final)
        if runs:
            starts = np.concatenate([[0], np.cumsum(sizes)])
            top = final and len(runs) == 1 and not self.children
            numbers = self.out.numbers(len(runs), self.root if top else None)
            pages = self.out.pages(len(runs))
            build(pages, self.kind, self.usable, self.buffer, starts, runs, None)
            self.out.put(numbers, pages)
            self.children.append(numbers)
            after = np.array([b for _, b in runs], dtype=np.int64)
            if self.separators:
                after = after[after < len(sizes)]
                self.key_time.append(log_ns[after])
                self.key_rowid.append(rowid[after])
            else:
                self.key_rowid.append(rowid[after - 1])
            rest = runs[-1][1] + 1 if self.separators else runs[-1][1]
            used = int(starts[min(rest, len(sizes))])
        else:
            rest, used = 0, 0
        if final and rest < len(sizes):
            raise AssertionError("cells left out of the leaves")
        self.buffer[: self.held - used] = self.buffer[used : self.held]
        self.held -= used
        self.sizes, self.log_ns, self.rowid = sizes[rest:], log_ns[rest:], rowid[rest:]

    def finish(self) -> None:
        """Write the interior levels: each page's cells are the keys between its children, its right-most child in its header."""
        children = np.concatenate(self.children)
        rowid = np.concatenate(self.key_rowid)[: len(children) - 1]
        log_ns = np.concatenate(self.key_time)[: len(children) - 1] if self.separators else rowid
        kind = INDEX_INTERIOR if self.separators else INTERIOR
        while len(children) > 1:
            if self.separators:
                flat, sizes = join([low_bytes(children[: len(rowid)], 4), *index_fields(log_ns, rowid)])
            else:
                flat, sizes = join([low_bytes(children[: len(rowid)], 4), varints(rowid)])
            runs = pack(sizes, self.usable - HEADER[kind], separators=True)
            numbers = self.out.numbers(len(runs), self.root if len(runs) == 1 else None)
            pages = self.out.pages(len(runs))
            build(pages, kind, self.usable, flat, np.concatenate([[0], np.cumsum(sizes)]), runs, children[[b for _, b in runs]])
            self.out.put(numbers, pages)
            up = np.array([b for _, b in runs[:-1]], dtype=np.int64)
            children, rowid, log_ns = numbers, rowid[up], log_ns[up]
