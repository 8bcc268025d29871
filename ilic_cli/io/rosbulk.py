"""Storage plugins for ``rosbags``' ROS 2 bag writer that also take a log's messages in bulk.

Both implement the writer's storage protocol (``add_msgtype``,
``add_connection``, ``write``, ``close``, ``abort``) and add
``add_samples(columns, ids)``, which writes every per-sample message of a
:class:`ilic_cli.io.rosencode.Columns` at once, in the order the per-message
writer writes them (per sample: ``/joint_states``, ``/joint_reference``,
``/ilic/extras``).

- :class:`BulkSqlite3Storage`: ``rosbags``' sqlite3 storage; the ``messages``
  table and its index are written as B-tree pages (:mod:`ilic_cli.io.sqlitewrite`),
  or sqlite3 cuts each topic's messages, passed as one blob, into rows.
- :class:`BulkMcapStorage`: an MCAP file written by
  :class:`ilic_cli.io.mcapframe.BulkWriter` (zstd chunks with CRCs, message
  indexes, summary), with ``rosbags``' channel metadata (``offered_qos_profiles``)
  and the bag metadata in a ``rosbag2`` metadata record, as ``rosbags``' own
  MCAP storage writes them.
"""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from ilic_cli import __version__
from ilic_cli.io import sqlitecells, sqlitewrite
from ilic_cli.io.rosencode import Columns
from ilic_cli.io.sqlitepages import table_max_local

SAMPLES_PER_INSERT = 65536
"""Samples inserted by one statement."""

STAMP_DIGITS = 20
"""Characters of a log time in the joined stamps (sign and 19 digits, zero-padded: any int64)."""


