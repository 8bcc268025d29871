"""Fast MCAP reading: records walked chunk by chunk, runs of message records decoded as columns.

The file is read record by record (magic, lengths bounded by the file size,
data-section CRC up to ``DataEnd``, footer and closing magic); schemas and
channels are parsed with the ``mcap`` record classes. Each chunk is
decompressed in one capped call and its CRC checked, then its records are
walked: where message records repeat with a fixed period (same opcodes,
lengths and channel ids, checked for every record through strided views), the
messages of each channel are handed to its sink as one run
(:meth:`ilic_cli.io.roscollect._Sink.add_run`); anything else is parsed one
record at a time. Only one decompressed chunk is in memory at a time.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Chunk, Schema

MAGIC = b"\x89MCAP0\r\n"
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END, OP_FOOTER = 0x03, 0x04, 0x05, 0x06, 0x0F, 0x02
MESSAGE_HEAD = 31
"""Bytes of a message record before its data: opcode, length, channel, sequence, log and publish time."""

MAX_PERIOD_RECORDS = 16
"""Most records in one repeating group that the run finder looks for."""

MIN_RUN = 4
"""Fewest repetitions of a group handled as a run (shorter ones are parsed record by record)."""

MAX_SKIP = 255
"""Most message records taken one by one between two searches for a run (irregular files)."""

MAX_HINT_EXPANSION = 64
"""A summary's message count is capped at this many times the file size over the 31 bytes of a message head."""


class McapScanError(Exception):
    """A structural problem found while walking an MCAP file (reported as a :class:`LogError`)."""


Declare = Callable[[Any, Any], Any]
"""``declare(channel, schema)`` -> sink or None, called for each new channel record."""


def scan(
    path: Path,
    declare: Declare,
    decompress: Callable[[Any, int], bytes],
    limit: int,
    progress: Callable[[int, int], None] | None,
    counts: dict[int, int] | None = None,
) -> None:
    """Walk every record of the MCAP file at ``path``.

    Parameters
    ----------
    path : Path
        The file.
    declare : callable
        Called as ``declare(channel, schema)`` for each channel record whose
        schema is known; returns the sink for its messages or None.
    decompress : callable
        ``decompress(chunk, limit)`` -> the chunk's records (size and cap checked).
    limit : int
        Largest accepted uncompressed chunk.
    progress : callable or None
        ``progress(bytes_read, file_size)`` after each chunk.
    counts : dict, optional
        Channel id -> message count from the file's summary: a hint for the
        sinks' column sizes (:meth:`ilic_cli.io.roscollect._Sink.reserve`), never trusted.

    Raises
    ------
    McapScanError
        Bad magic, truncation, a CRC mismatch, a malformed chunk.
    """
    size = path.stat().st_size
    most = MAX_HINT_EXPANSION * size // MESSAGE_HEAD
    state = _State(declare, {cid: min(int(n), most) for cid, n in (counts or {}).items()})
    with open(path, "rb") as stream:
        magic = stream.read(8)
        if magic != MAGIC:
            raise McapScanError("bad magic bytes (not MCAP, or truncated)")
        crc: int | None = zlib.crc32(magic)
        while True:
            head = stream.read(9)
            if len(head) < 9:
                raise McapScanError("file is truncated or corrupt (unexpected end of data)")
            opcode, length = struct.unpack("<BQ", head)
            if length > size:
                raise McapScanError("file is truncated or corrupt (a record runs past the end of the file)")
            body = stream.read(length)
            if len(body) < length:
                raise McapScanError("file is truncated or corrupt (unexpected end of data)")
            if opcode == OP_DATA_END:
                if len(body) < 4:
                    raise McapScanError("file is truncated or corrupt (unexpected end of data)")
                expected = struct.unpack_from("<I", body)[0]
                if crc is not None and expected != 0 and expected != crc:
                    raise McapScanError("CRC check failed in DataEnd record (file is corrupt)")
                crc = None
            elif crc is not None:
                crc = zlib.crc32(body, zlib.crc32(head, crc))
            if opcode == OP_CHUNK:
                chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
                del body
                data = decompress(chunk, limit)
                if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
                    raise McapScanError("CRC check failed in Chunk record (file is corrupt)")
                del chunk
                state.walk(np.frombuffer(data, dtype=np.uint8))
                if progress is not None:
                    progress(stream.tell(), size)
            elif opcode == OP_SCHEMA:
                state.schema(Schema.read(ReadDataStream(io.BytesIO(body))))
            elif opcode == OP_CHANNEL:
                state.channel(Channel.read(ReadDataStream(io.BytesIO(body))))
            elif opcode == OP_MESSAGE:
                state.single(np.frombuffer(body, dtype=np.uint8), -9, length)
            elif opcode == OP_FOOTER:
                if stream.read(8) != MAGIC:
                    raise McapScanError("bad magic bytes (not MCAP, or truncated)")
                break
    if progress is not None:
        progress(size, size)


