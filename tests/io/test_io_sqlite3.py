"""ROS 2 sqlite3 bags in bulk: the read in batches joined by sqlite3 (their checks, the row-by-row
fall-backs) and the write in statements that sqlite3 cuts into rows (the
write as B-tree pages: tests/io/test_sqlitewrite.py).

Every bag read here is also read message by message through ``rosbags``; the
columns must have the same bits (:func:`tests.io.test_io_differential.read_both`).
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import WriteOptions, read_log, ros2sqlite, rosbulk, write_log
from ilic_cli.runlog import RunLog
from tests.conftest import make_synthetic_log
from tests.io.test_io_differential import assert_log_equals_source, read_both

N = 3000


def _table(rows: list[tuple[object, ...]], key: str = "INTEGER PRIMARY KEY") -> sqlite3.Connection:
    db = sqlite3.connect(":memory:")
    db.execute(f"CREATE TABLE messages(id {key}, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL)")
    db.executemany("INSERT INTO messages VALUES (?, ?, ?, ?)", rows)
    return db


ROWS = [(1, 1, -5, b"\x00\x01\x00"), (2, 2, 2**63 - 1, b""), (5, 1, 7, b"\xff\xfe\x00abc"), (9, 3, 8, b"x" * 300)]
JOINED = ros2sqlite.SQL_JOINED.format(ids="1, 2")
ROWS_SQL = ros2sqlite.SQL_ROWS.format(ids="1, 2")
ALL = (-(2**63), 2**63 - 1)


def test_joined_batch_gives_the_rows_of_the_wanted_topics_in_the_range_in_id_order() -> None:
    topic_id, log_ns, sizes, buf = ros2sqlite._joined_batch(_table(ROWS), JOINED, *ALL)  # type: ignore[misc]
    assert topic_id.tolist() == [1, 2, 1]
    assert log_ns.tolist() == [-5, 2**63 - 1, 7]  # int64 extremes survive the decimal text
    assert sizes.tolist() == [3, 0, 6]
    assert buf.tobytes() == b"\x00\x01\x00\xff\xfe\x00abc"  # NULs inside blobs are kept
    assert ros2sqlite._joined_batch(_table(ROWS), JOINED, 2, 5)[1].tolist() == [2**63 - 1, 7]  # type: ignore[index]
    assert len(ros2sqlite._joined_batch(_table(ROWS), JOINED, 6, 8)[0]) == 0  # type: ignore[index]  # none in the range: an empty batch


@pytest.mark.parametrize(
    "row",
    [(3, 1, 6, "t\u00e9xt"), (3, 1, 6, "text"), (3, 1, 6, 12), (3, 1, 6.5, b"ab"), (3, 1, "later", b"ab")],
    ids=["non-ascii-text-data", "ascii-text-data", "integer-data", "real-timestamp", "text-timestamp"],
)
def test_joined_batch_refuses_rows_of_other_types(row: tuple[object, ...]) -> None:
    """Such a batch goes row by row, where the values keep their type (as on the per-message path)."""
    assert ros2sqlite._joined_batch(_table([*ROWS, row]), JOINED, *ALL) is None


def test_joined_batch_refuses_ids_that_do_not_increase_or_leave_the_range() -> None:
    """The ids checked are the ones joined: rows visited in another order, or outside the range, are refused, not read."""
    backwards = JOINED.replace("FROM messages", "FROM (SELECT * FROM messages ORDER BY id DESC LIMIT 100)")
    assert ros2sqlite._joined_batch(_table(ROWS), backwards, *ALL) is None
    wider = JOINED.replace("BETWEEN ?1 AND ?2", "BETWEEN ?1 AND ?2 + 4")
    assert ros2sqlite._joined_batch(_table(ROWS), wider, 1, 2) is None


@pytest.mark.parametrize(
    ("key", "rowid"),
    [("INTEGER PRIMARY KEY", True), ("integer primary key", True), ("INTEGER PRIMARY KEY DESC", False), ("PRIMARY KEY", False), ("INTEGER", False)],
)
def test_only_an_id_that_is_the_rowid_is_read_in_ranges(key: str, rowid: bool) -> None:
    assert ros2sqlite._id_is_rowid(_table(ROWS, key)) is rowid
    without = sqlite3.connect(":memory:")
    without.execute("CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB) WITHOUT ROWID")
    assert not ros2sqlite._id_is_rowid(without)


@pytest.mark.parametrize("joined", [True, False], ids=["joined", "row-by-row"])
def test_id_ranges_take_every_id_from_the_smallest_to_the_largest(monkeypatch: pytest.MonkeyPatch, joined: bool) -> None:
    monkeypatch.setattr(ros2sqlite, "SQL_BATCH", 2)
    db = _table([(-(2**63), 1, 1, b"a"), (-1, 2, 2, b"bb"), (0, 1, 3, b"c"), (7, 2, 4, b"dd"), (2**63 - 1, 1, 5, b"e")])
    ranges = list(ros2sqlite._id_ranges(db))
    assert ranges == [(-(2**63), -(2**63) + 1), (-1, 0), (7, 8), (2**63 - 1, 2**63 - 1)]
    batches = [ros2sqlite._range_batch(db, JOINED if joined else None, ROWS_SQL, *r) for r in ranges]
    assert [len(b[0]) for b in batches] == [1, 2, 1, 1]
    assert np.concatenate([b[1] for b in batches]).tolist() == [1, 2, 3, 4, 5]
    assert b"".join(b[3].tobytes() for b in batches) == b"abbcdde"
    assert list(ros2sqlite._id_ranges(_table([]))) == []


@pytest.fixture
def bag(tmp_path: Path) -> tuple[Path, object]:
    log = make_synthetic_log(samples=N)
    return write_log(log, tmp_path / "bag", options=WriteOptions(storage="sqlite3")), log


def _spy(monkeypatch: pytest.MonkeyPatch, refuse_every: int = 0) -> list[bool]:
    """Record whether each batch was joined; refuse every ``refuse_every``-th joined batch (0: none).

    The read off the file's pages (tests/io/test_sqlitepages.py) is turned off: the SQL path is the one spied on.
    """
    monkeypatch.setattr(ros2sqlite, "_feed_pages", lambda *args: False)
    joined: list[bool] = []
    original = ros2sqlite._joined_batch

    def spy(db: sqlite3.Connection, joined_sql: str, first: int, last: int):  # type: ignore[no-untyped-def]
        got = original(db, joined_sql, first, last)
        if got is not None and refuse_every and (len(joined) + 1) % refuse_every == 0:
            got = None
        joined.append(got is not None)
        return got

    monkeypatch.setattr(ros2sqlite, "_joined_batch", spy)
    return joined


def test_small_batches_joined_and_fetched_give_the_per_message_columns(bag: tuple[Path, object], monkeypatch: pytest.MonkeyPatch) -> None:
    path, log = bag
    monkeypatch.setattr(ros2sqlite, "SQL_BATCH", 1000)  # 9001 rows: 10 batches, batch edges inside samples
    joined = _spy(monkeypatch, refuse_every=3)
    assert_log_equals_source(read_both(path), log)
    assert joined[:10] == [True, True, False, True, True, False, True, True, False, True]


def test_our_bag_is_read_in_joined_batches(bag: tuple[Path, object], monkeypatch: pytest.MonkeyPatch) -> None:
    path, log = bag
    joined = _spy(monkeypatch)
    assert_log_equals_source(read_both(path), log)
    assert joined == [True]  # one batch of 9001 rows


@pytest.mark.parametrize(
    ("table", "update"),
    [
        ("plain(id INTEGER, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL)", ""),
        # a text id sorts after every number: ranges of numbers would miss its message
        ("plain(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB) WITHOUT ROWID", "UPDATE messages SET id = 'last' WHERE id = 10;"),
    ],
    ids=["no-key", "without-rowid-text-id"],
)
def test_bag_whose_ids_are_not_the_rowid_is_read_through_one_cursor(bag: tuple[Path, object], monkeypatch: pytest.MonkeyPatch, table: str, update: str) -> None:
    """``messages.id`` that is not the ``rowid`` (another writer): no batches by id, same columns."""
    path, log = bag
    db_file = next(path.glob("*.db3"))
    with sqlite3.connect(db_file) as db:
        db.executescript(
            f"CREATE TABLE {table}; INSERT INTO plain SELECT * FROM messages ORDER BY id; DROP TABLE messages; ALTER TABLE plain RENAME TO messages;{update}"
        )
    db.close()
    joined = _spy(monkeypatch)
    assert_log_equals_source(read_both(path), log)
    assert joined == []


@pytest.mark.parametrize("samples", [1, 3, 4])
def test_insert_statement_cuts_blobs_and_stamps_into_rows_in_order(samples: int) -> None:
    """Up to ``most`` samples (4: a 2 x 2 counter), each with a message of topic 7 (2 bytes) then one of topic 3 (3 bytes)."""
    db = _table([])
    stamps = np.array([-(2**63), -5, 0, 2**63 - 1], dtype=np.int64)[:samples]
    text = np.char.zfill(stamps.astype(f"S{rosbulk.STAMP_DIGITS}"), rosbulk.STAMP_DIGITS).tobytes()
    messages = b"".join(b"a%d\x00b%d" % (i, i) for i in range(samples))
    db.execute(rosbulk.insert_rows_sql([7, 3], [2, 3], 4), [samples, text, messages])
    rows = db.execute("SELECT id, topic_id, timestamp, data FROM messages").fetchall()
    assert rows == [(i + 1, (7, 3)[i % 2], int(stamps[i // 2]), (b"a%d" % (i // 2)) if i % 2 == 0 else b"\x00b%d" % (i // 2)) for i in range(2 * samples)]


def test_bulk_sqlite3_writer_gives_the_per_message_bytes_across_statements(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The bulk writer's SQL path (the page path gives the same rows, not the same bytes: tests/io/test_sqlitewrite.py)."""
    log = make_synthetic_log(samples=N)
    monkeypatch.setattr(rosbulk, "SAMPLES_PER_INSERT", 700)  # 5 statements, the last one short
    monkeypatch.setattr(rosbulk.BulkSqlite3Storage, "pages", False)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    bulk = write_log(log, tmp_path / "a" / "bag", options=WriteOptions(storage="sqlite3", fast=True))
    each = write_log(log, tmp_path / "b" / "bag", options=WriteOptions(storage="sqlite3", fast=False))
    assert (bulk / "bag.db3").read_bytes() == (each / "bag.db3").read_bytes()


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_simulate_writes_either_ros2_bag_storage(tmp_path: Path, storage: str) -> None:
    """``ilic simulate --format rosbag2 --storage S``: the bag's storage file is S's, with the log of the .mcap output."""
    from tests.clirun import run_cli

    args = ["simulate", "--scenario", "paper-sim", "--duration", "1", "--seed", "2"]
    assert run_cli(*args, "-o", str(tmp_path / "x.mcap")).status == 0
    assert run_cli(*args, "-o", str(tmp_path / "bag"), "--format", "rosbag2", "--storage", storage).status == 0
    assert [p.suffix for p in sorted((tmp_path / "bag").iterdir())] == [{"sqlite3": ".db3", "mcap": ".mcap"}[storage], ".yaml"]
    log = read_log(tmp_path / "x.mcap")
    assert_log_equals_source(read_both(tmp_path / "bag"), RunLog(log.channels, log.units, {k: v for k, v in log.meta.items() if k != "source"}))