class BulkSqlite3Storage(Sqlite3Writer):
    """``rosbags``' sqlite3 storage with :meth:`add_samples`.

    The database is not synced to disk at commit (``PRAGMA synchronous = OFF``),
    like every other output, which ``write_log`` writes to a temporary path and
    renames.

    The samples' rows are not inserted by sqlite3 when they can be written as
    pages (:mod:`ilic_cli.io.sqlitewrite`): they wait for :meth:`close`, which
    lets sqlite3 finish the file and then writes the ``messages`` table and
    its ``timestamp_idx`` index as B-tree pages. Rows whose cells would spill
    to overflow pages, timestamps that decrease (the index's entries would
    not be in id order), a message written after the samples, or a file
    whose header or trees are not as expected go to :meth:`insert_sql`
    instead: the same rows, ids and index either way (not the same bytes:
    the pages are filled fuller than sqlite3 fills them).
    """

    pages = True
    """Whether the samples' rows may be written as pages (else always with SQL)."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        """``rosbags``' ``Sqlite3Writer.__init__``, with ``synchronous = OFF`` set before the schema is committed."""
        if compression == CompressionMode.STORAGE:
            raise WriterError("SQLITE3 writer does not support storage-side compression.")
        self.path = path / f"{path.name}.db3"
        self.conn = sqlite3.connect(f"file:{self.path}", uri=True)
        self.conn.execute("PRAGMA synchronous = OFF")  # before the schema's commit, which would wait for the disk
        self.conn.executescript(self.SQLITE_SCHEMA)
        self.cursor = self.conn.cursor()
        self.pending: tuple[Columns, dict[str, int]] | None = None

    def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
        """Insert one message (after the samples' rows, when they wait: the ids stay in the order of the calls)."""
        self._insert_pending()
        super().write(connection, timestamp, data)

    def add_samples(self, columns: Columns, ids: dict[str, int]) -> None:
        """Write every per-sample message of ``columns`` (topic ids from ``ids``): as pages at :meth:`close`, or now with SQL."""
        self._insert_pending()
        topics = columns.sample_topics()
        if not topics or not len(columns.log_ns):
            return
        if self.pages and self._fits(columns, ids):
            self.pending = (columns, ids)
        else:
            self.insert_sql(columns, ids)

    def _fits(self, columns: Columns, ids: dict[str, int]) -> bool:
        """Whether every row's cell fits in a leaf page (no overflow pages) of a file whose header the page writer expects."""
        try:  # the header as the schema's commit wrote it
            _, usable, _ = sqlitewrite.header(self.path)
        except sqlitewrite.NotWritten:
            return False
        return sqlitecells.max_payload(_bulk(columns, ids)) <= table_max_local(usable)

    def _insert_pending(self) -> None:
        if self.pending is not None:
            columns, ids = self.pending
            self.pending = None
            self.insert_sql(columns, ids)

    def close(self, version: int, metadata: str) -> None:
        """``rosbags``' close, then the samples' rows written as pages, if they wait."""
        if self.pending is None:
            super().close(version, metadata)
            return
        columns, ids = self.pending
        roots = dict(self.conn.execute("SELECT name, rootpage FROM sqlite_master WHERE name IN ('messages', 'timestamp_idx')").fetchall())
        rows = self.conn.execute("SELECT id, timestamp, typeof(id), typeof(timestamp) FROM messages ORDER BY id").fetchall()
        prior = None
        if len(roots) == 2 and all(r[2] == r[3] == "integer" for r in rows):
            rowid = np.array([r[0] for r in rows], dtype=np.int64)
            log_ns = np.array([r[1] for r in rows], dtype=np.int64)
            if sqlitewrite.nondecreasing(log_ns, columns.log_ns):  # else the index's entries would not be in id order
                self.conn.commit()  # the rows so far on disk, for their cells
                try:
                    prior = sqlitewrite.before(self.path, roots["messages"], roots["timestamp_idx"], rowid, log_ns)
                except sqlitewrite.NotWritten:
                    prior = None  # the same rows by SQL; the file counts one more change
        if prior is None:
            self._insert_pending()
            super().close(version, metadata)
            return
        self.pending = None
        super().close(version, metadata)
        sqlitewrite.write_trees(self.path, roots["messages"], roots["timestamp_idx"], prior, _bulk(columns, ids))

    def insert_sql(self, columns: Columns, ids: dict[str, int]) -> None:
        """Insert every per-sample message of ``columns`` (topic ids from ``ids``) with SQL.

        One ``INSERT`` per :data:`SAMPLES_PER_INSERT` samples (:func:`insert_rows_sql`)
        takes the samples' messages back to back as one blob and their log
        times as one fixed-width text, and sqlite3 cuts them into rows: the
        same rows, in the same order, as one ``INSERT`` each, so the same
        file, without a Python object per message.
        """
        topics = columns.sample_topics()
        sql = insert_rows_sql([ids[topic] for topic in topics], [columns.sizes[topic] for topic in topics], SAMPLES_PER_INSERT)
        for start in range(0, len(columns.log_ns), SAMPLES_PER_INSERT):
            stop = min(start + SAMPLES_PER_INSERT, len(columns.log_ns))
            stamps = np.char.zfill(columns.log_ns[start:stop].astype(f"S{STAMP_DIGITS}"), STAMP_DIGITS)
            messages = np.hstack([columns.rows(topic, start, stop) for topic in topics])
            self.cursor.execute(sql, [stop - start, memoryview(stamps), memoryview(messages)])  # type: ignore[arg-type]  # bound as blobs, not copied to bytes first; numpy's stubs give ndarray the buffer protocol only for Python >= 3.12


def _bulk(columns: Columns, ids: dict[str, int]) -> sqlitecells.Bulk:
    """The samples' rows of ``columns`` for the page writer."""
    topics = columns.sample_topics()

    def rows(k: int, start: int, stop: int) -> np.ndarray:
        return columns.rows(topics[k], start, stop)

    return sqlitecells.Bulk([ids[topic] for topic in topics], [columns.sizes[topic] for topic in topics], columns.log_ns, rows)