class _State:
    """Schemas, channels and sinks seen so far, and the chunk walker."""

    def __init__(self, declare: Declare, counts: dict[int, int]) -> None:
        self.declare = declare
        self.counts = counts
        self.schemas: dict[int, Any] = {}
        self.sinks: dict[int, Any] = {}
        # after failed searches for a run, the next few message records are
        # taken one by one without searching (1, 3, 7, ... up to MAX_SKIP)
        self.skip = 0
        self.backoff = 1

    def schema(self, record: Any) -> None:
        self.schemas[record.id] = record

    def channel(self, record: Any) -> None:
        schema = self.schemas.get(record.schema_id)
        if schema is not None:
            sink = self.sinks[record.id] = self.declare(record, schema)
            if sink is not None and self.counts.get(record.id):
                sink.reserve(self.counts[record.id])

    def single(self, buf: np.ndarray, at: int, length: int) -> None:
        """One message record whose opcode is at ``at`` (its body starts at ``at + 9``)."""
        if length < MESSAGE_HEAD - 9:
            raise McapScanError("file is truncated or corrupt (a message record is too short)")
        body = at + 9
        channel_id, _, log_time, _ = struct.unpack_from("<HIQQ", buf, body)  # type: ignore[arg-type]  # numpy's stubs give ndarray the buffer protocol only for Python >= 3.12
        sink = self.sinks.get(channel_id)
        if sink is not None:
            sink.add(log_time, bytes(buf[at + MESSAGE_HEAD : at + 9 + length]))

    def walk(self, buf: np.ndarray) -> None:
        """Walk the records of one decompressed chunk."""
        end = len(buf)
        pos = 0
        while pos < end:
            if end - pos < 9:
                raise McapScanError("file is truncated or corrupt (a record runs past the end of its chunk)")
            opcode = int(buf[pos])
            length = int(buf[pos + 1 : pos + 9].view("<u8")[0])
            stop = pos + 9 + length
            if stop > end:
                raise McapScanError("file is truncated or corrupt (a record runs past the end of its chunk)")
            if opcode == OP_MESSAGE:
                advanced = self._run(buf, pos, end) if self.skip == 0 else 0
                if advanced:
                    self.backoff = 1
                    pos += advanced
                    continue
                if self.skip:
                    self.skip -= 1
                else:
                    self.skip = self.backoff - 1
                    self.backoff = min(2 * self.backoff, MAX_SKIP + 1)
                self.single(buf, pos, length)
            elif opcode == OP_SCHEMA:
                self.schema(Schema.read(ReadDataStream(io.BytesIO(buf[pos + 9 : stop].tobytes()))))
            elif opcode == OP_CHANNEL:
                self.channel(Channel.read(ReadDataStream(io.BytesIO(buf[pos + 9 : stop].tobytes()))))
            elif opcode == OP_CHUNK:
                raise McapScanError("a chunk inside a chunk (file is corrupt)")
            pos = stop

    def _run(self, buf: np.ndarray, pos: int, end: int) -> int:
        """Hand a run of repeating message groups at ``pos`` to the sinks; return the bytes taken (0: none)."""
        heads: list[tuple[int, int, int, int]] = []  # offset from pos, opcode, length, channel
        at = pos
        while len(heads) <= MAX_PERIOD_RECORDS and end - at >= MESSAGE_HEAD:
            opcode = int(buf[at])
            length = int(buf[at + 1 : at + 9].view("<u8")[0])
            if opcode != OP_MESSAGE or length < MESSAGE_HEAD - 9 or at + 9 + length > end:
                break
            channel = int(buf[at + 9 : at + 11].view("<u2")[0])
            if heads and (length, channel) == heads[0][2:]:
                break
            heads.append((at - pos, opcode, length, channel))
            at += 9 + length
        period = at - pos
        if (
            not heads
            or end - at < MESSAGE_HEAD
            or (int(buf[at]), int(buf[at + 1 : at + 9].view("<u8")[0]), int(buf[at + 9 : at + 11].view("<u2")[0])) != (OP_MESSAGE, heads[0][2], heads[0][3])
        ):
            return 0
        groups = (end - pos) // period
        if groups < MIN_RUN:
            return 0
        good = np.ones(groups, dtype=bool)
        for offset, _, length, channel in heads:
            first = pos + offset
            good &= np.ndarray((groups,), dtype=np.uint8, buffer=buf, offset=first, strides=(period,)) == OP_MESSAGE
            good &= np.ndarray((groups,), dtype="<u8", buffer=buf, offset=first + 1, strides=(period,)) == length
            good &= np.ndarray((groups,), dtype="<u2", buffer=buf, offset=first + 9, strides=(period,)) == channel
        bad = np.flatnonzero(~good)
        groups = int(bad[0]) if len(bad) else groups
        if groups < MIN_RUN:
            return 0
        slots_of: dict[int, list[tuple[int, int]]] = {}
        for offset, _, length, channel in heads:
            slots_of.setdefault(channel, []).append((offset, length))
        for channel, slots in slots_of.items():
            sink = self.sinks.get(channel)
            if sink is not None:
                self._feed(sink, buf, pos, period, groups, slots)
        return groups * period

    def _feed(self, sink: Any, buf: np.ndarray, pos: int, period: int, groups: int, slots: list[tuple[int, int]]) -> None:
        """Hand one channel's messages of a run to its sink, in file order.

        One slot per group: a strided run. Several slots of one size: the
        messages gathered in file order, then one run. Several sizes: one by one.
        """
        sizes = {length for _, length in slots}
        if len(sizes) > 1:
            for k in range(groups):
                for offset, length in slots:
                    self.single(buf, pos + k * period + offset, length)
            return
        length = sizes.pop()
        size = length + 9 - MESSAGE_HEAD
        if len(slots) == 1:
            first = pos + slots[0][0]
            log_ns = np.ndarray((groups,), dtype="<u8", buffer=buf, offset=first + 15, strides=(period,))
            if int(log_ns.max()) >= 2**63:
                for k in range(groups):
                    self.single(buf, first + k * period, length)
            else:
                sink.add_run(buf, first + MESSAGE_HEAD, period, groups, size, log_ns.astype(np.int64))
            return
        starts = (pos + np.array([offset for offset, _ in slots], dtype=np.int64)[None, :] + period * np.arange(groups, dtype=np.int64)[:, None]).reshape(-1)
        log_ns = buf[starts[:, None] + 15 + np.arange(8)].copy().view("<u8").reshape(-1)
        if int(log_ns.max()) >= 2**63:
            for start in starts.tolist():
                self.single(buf, start, length)
            return
        data = buf[starts[:, None] + MESSAGE_HEAD + np.arange(size)].reshape(-1)
        sink.add_run(data, 0, size, len(starts), size, log_ns.astype(np.int64))