def test_rosbags_opens_bags_without_automatic_indexes_and_mapped_and_only_then(tmp_path: Path) -> None:
    import apsw

    def settings() -> tuple[int, int]:
        db = apsw.Connection(str(tmp_path / "x.db3"))
        return int(db.execute("PRAGMA automatic_index").fetchall()[0][0]), int(db.execute("PRAGMA mmap_size").fetchall()[0][0])

    hooks = list(apsw.connection_hooks)
    with pytest.raises(KeyError), ros2sqlite.rosbags_sqlite_settings():
        assert settings() == (0, ros2sqlite.SQL_MMAP)
        raise KeyError("a failed open")
    assert settings() == (1, 0)
    assert apsw.connection_hooks == hooks


@pytest.mark.parametrize("uncounted", [False, True])
def test_fast_read_opens_the_storage_without_counting(bag: tuple[Path, object], uncounted: bool) -> None:
    """The storage's topics stay (ids, names, types); only the counts of its scans go; ``metadata.yaml``'s remain."""
    from rosbags.rosbag2 import Reader

    path, _ = bag
    reader = Reader(path)
    with ros2sqlite.rosbags_sqlite_settings(uncounted=uncounted):
        reader.open()
    try:
        (storage,) = reader.storage.storages  # type: ignore[attr-defined]
        assert [(c.id, c.topic, c.msgcount) for c in storage.connections] == [(c.id, c.topic, 0 if uncounted else c.msgcount) for c in reader.connections]
        assert {c.topic: c.msgcount for c in reader.connections}["/joint_states"] == N
        assert storage.metadata.message_count == (0 if uncounted else 3 * N + 1)
    finally:
        reader.close()


@pytest.mark.parametrize("count", [10**15, -3, "many"])
def test_counts_of_metadata_yaml_are_only_a_hint(bag: tuple[Path, object], count: object) -> None:
    """A bag whose metadata.yaml claims another message count reads the same (the count only sizes the columns)."""
    path, log = bag
    yaml = (path / "metadata.yaml").read_text()
    assert f"message_count: {N}\n" in yaml
    (path / "metadata.yaml").write_text(yaml.replace(f"message_count: {N}\n", f"message_count: {count!r}\n".replace("'", '"')))
    assert_log_equals_source(read_log(path), log)
