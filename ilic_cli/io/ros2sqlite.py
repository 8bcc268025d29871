"""The messages of an sqlite3 ROS 2 bag's storage, read in bulk and handed to the sinks in runs.

:func:`feed_sqlite` reads the table off the file's pages
(:mod:`ilic_cli.io.sqlitepages`); for a file that module does not read, in
ranges of ids that sqlite3 joins into one row each (:data:`SQL_JOINED`), or
row by row. :func:`rosbags_sqlite_settings` is how ``rosbags`` opens the
storage (its planner and pager settings, and no message counts when the read
counts them itself).
"""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import as_strided
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

from ilic_cli.io import current_progress, sqlitepages


def single_sqlite(reader: Any) -> Any:
    """The bag's only storage when it is an uncompressed sqlite3 file, else None."""
    bag = getattr(reader, "storage", None)
    storages = getattr(bag, "storages", None)
    metadata = getattr(bag, "metadata", None)
    if not isinstance(storages, list) or len(storages) != 1 or not isinstance(storages[0], Sqlite3Reader):
        return None
    if metadata is None or metadata.compression_mode or not isinstance(storages[0].path, Path):
        return None
    return storages[0]


SQL_BATCH = 65536
"""Message ids per batch (so at most as many rows)."""

SQL_MMAP = 2**30
"""Bytes of the database file sqlite3 may map into memory (an address range, not resident memory)."""

SQL_JOINED = (
    "SELECT count(*), sum(CASE WHEN typeof(timestamp) = 'integer' AND typeof(data) = 'blob' THEN 0 ELSE 1 END), "
    "group_concat(id), group_concat(topic_id), group_concat(timestamp), group_concat(length(data)), CAST(group_concat(data, '') AS BLOB) "
    "FROM messages WHERE id BETWEEN ?1 AND ?2 AND topic_id IN ({ids})"
)
"""The messages of the wanted topics with ids from ``?1`` to ``?2`` as one row: their count, the rows whose timestamp
is not an integer or data not a blob, the rows' ids, topic ids, timestamps and blob sizes (decimal,
comma-separated) and their blobs, joined in the order sqlite3 visits the rows.

Plain SQL of any sqlite3 that Python 3.11 builds with (3.7.15 or later). sqlite3 visits a range of
``rowid`` in order, but SQL does not promise the order of ``group_concat``; the ids
come along, and :func:`_joined_batch` refuses a batch whose ids do not increase.
"""

SQL_ROWS = "SELECT id, topic_id, timestamp, data FROM messages WHERE id BETWEEN ? AND ? AND topic_id IN ({ids}) ORDER BY id"
"""The same rows as :data:`SQL_JOINED`, one by one."""

SQL_NEXT_ID = "SELECT min(id) FROM messages WHERE id >= ?"
"""The first message id from an id on (a search of the ``rowid`` tree, not a scan)."""

SQL_ALL_ROWS = "SELECT id, topic_id, timestamp, data FROM messages WHERE topic_id IN ({ids}) ORDER BY id"
"""Every message of the wanted topics, for one cursor."""


