"""Storage plugins for ``rosbags``' ROS 2 bag writer that also take a log's messages in bulk.

Both implement the writer's storage protocol (``add_msgtype``,
``add_connection``, ``write``, ``close``, ``abort``) and add
``add_samples(columns, ids)``, which writes every per-sample message of a
:class:`ilic_cli.io.rosencode.Columns` at once, in the order the per-message
writer writes them (per sample: ``/joint_states``, ``/joint_reference``,
``/ilic/extras``).

- :class:`BulkSqlite3Storage`: ``rosbags``' sqlite3 storage, with one
  ``executemany`` of precomputed blobs.
- :class:`BulkMcapStorage`: an MCAP file written by
  :class:`ilic_cli.io.mcapframe.BulkWriter` (zstd chunks with CRCs, message
  indexes, summary), with ``rosbags``' channel metadata (``offered_qos_profiles``)
  and the bag metadata in a ``rosbag2`` metadata record, as ``rosbags``' own
  MCAP storage writes them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from ilic_cli.io.rosencode import Columns

ROWS_PER_INSERT = 65536 * 3
"""Messages prepared at a time."""

ROWS_PER_STATEMENT = 256
"""Rows of one multi-row ``INSERT`` (768 parameters, below every sqlite3 build's limit)."""


class BulkSqlite3Storage(Sqlite3Writer):
    """``rosbags``' sqlite3 storage with :meth:`add_samples`.

    The database is not synced to disk at commit (``PRAGMA synchronous = OFF``),
    like every other output, which ``write_log`` writes to a temporary path and
    renames; the file's bytes are the same.
    """

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, compression)
        self.conn.execute("PRAGMA synchronous = OFF")

    def add_samples(self, columns: Columns, ids: dict[str, int]) -> None:
        """Insert every per-sample message of ``columns`` (topic ids from ``ids``).

        Rows go in :data:`ROWS_PER_STATEMENT` at a time through one multi-row
        ``INSERT`` (the same rows, in the same order, as one ``INSERT`` each).
        """
        import numpy as np

        topics = columns.sample_topics()
        per = max(1, len(topics))
        step = max(1, ROWS_PER_INSERT // per)
        one = "INSERT INTO messages (topic_id, timestamp, data) VALUES(?, ?, ?)"
        many = "INSERT INTO messages (topic_id, timestamp, data) VALUES " + ", ".join(["(?, ?, ?)"] * ROWS_PER_STATEMENT)
        for start in range(0, len(columns.log_ns), step):
            stop = min(start + step, len(columns.log_ns))
            table = np.empty((stop - start, per, 3), dtype=object)
            stamps = columns.log_ns[start:stop].tolist()
            for j, topic in enumerate(topics):
                data = columns.rows(topic, start, stop).tobytes()
                size = columns.sizes[topic]
                table[:, j, 0] = ids[topic]
                table[:, j, 1] = stamps
                table[:, j, 2] = [data[k : k + size] for k in range(0, len(data), size)]
            flat = table.reshape(-1).tolist()
            del table
            whole = len(flat) // (3 * ROWS_PER_STATEMENT) * 3 * ROWS_PER_STATEMENT
            width = 3 * ROWS_PER_STATEMENT
            self.cursor.executemany(many, (flat[k : k + width] for k in range(0, whole, width)))
            self.cursor.executemany(one, (flat[k : k + 3] for k in range(whole, len(flat), 3)))


class BulkMcapStorage:
    """An MCAP storage for ``rosbags``' writer, written in bulk by :class:`~ilic_cli.io.mcapframe.BulkWriter`."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        from ilic_cli import __version__
        from ilic_cli.io.mcapframe import BulkWriter
        from ilic_cli.io.mcaplog import _compression_name

        if compression != CompressionMode.NONE:
            raise WriterError("the bulk MCAP storage compresses its chunks itself; no bag compression")
        self.path = path / f"{path.name}.mcap"
        self.stream = self.path.open("xb")
        self.writer = BulkWriter(self.stream, _compression_name())
        self.writer.start(profile="ros2", library=f"ilic {__version__}")
        self.schema_ids: dict[str, int] = {}
        self.channel_ids: dict[int, int] = {}

    def add_msgtype(self, connection: Any) -> None:
        """Register the connection's message type as a schema."""
        from rosbags.interfaces import MessageDefinitionFormat

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
        from ilic_cli.io.mcaplog import add_samples

        add_samples(self.writer, columns, {topic: self.channel_ids[cid] for topic, cid in ids.items()})

    def close(self, version: int, metadata: str) -> None:
        """Write the bag metadata record, the summary and the footer; close the file."""
        del version
        try:
            self.writer.add_metadata("rosbag2", {"serialized_metadata": metadata})
            self.writer.finish()
        finally:
            self.stream.close()

    def abort(self) -> None:
        """Close the file as it is (``write_log`` removes the temporary folder)."""
        self.stream.close()
