"""MCAP files with ROS 2 (CDR) messages, read and written with the ``mcap`` package.

Writing: one schema per message type (encoding ``ros2msg``, the concatenated
``.msg`` text that Foxglove and other MCAP viewers decode), channels with
message encoding ``cdr``, zstd-compressed chunks (``zstandard`` is a dependency of ``mcap``) with chunk and data-section CRCs, library string
``ilic <version>``: the same log always gives the same bytes. The topics are
those of :mod:`ilic_cli.io.rosschema`. ``WriteOptions.fast`` (the default)
fills whole columns into ``rosbags``-serialised message templates
(:func:`ilic_cli.io.rosencode.encode_columns`) and frames them in bulk
(:class:`ilic_cli.io.mcapframe.BulkWriter`); ``fast=False`` serialises each
message with ``rosbags`` and adds it with :class:`mcap.writer.Writer`. Both
give the same bytes.

Reading streams the file once, chunk by chunk, into NumPy columns
(:class:`ilic_cli.io.roscollect.Collector`): no Python object is kept per
message, so a 1-hour 1 kHz log is read in bounded memory. The fast path
(:mod:`ilic_cli.io.mcapscan`) walks the records itself and decodes runs of
same-layout messages as strided views; ``fast=False`` streams with
:class:`mcap.stream_reader.StreamReader` (CRC validation on) and decodes
message by message. Before a chunk is decompressed its declared size is
checked against ``min(2 GiB, 64 x file size)`` and the decompressor is capped
at that size, so a hostile file cannot exhaust memory. ``ros1`` encoded
channels are decoded too; other encodings are refused.
"""

from __future__ import annotations

import functools
import io
import struct
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lz4.frame
import numpy as np
import zstandard
from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader, breakup_chunk

from ilic_cli import __version__
from ilic_cli.errors import LogError
from ilic_cli.io import current_progress, mcapscan, roscollect, rosdecode, rosencode, rosschema
from ilic_cli.io.mcapframe import MESSAGE_HEAD, BulkWriter, frame_head

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions
    from ilic_cli.runlog import RunLog

MAX_CHUNK_BYTES = 2 * 2**30
"""Largest uncompressed chunk accepted (bytes)."""

MAX_EXPANSION = 64
"""Largest accepted ratio of a chunk's uncompressed size to the file size."""


def _compression() -> Any:
    from mcap.writer import CompressionType  # mcap.writer (some 40 ms) deferred: only writing needs it

    return CompressionType.ZSTD


def write(log: RunLog, path: Path, options: WriteOptions) -> None:
    """Write ``log`` to ``path`` as an MCAP file with ROS 2 CDR messages.

    Parameters
    ----------
    log : RunLog
        The log to write.
    path : Path
        Destination file (a temporary path chosen by ``write_log``).
    options : WriteOptions
        ``options.joint`` names the joint unless ``log.meta["joint"]`` does;
        ``options.fast`` picks the bulk writer (the same bytes as the per-message one).
    """
    from mcap.writer import Writer  # mcap.writer (some 40 ms) deferred: only writing needs it

    joint = rosencode.writer_joint(log, options.joint)
    columns = rosencode.encode_columns(log, joint) if options.fast else None
    if columns is not None:
        with open(path, "wb") as stream:
            write_columns(stream, columns, _compression_name(), profile="ros2", library=f"ilic {__version__}")
        return
    topics, messages = rosencode.encode(log, joint, rosschema.ROS2)
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=_compression(), enable_crcs=True, enable_data_crcs=True)
        writer.start(profile="ros2", library=f"ilic {__version__}")
        schema_ids: dict[str, int] = {}
        channel_ids: dict[str, int] = {}
        for spec in topics:
            if spec.msgtype not in schema_ids:
                text, _ = rosschema.message_definition(spec.msgtype, rosschema.ROS2)
                schema_ids[spec.msgtype] = writer.register_schema(name=spec.msgtype, encoding="ros2msg", data=text.encode("utf-8"))
            channel_ids[spec.topic] = writer.register_channel(topic=spec.topic, message_encoding="cdr", schema_id=schema_ids[spec.msgtype])
        counts: dict[str, int] = {}
        for topic, log_ns, data in messages:
            seq = counts.get(topic, 0)
            counts[topic] = seq + 1
            writer.add_message(channel_id=channel_ids[topic], log_time=log_ns, publish_time=log_ns, data=data, sequence=seq)
        writer.finish()


def _compression_name() -> str:
    from mcap.writer import CompressionType  # mcap.writer (some 40 ms) deferred: only writing needs it

    return {CompressionType.ZSTD: "zstd", CompressionType.LZ4: "lz4"}.get(_compression(), "")


BATCH = 65536
"""Samples framed at a time by the bulk writer."""


