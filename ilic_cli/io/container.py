"""Plumbing shared by the container modules (MCAP, ROS 1 and ROS 2 bags): error guards, streaming, writing."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ilic_cli.errors import LogError
from ilic_cli.io import current_progress
from ilic_cli.io.rosencode import encode
from ilic_cli.io.rosschema import typestore

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog


def short_text(exc: BaseException) -> str:
    """The exception's message on one line, cut at 160 characters."""
    text = " ".join(str(exc).split())
    return text[:160] + ("..." if len(text) > 160 else "")


@contextlib.contextmanager
def guarded(path: Path, container: str) -> Iterator[None]:
    """Context manager turning any unexpected library failure into a one-line :class:`LogError`.

    Parameters
    ----------
    path : Path
        The file named in the error.
    container : str
        Container name for the message (``"MCAP"``, ``"ROS 1 bag"``...).
    """
    try:
        yield
    except LogError:
        raise
    except MemoryError:
        raise LogError(path, f"{container} content needs more memory than available") from None
    except Exception as exc:  # noqa: BLE001 - every failure on file content is bad input
        raise LogError(path, f"cannot read {container} content ({type(exc).__name__}: {short_text(exc)})") from None


def feed_sinks(reader: Any, wanted: list[Any], sinks: dict[int, Any], path: Path) -> None:
    """Stream a ``rosbags`` reader's messages of the ``wanted`` connections into their sinks.

    Drives the read's progress display (if any) every 65536 messages.
    """
    total = sum(int(getattr(conn, "msgcount", 0) or 0) for conn in wanted) or 1
    with current_progress(path) as progress:
        for done, (conn, log_ns, data) in enumerate(reader.messages(connections=wanted) if wanted else (), start=1):
            sinks[conn.id].add(log_ns, data)
            if progress is not None and done % 65536 == 0:
                progress(done, total)
        if progress is not None:
            progress(total, total)


def close_quietly(reader: Any) -> None:
    """Close a ``rosbags`` reader; a broken one's close error must not mask the real error."""
    try:
        reader.close()
    except Exception:  # noqa: BLE001, S110
        pass


def write_bag(writer: Any, log: RunLog, joint: str, kind: str) -> None:
    """Write ``log``'s messages with a not yet opened ``rosbags`` writer (ROS 1 or ROS 2).

    The writer is aborted on any failure, so that no half-written bag is closed.
    """
    topics, messages = encode(log, joint, kind)
    ts = typestore(kind)
    writer.open()
    try:
        connections = {spec.topic: writer.add_connection(spec.topic, spec.msgtype, typestore=ts) for spec in topics}
        for topic, log_ns, data in messages:
            writer.write(connections[topic], log_ns, data)
    except BaseException:
        writer.abort()
        raise
    writer.close()
