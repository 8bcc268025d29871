"""The ``messages`` table and its ``timestamp_idx`` index written as B-tree pages (:mod:`ilic_cli.io.sqlitewrite`, issue 33).

Every file written as pages is checked against the same rows inserted by
sqlite3 (:meth:`ilic_cli.io.rosbulk.BulkSqlite3Storage.insert_sql`): the same
rows by id and through the index, sqlite3's own integrity check (the index
against the table, the pages' free space), and :mod:`ilic_cli.io.sqlitepages`
reading it off the pages; bags written through ``write_log`` are also read by
``rosbags`` and by ``ilic info`` and ``ilic identify``.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.enums import CompressionMode

from ilic_cli.io import WriteOptions, rosbulk, sqlitecells, sqlitepages, sqlitewrite, write_log
from tests.clirun import run_cli
from tests.conftest import make_synthetic_log


@dataclass
class Samples:
    """A stand-in for :class:`ilic_cli.io.rosencode.Columns`: per sample one message of each topic, of the topic's size."""

    log_ns: np.ndarray
    sizes: dict[str, int]

    def sample_topics(self) -> list[str]:
        return list(self.sizes)

    def rows(self, topic: str, start: int, stop: int) -> np.ndarray:
        k = list(self.sizes).index(topic)
        i = np.arange(start, stop, dtype=np.int64)[:, None]
        return ((i * 31 + np.arange(self.sizes[topic]) * 7 + k * 101) % 251).astype(np.uint8)


IDS = {"/a": 1, "/b": 300, "/c": 7}
"""Topic ids of serial types 9 (the constant 1), 2 and 1."""

STAMPS = [-(2**40), -129, -1, 0, 0, 1, 127, 128, 255, 256, 2**15, 2**23, 2**31, 2**47, 2**62, 2**63 - 1]
"""Nondecreasing timestamps of every integer width (and repeated)."""


def _write(folder: Path, samples: Samples, ids: dict[str, int], pages: bool, before: bool = True, after: bool = False) -> Path:
    """A file written by the bulk storage: a message that spills to overflow pages (as the bag's metadata does), the samples, maybe one more message."""
    folder.mkdir()
    storage = rosbulk.BulkSqlite3Storage(folder, CompressionMode.NONE)
    storage.pages = pages
    if before:
        storage.write(SimpleNamespace(id=9), int(samples.log_ns[0]), b"metadata" * 1000)
    storage.add_samples(samples, ids)  # type: ignore[arg-type]  # a stand-in for Columns
    if after:
        storage.write(SimpleNamespace(id=9), -5, b"late")
    storage.close(9, "bag metadata")
    return storage.path


def _rows(path: Path) -> tuple[list[tuple[object, ...]], ...]:
    with sqlite3.connect(path) as db:
        by_id = db.execute("SELECT * FROM messages ORDER BY id").fetchall()
        by_index = db.execute("SELECT id, timestamp FROM messages INDEXED BY timestamp_idx ORDER BY timestamp").fetchall()
        rest = db.execute("SELECT type, name, tbl_name, rootpage, sql FROM sqlite_master").fetchall()
        rest += db.execute("SELECT * FROM metadata").fetchall() + db.execute("SELECT * FROM schema").fetchall()
        checks = db.execute("PRAGMA integrity_check").fetchall() + db.execute("PRAGMA quick_check").fetchall()
    db.close()
    return by_id, by_index, rest, checks


def _depth(path: Path, name: str) -> int:
    """Levels of a B-tree (its left-most path)."""
    with sqlite3.connect(path) as db:
        root = db.execute("SELECT rootpage FROM sqlite_master WHERE name = ?", (name,)).fetchone()[0]
        size = db.execute("PRAGMA page_size").fetchone()[0]
    db.close()
    data = path.read_bytes()
    page, depth = root, 1
    while data[(page - 1) * size] in (sqlitepages.INTERIOR, sqlitepages.INDEX_INTERIOR):
        at = (page - 1) * size
        first = int.from_bytes(data[at + 12 : at + 14], "big")
        page, depth = int.from_bytes(data[at + first : at + first + 4], "big"), depth + 1
    return depth