def insert_rows_sql(topic_ids: list[int], sizes: list[int], most: int) -> str:
    """An ``INSERT`` into ``messages`` of the messages of ``?1`` samples (at most ``most``): per sample, one message of each topic in order.

    Parameters: ``?1`` the number of samples, ``?2`` their log times
    (:data:`STAMP_DIGITS` characters each), ``?3`` their messages, sample
    after sample, topic after topic (``sizes`` bytes each). The samples are
    counted by a ``CROSS JOIN`` of two counters of ``isqrt(most)`` rounded
    up (cheaper than counting every row in a recursive common table
    expression, sqlite3 3.8.3 or later); a ``CROSS JOIN`` keeps its left
    table in the outer loop, so the rows come in order.
    """
    side = math.isqrt(max(most, 1) - 1) + 1
    width = sum(sizes)
    starts = [sum(sizes[:j]) for j in range(len(sizes))]
    topics = ", ".join(f"({tid}, {start + 1}, {size})" for tid, start, size in zip(topic_ids, starts, sizes))
    return (
        f"WITH RECURSIVE counter(x) AS (SELECT 0 UNION ALL SELECT x + 1 FROM counter WHERE x + 1 < {side}), "
        f"sample(i) AS (SELECT a.x * {side} + b.x FROM counter AS a CROSS JOIN counter AS b WHERE a.x * {side} < ?1 AND a.x * {side} + b.x < ?1), "
        f"topic(id, start, size) AS (VALUES {topics}) "
        "INSERT INTO messages (topic_id, timestamp, data) "
        f"SELECT topic.id, CAST(substr(?2, i * {STAMP_DIGITS} + 1, {STAMP_DIGITS}) AS INTEGER), substr(?3, i * {width} + topic.start, topic.size) "
        "FROM sample CROSS JOIN topic"
    )


class BulkMcapStorage:
    """An MCAP storage for ``rosbags``' writer, written in bulk by :class:`~ilic_cli.io.mcapframe.BulkWriter`."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        if compression != CompressionMode.NONE:
            raise WriterError("the bulk MCAP storage compresses its chunks itself; no bag compression")
        from ilic_cli.io import mcaplog  # mcap (some 20 ms) deferred: an sqlite3 bag does not load it
        from ilic_cli.io.mcapframe import BulkWriter  # mcap too

        self.path = path / f"{path.name}.mcap"
        self.stream = self.path.open("xb")
        self.writer = BulkWriter(self.stream, mcaplog._compression_name())
        self.writer.start(profile="ros2", library=f"ilic {__version__}")
        self.schema_ids: dict[str, int] = {}
        self.channel_ids: dict[int, int] = {}

    def add_msgtype(self, connection: Any) -> None:
        """Register the connection's message type as a schema."""
        encoding = "ros2msg" if connection.msgdef.format == MessageDefinitionFormat.MSG else "ros2idl"
        self.schema_ids[connection.msgtype] = self.writer.register_schema(connection.msgtype, encoding, connection.msgdef.data.encode("utf-8"))

    def add_connection(self, connection: Any, offered_qos_profiles: str) -> None:
        """Register the connection as a channel with its QoS profiles."""
        channel = self.writer.register_channel(
            connection.topic,
            connection.ext.serialization_format,
            self.schema_ids[connection.msgtype],
            {"offered_qos_profiles": offered_qos_profiles},
        )
        self.channel_ids[connection.id] = channel

    def write(self, connection: Any, timestamp: int, data: bytes | memoryview) -> None:
        """Add one message."""
        self.writer.add_message(self.channel_ids[connection.id], timestamp, bytes(data), timestamp, 0)

    def add_samples(self, columns: Columns, ids: dict[str, int]) -> None:
        """Add every per-sample message of ``columns`` (connection ids from ``ids``)."""
        from ilic_cli.io import mcaplog  # mcap deferred (loaded by __init__ already)

        mcaplog.add_samples(self.writer, columns, {topic: self.channel_ids[cid] for topic, cid in ids.items()})

    def close(self, version: int, metadata: str) -> None:
        """Write the bag metadata record, the summary and the footer; close the file."""
        del version
        try:
            self.writer.add_metadata("rosbag2", {"serialized_metadata": metadata})
            self.writer.finish()
        except BaseException:
            self.writer.abort()
            raise
        finally:
            self.stream.close()

    def abort(self) -> None:
        """Stop the compressing threads; close the file as it is (``write_log`` removes the temporary folder)."""
        try:
            self.writer.abort()
        finally:
            self.stream.close()
