"""Bulk MCAP writing: message records framed as NumPy rows, chunked like ``mcap.writer.Writer``.

:class:`BulkWriter` lays a file out record for record as the ``mcap``
library's :class:`~mcap.writer.Writer` does (same chunking rule, compression,
chunk and data-section CRCs, message indexes, summary, summary offsets), so
the same messages give the same bytes; but it takes groups of fixed-size
message records as rows of a uint8 array (:meth:`BulkWriter.add_groups`) and
frames whole chunks and message indexes with NumPy instead of one Python call
per message. The non-message records are written with the ``mcap`` record
classes.
"""

from __future__ import annotations

import collections
import struct
import zlib
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import IO, Any

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset

from ilic_cli.io.cdrcols import put
from ilic_cli.io.mcapscan import MAGIC

MESSAGE_HEAD = 31
"""Bytes of a message record before its data."""

OP_MESSAGE = 0x05
OP_MESSAGE_INDEX = 0x07

COMPRESSING = 2
"""Threads compressing chunks while the next ones are framed (zstd and crc32 release the GIL)."""

MAX_PENDING = 4
"""Most closed chunks held in memory before the oldest one is written."""


def compress_chunk(compression: str, data: bytes) -> tuple[bytes, int]:
    """``data`` compressed as ``mcap.writer.Writer`` compresses a chunk (``"zstd"`` level 3, ``"lz4"``, ``""``), and its crc32."""
    if compression == "zstd":
        compressed = zstandard.compress(data)
    elif compression == "lz4":
        compressed = lz4.frame.compress(data)
    else:
        compressed = data
    return compressed, zlib.crc32(data)


@dataclass
class _Pending:
    """A closed chunk waiting for its compression: what its records need besides the compressed bytes."""

    job: Future[tuple[bytes, int]]
    size: int
    start: int
    end: int
    index: dict[int, tuple[list[np.ndarray], list[np.ndarray]]]


def frame_head(rows: np.ndarray, offset: int, length: int, channel_id: int, sequence: np.ndarray, log_ns: np.ndarray) -> None:
    """Write message record heads at byte ``offset`` of every row of ``rows``.

    ``length`` is the record length after the opcode and length fields
    (22 + data size); log and publish time are both ``log_ns``.
    """
    rows[:, offset] = OP_MESSAGE
    put(rows, offset + 1, "<u8", np.full(rows.shape[0], length, dtype=np.uint64))
    put(rows, offset + 9, "<u2", np.full(rows.shape[0], channel_id, dtype=np.uint16))
    put(rows, offset + 11, "<u4", sequence.astype(np.uint32))
    put(rows, offset + 15, "<u8", log_ns.astype(np.uint64))
    put(rows, offset + 23, "<u8", log_ns.astype(np.uint64))