def _pages_read(path: Path) -> list[tuple[int, int, int, bytes]]:
    db = sqlite3.connect(path.resolve().as_uri() + "?mode=ro&immutable=1", uri=True)
    try:
        rows = sqlitepages.read(path, db, set(IDS.values()) | {9})
        assert not rows.fetched or list(rows.fetched) == [0]  # only the message that spills is fetched by SQL
        return [(int(rows.rowid[j]), int(rows.topic_id[j]), int(rows.log_ns[j]), int(rows.size[j])) for j in range(len(rows.rowid))]  # type: ignore[misc]
    finally:
        db.close()


@pytest.fixture
def written(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The row counts :func:`ilic_cli.io.sqlitewrite.write_trees` wrote (its calls)."""
    calls: list[int] = []
    real = sqlitewrite.write_trees

    def spy(path: Path, table_root: int, index_root: int, prior: sqlitewrite.Before, bulk: sqlitecells.Bulk) -> None:
        calls.append(len(prior.rowid) + len(bulk.log_ns) * len(bulk.topic_ids))
        real(path, table_root, index_root, prior, bulk)

    monkeypatch.setattr(sqlitewrite, "write_trees", spy)
    return calls


def _same_as_sql(tmp_path: Path, samples: Samples, ids: dict[str, int], **kw: bool) -> Path:
    pages = _write(tmp_path / "pages", samples, ids, pages=True, **kw)
    sql = _write(tmp_path / "sql", samples, ids, pages=False, **kw)
    got, want = _rows(pages), _rows(sql)
    assert got[3] == [("ok",), ("ok",)]  # sqlite3's own checks: the index against the table, every page accounted for
    assert got[0] == want[0]
    assert got[1] == want[1] == sorted(want[1], key=lambda row: (row[1], row[0]))
    assert got[2] == want[2]  # the schema (root pages unmoved), the other tables
    return pages


def test_topics_of_every_size_and_id_give_sqlites_rows(tmp_path: Path, written: list[int]) -> None:
    """1001 samples (the last leaf page part full), timestamps of every width, messages of 1 to 3000 bytes."""
    log_ns = np.sort(np.resize(np.array(STAMPS, dtype=np.int64), 1001))
    samples = Samples(log_ns, {"/a": 1, "/b": 200, "/c": 3000})
    path = _same_as_sql(tmp_path, samples, IDS)
    assert written == [1 + 3003]
    got = _pages_read(path)
    assert [row[:3] for row in got[1:]] == [(2 + j, tid, int(log_ns[j // 3])) for j, tid in zip(range(3003), [1, 300, 7] * 1001)]
    assert [row[3] for row in got[1:4]] == [1, 200, 3000]


def test_three_levels_in_both_trees(tmp_path: Path, written: list[int]) -> None:
    """30000 samples of two topics: 60001 rows, interior pages over interior pages in the table and in the index."""
    samples = Samples(2**62 + np.arange(30000, dtype=np.int64) * 1_000_000 // 3, {"/a": 2, "/b": 40})
    path = _same_as_sql(tmp_path, samples, {"/a": 1, "/b": 300})
    assert written == [60001]
    assert _depth(path, "messages") == 3
    assert _depth(path, "timestamp_idx") == 3
    assert len(_pages_read(path)) == 60001


def test_a_single_leaf_is_the_root(tmp_path: Path, written: list[int]) -> None:
    samples = Samples(np.array([5, 6], dtype=np.int64), {"/a": 3})
    path = _same_as_sql(tmp_path, samples, {"/a": 1}, before=False)
    assert written == [2]
    assert _depth(path, "messages") == _depth(path, "timestamp_idx") == 1


@pytest.mark.parametrize(
    ("samples", "kw"),
    [
        (Samples(np.arange(50, dtype=np.int64), {"/a": 1, "/b": 4100}), {}),
        (Samples(np.arange(50, dtype=np.int64)[::-1].copy(), {"/a": 10}), {}),
        (Samples(np.arange(50, dtype=np.int64), {"/a": 10}), {"after": True}),
    ],
    ids=["overflow-pages", "timestamps-decrease", "a-message-after"],
)
def test_rows_the_pages_do_not_take_are_inserted_by_sql(tmp_path: Path, written: list[int], samples: Samples, kw: dict[str, bool]) -> None:
    """A cell that would spill to overflow pages, an index not in id order, a message after the samples: sqlite3 inserts the rows, the same file."""
    pages = _write(tmp_path / "pages", samples, {"/a": 1, "/b": 2}, pages=True, **kw)
    sql = _write(tmp_path / "sql", samples, {"/a": 1, "/b": 2}, pages=False, **kw)
    assert written == []
    assert pages.read_bytes() == sql.read_bytes()
    assert _rows(pages)[3] == [("ok",), ("ok",)]


def test_bags_give_rosbags_and_ilics_own_view(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, written: list[int]) -> None:
    """A bag from ``write_log``: ``rosbags`` reads the same messages, ``ilic info`` and ``ilic identify`` say the same as of the bag sqlite3 wrote."""
    log = make_synthetic_log(samples=3000)
    (tmp_path / "pages").mkdir()
    (tmp_path / "sql").mkdir()
    pages = write_log(log, tmp_path / "pages" / "bag", options=WriteOptions(storage="sqlite3"))
    monkeypatch.setattr(rosbulk.BulkSqlite3Storage, "pages", False)
    sql = write_log(log, tmp_path / "sql" / "bag", options=WriteOptions(storage="sqlite3"))
    assert written == [1 + 3 * 3000]
    assert _rows(pages / "bag.db3")[:3] == _rows(sql / "bag.db3")[:3]
    assert _rows(pages / "bag.db3")[3] == [("ok",), ("ok",)]

    def messages(path: Path) -> list[tuple[str, int, bytes]]:
        with Reader(path) as reader:
            return [(conn.topic, stamp, bytes(data)) for conn, stamp, data in reader.messages()]

    assert messages(pages) == messages(sql)
    for command in ("info", "identify"):
        a, b = run_cli(command, str(pages)), run_cli(command, str(sql))
        assert a.status == b.status == 0
        assert a.stdout.replace(str(pages), "BAG") == b.stdout.replace(str(sql), "BAG")


def test_integers_take_sqlites_serial_types() -> None:
    values = [0, 1, 2, -1, 127, -128, 128, 32767, -32769, 2**23 - 1, 2**31 - 1, -(2**31), 2**31, 2**47 - 1, 2**47, -(2**63)]
    assert sqlitecells.serial_types(np.array(values, dtype=np.int64)).tolist() == [8, 9, 1, 1, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6]


def test_pages_hold_runs_of_cells_and_separators_go_up() -> None:
    """Cells of 10 bytes (12 with the pointer) in pages of 36: 3 a page; with separators, the cell after each page goes up, and the last page keeps one."""
    sizes = np.full(7, 10)
    assert sqlitewrite.pack(sizes, 36, separators=False) == [(0, 3), (3, 6), (6, 7)]
    assert sqlitewrite.pack(sizes, 36, separators=True) == [(0, 3), (4, 7)]
    assert sqlitewrite.pack(np.full(8, 10), 36, separators=True) == [(0, 3), (4, 6), (7, 8)]  # not (4, 7): 7 would go up, the last page empty
    assert sqlitewrite.pack(sizes, 36, separators=False, final=False) == [(0, 3), (3, 6)]  # the last cell waits for more
    for last in (np.array([7, 7, 25]), np.array([7, 25])):  # a cell too big for a page, last
        with pytest.raises(sqlitewrite.NotWritten):
            sqlitewrite.pack(last, 21, separators=True)


def _pack_one_page_at_a_time(sizes: np.ndarray, capacity: int, separators: bool, final: bool) -> list[tuple[int, int]] | None:
    """:func:`ilic_cli.io.sqlitewrite.pack` page after page (None: a cell that does not fit)."""
    n, runs, a = len(sizes), [], 0
    while a < n:
        b = a
        while b < n and int(np.sum(sizes[a : b + 1] + 2)) <= capacity:
            b += 1
        if b >= n:
            runs += [(a, n)] if final else []
            break
        if separators and b + 1 >= n:
            if not final:
                break
            b -= 1
        if b <= a:
            return None
        runs.append((a, b))
        a = b + 1 if separators else b
    return runs


def test_pages_by_doubling_are_the_pages_one_at_a_time() -> None:
    rng = np.random.default_rng(4)
    for _ in range(600):
        sizes = rng.integers(1, 40, int(rng.integers(0, 50)))
        capacity, separators, final = int(rng.integers(20, 200)), bool(rng.integers(2)), bool(rng.integers(2))
        try:
            got: list[tuple[int, int]] | None = sqlitewrite.pack(sizes, capacity, separators, final)
        except sqlitewrite.NotWritten:
            got = None
        assert got == _pack_one_page_at_a_time(sizes, capacity, separators, final), (sizes.tolist(), capacity, separators, final)