def write_columns(stream: Any, columns: rosencode.Columns, compression: str, *, profile: str, library: str) -> None:
    """Write ``columns`` as an MCAP file, record for record as the per-message writer does.

    Parameters
    ----------
    stream : binary file
        Destination, at offset 0.
    columns : rosencode.Columns
        The messages (:func:`ilic_cli.io.rosencode.encode_columns`).
    compression : str
        ``"zstd"``, ``"lz4"`` or ``""``.
    profile, library : str
        Header fields.
    """
    writer = BulkWriter(stream, compression)
    writer.start(profile=profile, library=library)
    schema_ids: dict[str, int] = {}
    channel_ids: dict[str, int] = {}
    for spec in columns.topics:
        if spec.msgtype not in schema_ids:
            text, _ = rosschema.message_definition(spec.msgtype, rosschema.ROS2)
            schema_ids[spec.msgtype] = writer.register_schema(name=spec.msgtype, encoding="ros2msg", data=text.encode("utf-8"))
        channel_ids[spec.topic] = writer.register_channel(topic=spec.topic, message_encoding="cdr", schema_id=schema_ids[spec.msgtype])
    ns = columns.log_ns
    try:
        writer.add_message(channel_ids[rosschema.TOPIC_METADATA], int(ns[0]), columns.metadata, int(ns[0]), 0)
        add_samples(writer, columns, channel_ids)
        writer.finish()
    except BaseException:
        writer.abort()
        raise


def add_samples(writer: Any, columns: rosencode.Columns, channel_ids: dict[str, int]) -> None:
    """Frame the per-sample messages of ``columns`` and add them to ``writer`` (a :class:`~ilic_cli.io.mcapframe.BulkWriter`).

    Each sample's messages follow each other in topic order; the message
    sequence number is the sample index.
    """
    ns = columns.log_ns
    order = columns.sample_topics()
    slots = []
    width = 0
    for topic in order:
        size = MESSAGE_HEAD + columns.sizes[topic]
        slots.append((width, size, channel_ids[topic]))
        width += size
    for start in range(0, len(ns), BATCH):
        stop = min(start + BATCH, len(ns))
        rows = np.empty((stop - start, width), dtype=np.uint8)
        sequence = np.arange(start, stop, dtype=np.int64)
        for topic, (offset, size, channel_id) in zip(order, slots):
            rows[:, offset + MESSAGE_HEAD : offset + size] = columns.rows(topic, start, stop)
            frame_head(rows, offset, size - 9, channel_id, sequence, ns[start:stop])
        writer.add_groups(rows, slots, ns[start:stop])


@functools.lru_cache(maxsize=1)
def _zstd() -> Any:
    """One zstd decompressor, reused for every chunk."""
    return zstandard.ZstdDecompressor()


def _decompress(chunk: Any, limit: int, path: Path) -> bytes:
    size = int(chunk.uncompressed_size)
    if size > limit:
        raise LogError(path, f"MCAP chunk declares {size} uncompressed bytes (limit {limit}); file is corrupt or hostile")
    if chunk.compression == "":
        data = bytes(chunk.data)
    elif chunk.compression == "zstd":
        if zstandard.frame_content_size(chunk.data) == size:
            # the frame declares the (already bounded) size: one call into a buffer of that size
            data = _zstd().decompress(chunk.data, max_output_size=size)
        else:
            # a streaming read stops at size + 1 bytes whatever the frame header claims
            with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as reader:
                data = reader.read(size + 1)
    elif chunk.compression == "lz4":
        data = lz4.frame.LZ4FrameDecompressor().decompress(chunk.data, max_length=size + 1)
    else:
        raise LogError(path, f"MCAP chunk compression '{chunk.compression}' is not supported")
    if len(data) != size:
        raise LogError(path, f"MCAP chunk decompresses to {len(data)} bytes, not the declared {size}; file is corrupt")
    return data


def scan(path: Path, collector: roscollect.Collector | None = None, progress: Any = None, *, fast: bool = True) -> None:
    """Read every record of an MCAP file once, checking CRCs; feed messages to ``collector``.

    Parameters
    ----------
    path : Path
        The MCAP file.
    collector : roscollect.Collector, optional
        Receives every channel (as a topic, ROS message types normalised to
        ``pkg/msg/Type``) and the messages of the topics it reads. Without it
        the file is only checked.
    progress : callable, optional
        Called as ``progress(bytes_read, file_size)`` after each chunk.
    fast : bool
        Decode runs of same-layout messages as columns (:mod:`ilic_cli.io.mcapscan`);
        False: record by record with the ``mcap`` library's stream reader.

    Raises
    ------
    LogError
        For a truncated, corrupt (CRC mismatch) or hostile file.
    """
    try:
        if fast:
            _scan_fast(path, collector, progress)
        else:
            _scan(path, collector, progress)
    except mcapscan.McapScanError as exc:
        raise LogError(path, f"not a readable MCAP file: {exc}") from None
    except LogError:
        raise
    except MemoryError:
        raise LogError(path, "MCAP file needs more memory than available; file is corrupt or too large") from None
    except Exception as exc:  # noqa: BLE001 - every library failure is bad input
        raise LogError(path, f"not a readable MCAP file: {_describe(exc)}") from None