class BulkWriter:
    """Writes an MCAP file as :class:`mcap.writer.Writer` would, taking messages in bulk.

    Parameters
    ----------
    stream : binary file
        Opened for writing, positioned at 0.
    compression : str
        ``"zstd"``, ``"lz4"`` or ``""``.
    chunk_size : int
        A chunk is closed once a message makes it larger than this (bytes).
    data_crc : bool
        Write the data-section CRC in ``DataEnd``.
    """

    def __init__(self, stream: IO[bytes], compression: str, chunk_size: int = 1024 * 1024, data_crc: bool = True) -> None:
        self.stream = stream
        self.compression = compression
        self.chunk_size = chunk_size
        self.data_crc = data_crc
        self.crc = 0
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, Any] = {}
        self.chunk_indexes: list[Any] = []
        self.metadata_indexes: list[Any] = []
        self.pending: collections.deque[_Pending] = collections.deque()
        self.pool: Any = None
        self.stats = Statistics(
            attachment_count=0,
            channel_count=0,
            channel_message_counts={},
            chunk_count=0,
            message_count=0,
            metadata_count=0,
            message_start_time=0,
            message_end_time=0,
            schema_count=0,
        )
        self._reset_chunk()

    # -- raw output ---------------------------------------------------------
    def _write(self, data: bytes | memoryview) -> None:
        if self.data_crc:
            self.crc = zlib.crc32(data, self.crc)
        self.stream.write(data)

    @staticmethod
    def _record(record: Any) -> bytes:
        builder = RecordBuilder()
        record.write(builder)
        return bytes(builder.end())

    def _reset_chunk(self) -> None:
        self.pieces: list[bytes | memoryview] = []
        self.count = 0
        self.num_messages = 0
        self.chunk_start = 0
        self.chunk_end = 0
        # channel id -> lists of (log times, offsets) arrays, in order of first message
        self.index: dict[int, tuple[list[np.ndarray], list[np.ndarray]]] = {}

    def _chunk_add(self, data: bytes | memoryview) -> None:
        self.pieces.append(data)
        self.count += len(data)

    # -- records ------------------------------------------------------------
    def start(self, profile: str, library: str) -> None:
        """Write the magic and the header."""
        self._write(MAGIC)
        self._write(self._record(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a schema (to the current chunk); return its id."""
        schema_id = len(self.schemas) + 1
        schema = Schema(id=schema_id, data=data, encoding=encoding, name=name)
        self.schemas[schema_id] = schema
        self.stats.schema_count += 1
        self._chunk_add(self._record(schema))
        self._maybe_finish_chunk()
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int, metadata: Mapping[str, str] | None = None) -> int:
        """Add a channel (to the current chunk); return its id."""
        channel_id = len(self.channels) + 1
        channel = Channel(id=channel_id, topic=topic, message_encoding=message_encoding, schema_id=schema_id, metadata=dict(metadata or {}))
        self.channels[channel_id] = channel
        self.stats.channel_count += 1
        self._chunk_add(self._record(channel))
        self._maybe_finish_chunk()
        return channel_id

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        """Add one message."""
        record = struct.pack("<BQHIQQ", OP_MESSAGE, 22 + len(data), channel_id, sequence, log_time, publish_time) + data
        self._note(np.array([channel_id]), np.array([log_time], dtype=np.int64), np.array([self.count], dtype=np.int64))
        self._chunk_add(record)
        self._maybe_finish_chunk()

    def _note(self, channel_ids: np.ndarray, log_ns: np.ndarray, offsets: np.ndarray) -> None:
        """Account messages (one per entry) added at chunk ``offsets``: times, counts, index entries."""
        low, high = int(log_ns.min()), int(log_ns.max())
        stats = self.stats
        stats.message_start_time = low if stats.message_count == 0 else min(low, stats.message_start_time)
        stats.message_end_time = max(high, stats.message_end_time)
        self.chunk_start = low if self.num_messages == 0 else min(low, self.chunk_start)
        self.chunk_end = max(high, self.chunk_end)
        n = len(log_ns)
        stats.message_count += n
        self.num_messages += n
        for channel_id in dict.fromkeys(channel_ids.tolist()):
            mine = channel_ids == channel_id
            count = int(mine.sum())
            stats.channel_message_counts[channel_id] = stats.channel_message_counts.get(channel_id, 0) + count
            times, offs = self.index.setdefault(channel_id, ([], []))
            times.append(log_ns[mine] if count < n else log_ns)
            offs.append(offsets[mine] if count < n else offsets)

    def add_groups(self, rows: np.ndarray, slots: list[tuple[int, int, int]], log_ns: np.ndarray) -> None:
        """Add ``len(rows)`` groups of message records.

        Parameters
        ----------
        rows : ndarray of uint8, shape (groups, group bytes)
            Complete message records (see :func:`frame_head`), back to back in each row.
        slots : list of (offset, record bytes, channel id)
            The records of a group, in order.
        log_ns : ndarray of int64
            Log time of each group's messages.
        """
        rows = np.ascontiguousarray(rows)
        groups, width = rows.shape
        flat = memoryview(rows.reshape(-1))  # type: ignore[arg-type]  # numpy's stubs give ndarray the buffer protocol only for Python >= 3.12
        per = len(slots)
        offsets = np.array([s[0] for s in slots], dtype=np.int64)
        ends = offsets + np.array([s[1] for s in slots], dtype=np.int64)
        channels = np.array([s[2] for s in slots], dtype=np.int64)
        total = groups * per

        def start_of(k: int) -> int:
            return (k // per) * width + int(offsets[k % per])

        def end_of(k: int) -> int:
            return (k // per) * width + int(ends[k % per])

        k = 0
        while k < total:
            # the chunk closes after the first record that takes it past chunk_size
            threshold = self.chunk_size - self.count + start_of(k)
            e = max(k, (max(threshold, 0) // width - 1) * per)
            while e < total and end_of(e) <= threshold:
                e += 1
            last = min(e, total - 1)
            first_byte, last_byte = start_of(k), end_of(last)
            ks = np.arange(k, last + 1, dtype=np.int64)
            starts = (ks // per) * width + offsets[ks % per]
            self._note(channels[ks % per], log_ns[ks // per], starts - first_byte + self.count)
            self._chunk_add(flat[first_byte:last_byte])
            k = last + 1
            self._maybe_finish_chunk()

    def _maybe_finish_chunk(self) -> None:
        if self.count > self.chunk_size:
            self._finish_chunk()

    def _finish_chunk(self) -> None:
        """Close the current chunk: hand it to a compressing thread; write the chunks whose compression is done, in order."""
        if self.num_messages == 0:
            return
        self.stats.chunk_count += 1
        if self.pool is None:
            self.pool = ThreadPoolExecutor(COMPRESSING, thread_name_prefix="mcap-chunk")
        job = self.pool.submit(compress_chunk, self.compression, b"".join(self.pieces))
        self.pending.append(_Pending(job, self.count, self.chunk_start, self.chunk_end, self.index))
        self._reset_chunk()
        while self.pending and (len(self.pending) > MAX_PENDING or self.pending[0].job.done()):
            self._write_chunk(self.pending.popleft())

    def _flush_chunks(self) -> None:
        """Write every closed chunk; stop the compressing threads."""
        while self.pending:
            self._write_chunk(self.pending.popleft())
        if self.pool is not None:
            self.pool.shutdown()
            self.pool = None

    def abort(self) -> None:
        """Drop the chunks still compressing and stop the threads (after an error or a signal; the file is left as it is).

        Without it a signal that lands while the pool starts a thread can leave a worker the
        pool never registered: nothing would wake it at exit, and the process would hang there.
        ``shutdown`` posts the wake-up that every worker passes on to the next.
        """
        self.pending.clear()
        if self.pool is not None:
            self.pool.shutdown(wait=False, cancel_futures=True)
            self.pool = None

    def _write_chunk(self, chunk: _Pending) -> None:
        """Write a chunk record and its message indexes (once its compression is done)."""
        compressed, crc = chunk.job.result()
        record = Chunk(
            compression=self.compression,
            data=compressed,
            message_start_time=chunk.start,
            message_end_time=chunk.end,
            uncompressed_crc=crc,
            uncompressed_size=chunk.size,
        )
        chunk_offset = self.stream.tell()
        data = self._record(record)
        self._write(data)
        index_start = self.stream.tell()
        offsets: dict[int, int] = {}
        parts = []
        at = index_start
        for channel_id, (times, offs) in chunk.index.items():
            offsets[channel_id] = at
            entries = np.empty((sum(len(t) for t in times), 2), dtype="<u8")
            entries[:, 0] = np.concatenate(times)
            entries[:, 1] = np.concatenate(offs)
            body = entries.tobytes()
            part = struct.pack("<BQHI", OP_MESSAGE_INDEX, 6 + len(body), channel_id, len(body)) + body
            parts.append(part)
            at += len(part)
        indexes = b"".join(parts)
        self._write(indexes)
        self.chunk_indexes.append(
            ChunkIndex(
                message_start_time=chunk.start,
                message_end_time=chunk.end,
                chunk_start_offset=chunk_offset,
                chunk_length=len(data),
                message_index_offsets=offsets,
                message_index_length=len(indexes),
                compression=self.compression,
                compressed_size=len(compressed),
                uncompressed_size=chunk.size,
            )
        )

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Close the current chunk, then write a metadata record (indexed in the summary)."""
        self._finish_chunk()
        self._flush_chunks()
        offset = self.stream.tell()
        self.stats.metadata_count += 1
        record = self._record(Metadata(name=name, metadata=dict(data)))
        self._write(record)
        self.metadata_indexes.append(MetadataIndex(offset=offset, length=len(record), name=name))

    def finish(self) -> None:
        """Close the last chunk, write ``DataEnd``, the summary and the footer."""
        self._finish_chunk()
        self._flush_chunks()
        self._write(self._record(DataEnd(self.crc if self.data_crc else 0)))
        summary_start = self.stream.tell()
        builder = RecordBuilder()
        offsets = []

        def group(opcode: Any, records: list[Any]) -> None:
            begin = builder.count
            for record in records:
                record.write(builder)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + begin, group_length=builder.count - begin))

        group(Opcode.SCHEMA, list(self.schemas.values()))
        group(Opcode.CHANNEL, list(self.channels.values()))
        group(Opcode.STATISTICS, [self.stats])
        group(Opcode.CHUNK_INDEX, self.chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, [])
        group(Opcode.METADATA_INDEX, self.metadata_indexes)
        offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = bytes(builder.end())
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, 0 if not summary else summary_start, offset_start), crc)
        self.stream.write(summary)
        self.stream.write(self._record(Footer(summary_start=0 if not summary else summary_start, summary_offset_start=offset_start, summary_crc=crc)))
        self.stream.write(MAGIC)
