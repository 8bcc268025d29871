"""Readers and writers for run logs, chosen by path or by an explicit format.

The registry maps a format name to a module with ``read(path, selection, *, fast)``
and ``write(log, path, options)``; :func:`detect_format` picks the format from the
path (``.mat``, ``.csv``, ``.mcap``, ``.bag``, a ROS 2 bag folder).
"""

from __future__ import annotations

import contextlib
import contextvars
import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io.atomic import atomic_path

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog

FORMATS: dict[str, str] = {
    "mat": "ilic_cli.io.mat",
    "csv": "ilic_cli.io.csvlog",
    "mcap": "ilic_cli.io.mcaplog",
    "rosbag1": "ilic_cli.io.rosbag1",
    "rosbag2": "ilic_cli.io.rosbag2",
}
"""Format name -> module implementing ``read`` and ``write``."""

EXTENSIONS: dict[str, str] = {".mat": "mat", ".csv": "csv", ".mcap": "mcap", ".bag": "rosbag1"}


@dataclass(frozen=True)
class Selection:
    """Which part of a multi-topic, multi-joint log to read.

    Attributes
    ----------
    topic : str or None
        Topic with the measured ``sensor_msgs/JointState`` or ros2_control
        controller state; ``None``: the only JointState topic (or
        ``/joint_states``), else the only controller state.
    ref_topic : str or None
        Topic with the reference; ``None``: ``/joint_reference`` when present,
        else the controller state (see :mod:`ilic_cli.io.rosdecode`).
    joint : str or None
        Joint name; ``None``: the only joint.
    columns : tuple of (str, str)
        CSV: ``(channel, column name)`` pairs naming the columns that hold
        ``t``, ``q``, ``qd``, ``tau``, ``q_ref`` (others: by their usual names,
        :data:`ilic_cli.io.csvlog.ALIASES`).
    effort : str or None
        ROS: ``TOPIC`` or ``TOPIC:FIELD`` giving ``tau`` (``effort`` of a
        JointState; ``feedback.effort`` or ``output.effort`` of a controller
        state); ``None``: the measured topic's effort.
    """

    topic: str | None = None
    ref_topic: str | None = None
    joint: str | None = None
    columns: tuple[tuple[str, str], ...] = ()
    effort: str | None = None


@dataclass(frozen=True)
class WriteOptions:
    """Options for writers.

    Attributes
    ----------
    storage : str
        ``sqlite3`` or ``mcap`` (rosbag2 only).
    joint : str
        Joint name unless the log's metadata names one.
    fast : bool
        Serialise whole columns at once (MCAP, ROS 2 bags); False: the
        per-message writer, kept as the reference for the differential tests.
    """

    storage: str = "sqlite3"
    joint: str = "axis"
    fast: bool = True


class LogFormat(Protocol):
    """What a format module provides: ``read`` and ``write``."""

    def read(self, path: Path, selection: Selection, *, fast: bool = True) -> RunLog: ...

    def write(self, log: RunLog, path: Path, options: WriteOptions) -> None: ...


def bag_folder(path: Path, fmt: str | None = None) -> Path:
    """The ROS 2 bag folder a path inside it names (its ``metadata.yaml``, or its ``.db3``/``.mcap`` storage file); else ``path``.

    An explicit format other than ``rosbag2`` keeps the path as given (an
    ``.mcap`` storage file can be read as plain MCAP with ``mcap``).
    """
    if fmt not in (None, "rosbag2") or path.is_dir():
        return path
    if path.name == "metadata.yaml" or (path.suffix.lower() in (".db3", ".mcap") and (path.parent / "metadata.yaml").is_file()):
        return path.parent
    return path


def detect_format(path: str | Path, fmt: str | None = None, *, for_writing: bool = False) -> str:
    """Return the format name for ``path`` (or check the explicit ``fmt``); a path inside a ROS 2 bag names the bag (:func:`bag_folder`)."""
    p = Path(path) if for_writing else bag_folder(Path(path), fmt)
    if fmt:
        if fmt not in FORMATS:
            raise LogError(p, f"unknown format '{fmt}' (choose from {', '.join(FORMATS)})")
        return fmt
    if p.is_dir() or (not for_writing and (p / "metadata.yaml").exists()):
        return "rosbag2"
    ext = p.suffix.lower()
    if ext in EXTENSIONS:
        return EXTENSIONS[ext]
    if for_writing and ext == "":
        return "rosbag2"
    known = ", ".join([*EXTENSIONS, "a ROS 2 bag folder"])
    raise LogError(p, f"unknown log extension '{ext or '(none)'}' (known: {known}; or name the log's format)")


def _module(fmt: str) -> LogFormat:
    return importlib.import_module(FORMATS[fmt])


ProgressFactory = Callable[[Path], "Progress"]