def feed_sqlite(storage: Any, wanted: list[Any], sinks: dict[int, Any], path: Path) -> None:
    """Read the messages in batches of :data:`SQL_BATCH` ids in id order and hand each topic's blobs to its sink as runs.

    sqlite3 joins each batch into one row (:data:`SQL_JOINED`, no Python
    object per message); a batch with a row of other types, or whose ids do
    not increase, is fetched again row by row. Within a batch, a topic's
    messages of one size at a constant distance in the joined blobs form one
    run (:meth:`ilic_cli.io.roscollect._Sink.add_run`). Sinks sort by log time
    (stably), which gives ``rosbags``' order: log time, then insertion.
    """
    by_id: dict[int, Any] = {}
    for conn in wanted:
        for stored in storage.connections:
            # rosbags' rule for matching a bag's topic with the storage's
            if (
                stored.topic == conn.topic
                and stored.msgtype == conn.msgtype
                and stored.ext == conn.ext
                and (not stored.digest or not conn.digest or stored.digest == conn.digest)
            ):
                by_id[int(stored.id)] = sinks[conn.id]
    if not by_id:
        return
    # the counts of metadata.yaml (rosbags' storage did not count): a hint, at most a message per byte of the file
    most = storage.path.stat().st_size
    counts = {conn.id: min(conn.msgcount, most) if isinstance(conn.msgcount, int) and conn.msgcount > 0 else 0 for conn in wanted}
    for conn in wanted:
        sinks[conn.id].reserve(counts[conn.id])
    total = sum(counts.values()) or 1
    done = 0
    ids = ", ".join(str(tid) for tid in sorted(by_id))
    db = sqlite3.connect(storage.path.resolve().as_uri() + "?mode=ro&immutable=1", uri=True)
    try:
        if _feed_pages(storage.path, db, by_id, path, total):
            return
        db.execute(f"PRAGMA mmap_size = {SQL_MMAP}")  # pages mapped, not copied through read()
        joined = db.execute("PRAGMA encoding").fetchone()[0] == "UTF-8"  # group_concat joins blobs as UTF-8 text
        if _id_is_rowid(db):
            joined_sql, rows_sql = (SQL_JOINED.format(ids=ids) if joined else None), SQL_ROWS.format(ids=ids)
            batches: Iterator[Batch] = (_range_batch(db, joined_sql, rows_sql, first, last) for first, last in _id_ranges(db))
        else:
            batches = _cursor_batches(db, SQL_ALL_ROWS.format(ids=ids))
        with current_progress(path) as progress:
            for topic_id, log_ns, sizes, buf in batches:
                starts = np.cumsum(sizes) - sizes
                for tid, sink in by_id.items():
                    mine = np.flatnonzero(topic_id == tid)
                    if len(mine):
                        _feed_runs(sink, buf, starts[mine], sizes[mine], log_ns[mine])
                done += len(sizes)
                if progress is not None:
                    progress(done, total)
    finally:
        db.close()


_TABLES: dict[tuple[str, int, int, int], Any] = {}
"""The :class:`~ilic_cli.io.sqlitepages.Summary` of the last sqlite3 file read off its pages, by the file's identity (:func:`_identity`)."""