def _describe(exc: BaseException) -> str:
    if isinstance(exc, CRCValidationError):
        return f"CRC check failed in {type(exc.record).__name__} record (file is corrupt)"
    if isinstance(exc, (EndOfFile, struct.error, EOFError)):
        return "file is truncated or corrupt (unexpected end of data)"
    if isinstance(exc, InvalidMagic):
        return "bad magic bytes (not MCAP, or truncated)"
    if isinstance(exc, RecordLengthLimitExceeded):
        return "file is truncated or corrupt (a record runs past the end of the file)"
    text = " ".join(str(exc).split())[:160]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _topic(channel: Any, schema: Any) -> rosschema.RawTopic:
    encoding = channel.message_encoding
    kind = rosschema.ROS2 if encoding == "cdr" else rosschema.ROS1 if encoding == "ros1" else encoding
    return rosschema.RawTopic(channel.topic, rosschema.normalize_msgtype(schema.name), kind)


def _scan_fast(path: Path, collector: roscollect.Collector | None, progress: Any) -> None:
    limit = min(MAX_CHUNK_BYTES, MAX_EXPANSION * max(path.stat().st_size, 1))

    def declare(channel: Any, schema: Any) -> Any:
        return collector.declare(_topic(channel, schema)) if collector is not None else None

    def decompress(chunk: Any, cap: int) -> bytes:
        try:
            return _decompress(chunk, cap, path)
        except LogError:
            raise
        except Exception as exc:  # noqa: BLE001 - zstd/lz4 errors on damaged data
            raise LogError(path, f"not a readable MCAP file: a {chunk.compression} chunk cannot be decompressed (file is corrupt: {_describe(exc)})") from None

    mcapscan.scan(path, declare, decompress, limit, progress, _message_counts(path))


def _message_counts(path: Path) -> dict[int, int]:
    """Channel id -> message count from the file's summary (via ``mcap``); empty when there is none or it is unreadable."""
    try:
        with open(path, "rb") as stream:
            summary = SeekingReader(stream, validate_crcs=False).get_summary()
        if summary is None or summary.statistics is None:
            return {}
        return {int(k): int(v) for k, v in summary.statistics.channel_message_counts.items()}
    except Exception:  # noqa: BLE001 - a hint only; the scan checks the file
        return {}


def _scan(path: Path, collector: roscollect.Collector | None, progress: Any) -> None:
    file_size = path.stat().st_size
    limit = min(MAX_CHUNK_BYTES, MAX_EXPANSION * max(file_size, 1))
    schemas: dict[int, Any] = {}
    sinks: dict[int, Any] = {}

    def take(record: Any) -> None:
        if isinstance(record, Message):
            sink = sinks.get(record.channel_id)
            if sink is not None:
                sink.add(record.log_time, record.data)
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Channel) and collector is not None:
            schema = schemas.get(record.schema_id)
            if schema is None:
                return
            sinks[record.id] = collector.declare(_topic(record, schema))

    with open(path, "rb") as stream:
        reader = StreamReader(stream, emit_chunks=True, validate_crcs=True, record_size_limit=file_size)
        for record in reader.records:
            if isinstance(record, Chunk):
                try:
                    data = _decompress(record, limit, path)
                except LogError:
                    raise
                except Exception as exc:  # noqa: BLE001 - zstd/lz4 errors on damaged data
                    raise LogError(
                        path, f"not a readable MCAP file: a {record.compression} chunk cannot be decompressed (file is corrupt: {_describe(exc)})"
                    ) from None
                plain = Chunk(
                    compression="",
                    data=data,
                    message_start_time=record.message_start_time,
                    message_end_time=record.message_end_time,
                    uncompressed_crc=record.uncompressed_crc,
                    uncompressed_size=record.uncompressed_size,
                )
                for inner in breakup_chunk(plain, validate_crc=True):
                    take(inner)
                if progress is not None:
                    progress(stream.tell(), file_size)
            else:
                take(record)
    if progress is not None:
        progress(file_size, file_size)


def read(path: Path, selection: Selection, *, fast: bool = True) -> RunLog:
    """Read a run log from an MCAP file.

    Parameters
    ----------
    path : Path
        The MCAP file.
    selection : Selection
        Topic, reference topic and joint (for files not written by ilic).
    fast : bool
        Decode runs of same-layout messages as columns; False: message by message.

    Returns
    -------
    RunLog
    """
    collector = roscollect.Collector(path)
    with current_progress(path) as progress:
        scan(path, collector, progress, fast=fast)
    return rosdecode.decode_guarded(collector.finish(), selection, path, "MCAP")