class Progress(Protocol):
    """A progress display for reading one file (see :func:`read_log`)."""

    def update(self, done: int, total: int) -> None:
        """Show that ``done`` of ``total`` units (bytes, messages) are read."""

    def close(self) -> None:
        """Finish the display."""


_PROGRESS: contextvars.ContextVar[ProgressFactory | None] = contextvars.ContextVar("ilic_read_progress", default=None)


@contextlib.contextmanager
def current_progress(path: Path) -> Iterator[Callable[[int, int], None] | None]:
    """Yield the ``update(done, total)`` callback of the progress display of this read, or None.

    Container readers (MCAP, bags) call it while they stream a file; there is
    a display only when :func:`read_log` was given a ``progress`` factory.
    """
    factory = _PROGRESS.get()
    if factory is None:
        yield None
        return
    display = factory(path)
    try:
        yield display.update
    finally:
        display.close()


def read_log(
    path: str | Path,
    fmt: str | None = None,
    selection: Selection | None = None,
    *,
    validate: bool = True,
    progress: ProgressFactory | None = None,
    fast: bool = True,
) -> RunLog:
    """Read a log file into a :class:`~ilic_cli.runlog.RunLog`.

    Raises :class:`LogError` (one line, naming the file) for a missing, empty,
    corrupt or unusable file. ``progress`` makes a progress display for the
    file (called with its path) that streaming readers update. ``fast=False``
    takes the per-message decoding path of the container formats (the
    reference for the differential tests and benchmarks); both give the same
    columns bit for bit.
    """
    from ilic_cli.runlog import validate_samples  # the run log imports numpy (some 0.1 s): `ilic info --help` imports this package

    p = bag_folder(Path(path), fmt)
    if not p.exists():
        raise LogError(p, "no such file or folder")
    if p.is_file() and p.stat().st_size == 0:
        raise LogError(p, "file is empty")
    name = detect_format(p, fmt)
    _refuse_unused(p, name, selection or Selection())
    token = _PROGRESS.set(progress)
    try:
        # the keyword is passed only when it asks for the per-message path, so a
        # format module without it still reads (and refuses fast=False with TypeError)
        log = _module(name).read(p, selection or Selection(), fast=fast)
    finally:
        _PROGRESS.reset(token)
    log.meta.setdefault("source", str(p))
    if validate:
        validate_samples(log, str(p))
    if len(log) >= 100_000:
        _return_freed_memory()  # after the checks too: their temporaries' pages go back with the reader's
    return log


SELECTED_BY = {
    "topic": ("topics", ("mcap", "rosbag1", "rosbag2")),
    "ref_topic": ("reference topics", ("mcap", "rosbag1", "rosbag2")),
    "joint": ("joint names", ("mcap", "rosbag1", "rosbag2")),
    "effort": ("effort topics", ("mcap", "rosbag1", "rosbag2")),
    "columns": ("named columns", ("csv",)),
}
"""Each field of a :class:`Selection`: what it selects and the formats that have it."""


def _refuse_unused(path: Path, fmt: str, selection: Selection) -> None:
    """Refuse a selection the format has nothing to apply to (it would be ignored, and the log read as if it were not given)."""
    for name, (what, formats) in SELECTED_BY.items():
        if getattr(selection, name) and fmt not in formats:
            raise ChoiceError(path, f"a {fmt} log has no {what} to select", name.replace("_", "-"))


def _return_freed_memory() -> None:
    """Give the heap pages freed after a large read back to the OS (glibc ``malloc_trim``).

    Readers pack messages into many small NumPy blocks; once they are joined
    and freed, glibc would otherwise keep those pages for the process.
    """
    # ctypes (some 3 ms) deferred: only a read of 100k samples or more gives memory back
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.malloc_trim(0)
    except (OSError, AttributeError):  # not glibc: nothing to do
        pass


def write_log(log: RunLog, path: str | Path, fmt: str | None = None, options: WriteOptions | None = None, *, inputs: tuple[str | Path, ...] = ()) -> Path:
    """Write ``log`` to ``path`` atomically (temporary sibling, then rename)."""
    p = Path(path)
    name = detect_format(p, fmt, for_writing=True)
    if p.is_dir() and (name != "rosbag2" or p.is_symlink() or not (p / "metadata.yaml").is_file()):
        raise LogError(p, "is an existing folder that is not a ROS 2 bag; will not replace it (choose another output path)")
    if name == "rosbag2" and p.exists() and not p.is_dir():
        raise LogError(p, "a ROS 2 bag is a folder, but this path is an existing file; choose another output path")
    with atomic_path(p, directory=(name == "rosbag2"), inputs=inputs) as tmp:
        try:
            _module(name).write(log, tmp, options or WriteOptions())
        except LogError as exc:
            # writers only know the temporary path: name the target instead
            if exc.where is None or exc.where == str(tmp):
                raise LogError(p, exc.problem) from None
            raise
        except OSError as exc:
            raise LogError(p, f"cannot write: {exc.strerror or exc}") from None
    return p