def _identity(file: Path) -> tuple[str, int, int, int]:
    """The file's path, size, modification time and inode: another file, or the file changed, gives another key."""
    st = file.stat()
    return (str(file.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)


def table_summary(file: Path) -> Any:
    """The message counts, first messages and time range of the sqlite3 file ``file`` when this process just read it off its pages; else None."""
    try:
        return _TABLES.get(_identity(file))
    except OSError:
        return None


PAGE_BLOCK = 65536
"""Rows of the table whose messages are copied out of the file's pages at a time, every topic's (:func:`_feed_pages`)."""


def _feed_pages(file: Path, db: Any, by_id: dict[int, Any], path: Path, total: int) -> bool:
    """Feed the sinks from the table's rows read off the file's pages (:mod:`ilic_cli.io.sqlitepages`); False when that module does not read the file.

    The rows are taken :data:`PAGE_BLOCK` at a time, in id order; each
    topic's messages among them go to its sink in runs of one size: their
    blobs are copied out of the mapped file row after row (a window of the
    run's size at each blob's start), a message fetched by SQL alone. Then the
    block's pages leave the process's resident memory: every page is touched
    once here, whatever the topics.
    """
    try:
        rows = sqlitepages.read(file, db, set(by_id))
    except sqlitepages.Unusual:
        return False
    if rows.summary is not None:
        _TABLES.clear()  # the last table read only: a summary of a few topics
        _TABLES[_identity(file)] = rows.summary
    windows: dict[int, np.ndarray] = {}
    with current_progress(path) as progress:
        for c in range(0, len(rows.topic_id), PAGE_BLOCK):
            d = min(c + PAGE_BLOCK, len(rows.topic_id))
            for tid, sink in by_id.items():
                mine = np.flatnonzero(rows.topic_id[c:d] == tid) + c
                if len(mine):
                    _feed_rows(sink, rows, mine, windows)
            starts = rows.start[c:d]
            placed = starts >= 0
            if placed.any():
                rows.data.release(int(starts[placed].min()), int((starts + rows.size[c:d])[placed].max()))
            if progress is not None:
                progress(d, total)
    return True


def _feed_rows(sink: Any, rows: Any, mine: np.ndarray, windows: dict[int, np.ndarray]) -> None:
    """Rows ``mine`` (of one topic, in id order) to ``sink``: runs of one size copied out of the file, a row fetched by SQL alone."""
    sizes, starts, log_ns = rows.size[mine], rows.start[mine], rows.log_ns[mine]
    alone = starts < 0
    cut = np.flatnonzero((sizes[1:] != sizes[:-1]) | alone[1:] | alone[:-1]) + 1
    bounds = [0, *cut.tolist(), len(mine)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        if alone[a]:
            sink.add(int(log_ns[a]), rows.fetched[int(mine[a])])
            continue
        size = int(sizes[a])
        # each blob in a row padded to whole 8-byte words (the bytes after it in the file), so that the
        # rows start aligned and compare a word at a time (cdrcols.matching_rows); unpadded at the file's end
        padded = -(-size // 8) * 8
        width = padded if int(starts[a:b].max()) + padded <= len(rows.data) else size
        if width not in windows:
            windows[width] = as_strided(rows.data, shape=(len(rows.data) - width + 1, width), strides=(1, 1), writeable=False)
        sink.add_run(windows[width][starts[a:b]].reshape(-1), 0, width, b - a, size, log_ns[a:b])


Batch = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Topic ids, timestamps, blob sizes (int64 each) and the joined blobs (uint8) of a batch of rows."""


def _id_ranges(db: Any) -> Iterator[tuple[int, int]]:
    """Ranges of :data:`SQL_BATCH` ids (first and last, inclusive), each from the first id after the range before, up to the largest id."""
    last = 2**63 - 1
    (first,) = db.execute(SQL_NEXT_ID, (-(2**63),)).fetchone()
    while first is not None:
        end = min(int(first) + SQL_BATCH - 1, last)
        yield int(first), end
        if end == last:
            return
        (first,) = db.execute(SQL_NEXT_ID, (end + 1,)).fetchone()


def _range_batch(db: Any, joined_sql: str | None, rows_sql: str, first: int, last: int) -> Batch:
    """The rows with ids from ``first`` to ``last``: joined by sqlite3 when ``joined_sql`` is given and they can be (:func:`_joined_batch`), else one by one."""
    got = _joined_batch(db, joined_sql, first, last) if joined_sql is not None else None
    return got if got is not None else _split_rows(db.execute(rows_sql, (first, last)).fetchall())


def _cursor_batches(db: Any, all_sql: str) -> Iterator[Batch]:
    """Batches of the rows of ``all_sql`` through one cursor (``messages.id`` is not known to be the ``rowid``)."""
    cursor = db.execute(all_sql)
    while rows := cursor.fetchmany(SQL_BATCH):
        yield _split_rows(rows)


def _id_is_rowid(db: Any) -> bool:
    """Whether ``messages.id`` is the ``rowid`` of its table: the only primary key, declared INTEGER, no index of its own.

    Then every id is a distinct integer, and ranges of ids hold every row.
    (``WITHOUT ROWID`` or ``INTEGER PRIMARY KEY DESC`` give the key an index,
    and such an id may hold text.)
    """
    info = db.execute("PRAGMA table_info(messages)").fetchall()
    keys = [(name, str(kind).upper()) for _, name, kind, _, _, pk in info if pk]
    indexed = any(origin == "pk" for _, _, _, origin, *_ in db.execute("PRAGMA index_list(messages)").fetchall())
    return keys == [("id", "INTEGER")] and not indexed


def _joined_batch(db: Any, joined_sql: str, first: int, last: int) -> Batch | None:
    """The rows with ids from ``first`` to ``last``, joined by sqlite3 (:data:`SQL_JOINED`); None when they must be fetched row by row."""
    try:
        count, odd, *numbers, blobs = db.execute(joined_sql, (first, last)).fetchone()
    except sqlite3.DataError:  # the joined batch is longer than sqlite3's longest string
        return None
    if not count:
        return _split_rows([])
    if odd or not all(isinstance(text, str) for text in numbers):
        return None
    try:  # ids and topic ids may be of any type: then a number does not parse
        ids, topic_id, log_ns, sizes = (np.fromstring(text, dtype=np.int64, sep=",") for text in numbers)
    except ValueError:
        return None
    buf = np.frombuffer(blobs or b"", dtype=np.uint8)
    if any(len(column) != count for column in (ids, topic_id, log_ns, sizes)) or int(sizes.sum()) != len(buf):
        return None
    if ids[0] < first or ids[-1] > last or (np.diff(ids) <= 0).any():
        return None
    return topic_id, log_ns, sizes, buf


def _split_rows(rows: list[tuple[Any, ...]]) -> Batch:
    """The columns of rows ``(id, topic_id, timestamp, data)`` fetched as Python tuples."""
    _, topic_ids, stamps, blobs = zip(*rows) if rows else ((), (), (), ())
    sizes = np.fromiter(map(len, blobs), dtype=np.int64, count=len(blobs))
    buf = np.frombuffer(b"".join(blobs), dtype=np.uint8)
    return np.array(topic_ids, dtype=np.int64), np.array(stamps, dtype=np.int64), sizes, buf


def _feed_runs(sink: Any, buf: Any, starts: Any, sizes: Any, log_ns: Any) -> None:
    """Split messages (``starts``, ``sizes`` in ``buf``) into runs of one size at one distance."""
    n = len(starts)
    step = np.diff(starts)
    # message i starts a new run when its size differs from the previous one's
    # or the step to it differs from the step before (a run may then be cut
    # one message early, never joined wrongly)
    change = sizes[1:] != sizes[:-1]
    change[1:] |= step[1:] != step[:-1]
    bounds = [0, *(np.flatnonzero(change) + 1).tolist(), n]
    for a, b in zip(bounds[:-1], bounds[1:]):
        stride = int(step[a]) if b - a > 1 else 0
        sink.add_run(buf, int(starts[a]), stride, b - a, int(sizes[a]), log_ns[a:b])


ROSBAGS_UNCOUNTED = (
    ("count(messages.id)", "0"),
    (" LEFT JOIN messages ON topics.id == messages.topic_id", ""),
    ("SELECT MIN(timestamp), MAX(timestamp) + 1, COUNT(*) FROM messages", "SELECT NULL, NULL, 0"),
)
"""Parts of ``rosbags``' queries when it opens an sqlite3 storage, and what the fast read asks instead: no
message counts or time range, which cost a scan of the messages per topic and one more; ``metadata.yaml``
gives both (and the fast read counts as it reads). A query of another ``rosbags`` is left as it is."""


@contextlib.contextmanager
def rosbags_sqlite_settings(uncounted: bool = False) -> Iterator[None]:
    """While ``rosbags`` opens a bag, its sqlite3 connections plan without automatic indexes and map the file.

    Its per-topic message count (``topics LEFT JOIN messages``) otherwise
    builds a temporary index over every message, which costs more than a
    scan of the table per topic; the scans read mapped pages (``mmap_size``)
    instead of copying each through ``read()``. Settings of the planner and
    the pager: the counts are the same. With ``uncounted``, the storage's
    queries do not count at all (:data:`ROSBAGS_UNCOUNTED`): its topics then
    have ``msgcount`` 0.
    """
    try:
        import apsw  # rosbags' sqlite3 driver
    except ImportError:  # no sqlite3 storage to open
        yield
        return

    class Uncounted(apsw.Cursor):
        def execute(self, statements: str, *args: Any, **kwargs: Any) -> Any:
            for part, instead in ROSBAGS_UNCOUNTED:
                statements = statements.replace(part, instead)
            return super().execute(statements, *args, **kwargs)

    def hook(connection: Any) -> None:
        connection.execute("PRAGMA automatic_index = OFF")
        connection.execute(f"PRAGMA mmap_size = {SQL_MMAP}")
        if uncounted:
            connection.cursor_factory = Uncounted

    apsw.connection_hooks.append(hook)
    try:
        yield
    finally:
        apsw.connection_hooks.remove(hook)
