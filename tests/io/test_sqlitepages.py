"""The ``messages`` table of a ROS 2 sqlite3 bag read off the file's pages (:mod:`ilic_cli.io.sqlitepages`, issue 33).

Against sqlite3 itself (the same rows, ids, topic ids, timestamps and blobs)
on tables of every integer width, blobs that spill to overflow pages, gaps,
deleted rows and page sizes; against ``rosbags``' per-message reader on bags;
and the files it leaves to SQL.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import overview, read_log, ros2sqlite, sqlitepages, write_log
from tests.conftest import make_synthetic_log
from tests.io.test_io_differential import assert_log_equals_source, read_both

SCHEMA = "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL)"
INTEGERS = [0, 1, -1, 127, 128, -129, 2**15, 2**23 - 1, -(2**23), 2**31, 2**40, 2**47, -(2**47), 2**62, 2**63 - 1, -(2**63)]


def _rows_of(path: Path, wanted: set[int]) -> list[tuple[int, int, int, bytes]]:
    db = sqlite3.connect(path.resolve().as_uri() + "?mode=ro&immutable=1", uri=True)
    try:
        rows = sqlitepages.read(path, db, wanted)
    finally:
        db.close()
    out = []
    for j in range(len(rows.rowid)):
        blob = rows.fetched[j] if rows.start[j] < 0 else rows.data[rows.start[j] : rows.start[j] + rows.size[j]].tobytes()
        out.append((int(rows.rowid[j]), int(rows.topic_id[j]), int(rows.log_ns[j]), blob))
    return out


def _sql_rows(path: Path, wanted: set[int]) -> list[tuple[int, int, int, bytes]]:
    with sqlite3.connect(path) as db:
        got = db.execute("SELECT id, topic_id, timestamp, data FROM messages ORDER BY id").fetchall()
    db.close()
    return [row for row in got if row[1] in wanted]


def _table(path: Path, page_size: int, rows: list[tuple[int, int, int, bytes]]) -> None:
    with sqlite3.connect(path) as db:
        db.execute(f"PRAGMA page_size = {page_size}")
        db.execute(SCHEMA)
        db.executemany("INSERT INTO messages VALUES (?, ?, ?, ?)", rows)
    db.close()


@pytest.mark.parametrize("page_size", [512, 4096, 65536])
def test_rows_are_sqlites_own(tmp_path: Path, page_size: int) -> None:
    rng = np.random.default_rng(5)
    rows = []
    rid = 0
    for i in range(3000):
        rid += int(rng.integers(1, 4)) if i % 100 else 2**20  # gaps, and ids of 3 and 4 bytes
        size = int(rng.choice([1, 7, 90, 200, 700, 5000])) if i % 7 == 0 else 96  # some spill to overflow pages
        rows.append((rid, int(rng.integers(1, 4)), INTEGERS[i % len(INTEGERS)], rng.bytes(size)))
    path = tmp_path / "t.db3"
    _table(path, page_size, rows)
    with sqlite3.connect(path) as db:
        db.execute("DELETE FROM messages WHERE id % 11 = 0")  # free blocks inside the pages
    db.close()
    for wanted in ({1, 2, 3}, {2}):
        assert _rows_of(path, wanted) == _sql_rows(path, wanted)


@pytest.mark.parametrize(
    ("sql", "why"),
    [
        ("INSERT INTO messages VALUES (99, 1, 5, 'text')", "a text blob"),
        ("INSERT INTO messages VALUES (99, 1, 5.5, x'00')", "a real timestamp"),
        ("CREATE TABLE other(x); DROP TABLE messages; CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id, data, timestamp)", "other columns"),
    ],
)
def test_tables_of_other_values_or_schemas_are_left_to_sql(tmp_path: Path, sql: str, why: str) -> None:
    path = tmp_path / "t.db3"
    _table(path, 4096, [(i, 1, i, b"ab") for i in range(1, 50)])
    with sqlite3.connect(path) as db:
        db.executescript(sql)
    db.close()
    with pytest.raises(sqlitepages.Unusual):
        _rows_of(path, {1})


def test_a_write_ahead_log_is_left_to_sql(tmp_path: Path) -> None:
    path = tmp_path / "t.db3"
    _table(path, 4096, [(i, 1, i, b"ab") for i in range(1, 50)])
    (tmp_path / "t.db3-wal").write_bytes(b"x" * 100)
    with pytest.raises(sqlitepages.Unusual):
        _rows_of(path, {1})


def test_a_corrupt_page_is_left_to_sql(tmp_path: Path) -> None:
    path = tmp_path / "t.db3"
    _table(path, 4096, [(i, 1, i, b"ab" * 40) for i in range(1, 500)])
    raw = bytearray(path.read_bytes())
    raw[4096 : 4096 + 12] = bytes(12)  # the messages table's root page: no longer a B-tree page
    path.write_bytes(bytes(raw))
    with pytest.raises(sqlitepages.Unusual):
        _rows_of(path, {1})


def _deep_table(path: Path) -> tuple[bytearray, int]:
    """A table three levels deep (512-byte pages); the file's bytes and the root page's offset."""
    _table(path, 512, [(i, 1 + i % 3, i, bytes([i % 251]) * 60) for i in range(1, 3000)])
    with sqlite3.connect(path) as db:
        (root,) = db.execute("SELECT rootpage FROM sqlite_master WHERE name = 'messages'").fetchone()
    db.close()
    raw = bytearray(path.read_bytes())
    assert raw[(root - 1) * 512] == sqlitepages.INTERIOR
    return raw, (root - 1) * 512


def test_a_deep_tree_gives_its_leaves_in_key_order(tmp_path: Path) -> None:
    path = tmp_path / "t.db3"
    _deep_table(path)
    assert _rows_of(path, {1, 2, 3}) == _sql_rows(path, {1, 2, 3})  # the leaves out of key order would give ids that do not increase


@pytest.mark.parametrize("target", ["root", "page 1", "past the end"])
def test_a_cycle_or_a_page_out_of_the_tree_is_left_to_sql(tmp_path: Path, target: str) -> None:
    path = tmp_path / "t.db3"
    raw, root_at = _deep_table(path)
    page = {"root": root_at // 512 + 1, "page 1": 1, "past the end": len(raw) // 512 + 1}[target]
    raw[root_at + 8 : root_at + 12] = page.to_bytes(4, "big")  # the root's rightmost child
    path.write_bytes(bytes(raw))
    with pytest.raises(sqlitepages.Unusual):
        _rows_of(path, {1})


@pytest.mark.parametrize("fast_writer", [True, False], ids=["bulk-writer", "per-message-writer"])
def test_bags_read_off_the_pages_give_rosbags_columns(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fast_writer: bool) -> None:
    from ilic_cli.io import WriteOptions

    log = make_synthetic_log(samples=4000)
    path = write_log(log, tmp_path / "bag", options=WriteOptions(storage="sqlite3", fast=fast_writer))
    fed: list[bool] = []
    original = ros2sqlite._feed_pages

    def spy(*args: object) -> bool:
        fed.append(original(*args))  # type: ignore[arg-type]
        return fed[-1]

    monkeypatch.setattr(ros2sqlite, "_feed_pages", spy)
    assert_log_equals_source(read_both(path), log)
    assert fed == [True]


def test_overview_after_a_read_is_rosbags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ilic info``'s topics of an sqlite3 bag from the read's counts: the overview ``rosbags`` gives, without its count of the table."""
    path = write_log(make_synthetic_log(samples=3000), tmp_path / "bag")
    read_log(path)
    assert ros2sqlite.table_summary(next(path.glob("*.db3"))) is not None
    fast = overview._bag2(path)
    assert fast == overview._bag(path)
    assert {t.topic: t.count for t in fast}["/joint_states"] == 3000
    monkeypatch.setattr(overview, "_bag", lambda path: [])  # the summary path must not call rosbags' counting reader
    assert overview._bag2(path) == fast
    (next(path.glob("*.db3"))).touch()  # another modification time: the summary is not this file's any more
    assert overview._bag2(path) == []
