"""ROS 1 bags (``.bag``, format 2.0) through ``rosbags.rosbag1``.

Messages use the ROS 1 Noetic types of the ``rosbags`` type store (the same
topics as every ROS container, see :mod:`ilic_cli.io.roscollect`), uncompressed
chunks, no caller id: the same log always gives the same bytes.

Reading refuses connections whose MD5 sum differs from the built-in
definition (a differently defined message of the same name), and caps chunk
decompression at ``min(2 GiB, 64 x file size)``.

By default (``fast=True``) both directions go through
:mod:`ilic_cli.io.ros1fast` and :mod:`ilic_cli.io.ros1write`: reading decodes runs of same-layout messages as
NumPy views, chunk by chunk, and reads any file whose structure it does not
expect per message as before; writing serialises whole columns and gives the
bytes of the per-message writer.
"""

from __future__ import annotations

import bz2
from pathlib import Path
from typing import TYPE_CHECKING, Any

import lz4.frame
from rosbags.rosbag1 import Reader, Writer

from ilic_cli.errors import LogError
from ilic_cli.io import container, ros1fast, ros1write, roscollect, rosdecode, rosencode, rosschema

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions
    from ilic_cli.runlog import RunLog

MAX_CHUNK_BYTES = 2 * 2**30
MAX_EXPANSION = 64


def write(log: RunLog, path: Path, options: WriteOptions) -> None:
    """Write ``log`` to a ROS 1 bag.

    Parameters
    ----------
    log : RunLog
        The log to write.
    path : Path
        Destination file (a temporary path chosen by ``write_log``; it may
        exist empty and is replaced).
    options : WriteOptions
        ``options.joint`` names the joint unless ``log.meta["joint"]`` does;
        ``options.fast`` (default True) serialises whole columns at once
        (:mod:`ilic_cli.io.ros1write`), False writes message by message through
        ``rosbags``. Both give the same bytes.
    """
    joint = rosencode.writer_joint(log, options.joint)
    if getattr(options, "fast", True):
        ros1write.write(log, joint, path)
        return
    path.unlink(missing_ok=True)  # rosbags refuses to overwrite the placeholder
    container.write_bag(Writer(path), log, joint, rosschema.ROS1)


def _bounded(decompress: Any, limit: int, path: Path) -> Any:
    """Wrap a chunk decompressor so that it never returns more than ``limit`` bytes."""

    def run(data: bytes) -> bytes:
        if decompress is bz2.decompress:
            out = bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
        elif decompress is lz4.frame.decompress:
            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
        else:  # uncompressed: the data already is in memory
            out = decompress(data)
        if len(out) > limit:
            raise LogError(path, f"a bag chunk decompresses to more than {limit} bytes; file is corrupt or hostile")
        return out

    return run


def _declare(collector: roscollect.Collector, connections: list[Any], later: frozenset[str] = frozenset()) -> dict[int, Any]:
    """Register ``rosbags`` connections with ``collector``; return connection id -> sink of those to read.

    A connection whose MD5 sum differs from the built-in definition gets a
    sink that holds the error (raised when its topic is used). Topics of the
    types in ``later`` are registered without a sink (a second pass reads them).
    """
    ts = rosschema.typestore(rosschema.ROS1)
    sinks: dict[int, Any] = {}
    for conn in connections:
        topic = rosschema.RawTopic(conn.topic, rosschema.normalize_msgtype(conn.msgtype), rosschema.ROS1)
        sink = collector.declare(topic, decode=topic.msgtype not in later)
        if sink is None:
            continue
        _, md5 = ts.generate_msgdef(topic.msgtype)
        if conn.digest and conn.digest != md5 and sink.error is None:
            sink.error = f"topic {conn.topic}: definition of {topic.msgtype} differs from the standard one (md5 {conn.digest})"
        sinks[conn.id] = sink
    return sinks


def _collect(reader: Any, path: Path, topics: frozenset[str] | None = None) -> roscollect.Collected:
    """Stream the messages of every readable connection (or those of ``topics``) into a :class:`roscollect.Collector`."""
    collector = roscollect.Collector(path)
    connections = [conn for conn in reader.connections if topics is None or conn.topic in topics]
    sinks = _declare(collector, connections)
    wanted = [conn for conn in connections if conn.id in sinks]
    container.feed_sinks(reader, wanted, sinks, path)
    return collector.finish()


def _declare_columns(collector: roscollect.Collector, connections: list[Any]) -> dict[int, Any]:
    """:func:`_declare` for the columnar reader: the types it cannot take as columns are left to :func:`_collect`."""
    return _declare(collector, connections, roscollect.PER_MESSAGE)


def _open(path: Path, limit: int) -> Any:
    """A ``rosbags`` reader of ``path`` whose chunks decompress to at most ``limit`` bytes."""
    try:
        reader = Reader(path)
        reader.open()
    except LogError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds (incl. AssertionError) on bad files
        raise LogError(path, f"not a readable ROS 1 bag ({_describe(exc)})") from None
    for pos, chunk in list(reader.chunks.items()):
        reader.chunks[pos] = chunk._replace(decompressor=_bounded(chunk.decompressor, limit, path))
    return reader


def read(path: Path, selection: Selection, *, fast: bool = True) -> RunLog:
    """Read a run log from a ROS 1 bag.

    Parameters
    ----------
    path : Path
        The ``.bag`` file.
    selection : Selection
        Topic, reference topic and joint (for bags not written by ilic).
    fast : bool
        Decode runs of same-layout messages as NumPy views
        (:mod:`ilic_cli.io.ros1fast`); a file whose structure that reader does
        not handle is read per message. False: per message through ``rosbags``.

    Returns
    -------
    RunLog
    """
    limit = min(MAX_CHUNK_BYTES, MAX_EXPANSION * max(path.stat().st_size, 1))
    if fast:
        try:
            source = ros1fast.collect(path, limit, _declare_columns)
        except LogError:
            raise
        except MemoryError:
            raise LogError(path, "ROS 1 bag content needs more memory than available") from None
        except Exception:  # noqa: BLE001 - Fallback, or anything unexpected on a damaged file: per message
            source = None
        if source is not None:
            later = frozenset(name for name, topic in source.topics.items() if topic.msgtype in roscollect.PER_MESSAGE)
            if later:  # controller states, trajectories: a second pass, per message, over their connections only
                reader = _open(path, limit)
                try:
                    with container.guarded(path, "ROS 1 bag"):
                        source.adopt(_collect(reader, path, later))
                finally:
                    container.close_quietly(reader)
            return rosdecode.decode_guarded(source, selection, path, "ROS 1 bag")
    reader = _open(path, limit)
    try:
        with container.guarded(path, "ROS 1 bag"):
            source = _collect(reader, path)
        return rosdecode.decode_guarded(source, selection, path, "ROS 1 bag")
    finally:
        container.close_quietly(reader)


def _describe(exc: BaseException) -> str:
    text = " ".join(str(exc).split())[:160]
    if isinstance(exc, (EOFError,)) or "unexpected end" in text.lower() or "truncat" in text.lower():
        return "file is truncated"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
