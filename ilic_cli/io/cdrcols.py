"""Runs of same-layout ROS 2 CDR messages <-> NumPy columns, without a Python object per message.

A *layout* is what :func:`layout` finds by walking one little-endian CDR
message of a built-in type (``JointState``, ``JointTrajectoryPoint``,
``String``): where its stamps and float64 values lie, its names or text, and
which bytes are *structural* (encapsulation header, sequence and string
lengths, string bytes and NULs, padding). Messages of a run share a layout
when their structural bytes are equal, so a run is decoded by comparing the
structural bytes of every message with the first one's and taking the values
as strided views. Anything else (other types, big-endian or odd sizes,
messages that do not match) is left to the per-message decoder.

Writing goes the other way: one message serialised by ``rosbags`` is the
template, repeated and filled column by column (:func:`fill_rows`).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.io.rosschema import JOINT_STATE, STRING, TRAJECTORY, TRAJECTORY_POINT

LITTLE_ENDIAN = b"\x00\x01\x00\x00"
"""CDR encapsulation header of a little-endian plain CDR message."""

# field kinds, in message order (``one``: a sequence's length, which must be 1)
_POINT: tuple[tuple[str, str], ...] = (
    ("f64s", "positions"),
    ("f64s", "velocities"),
    ("f64s", "accelerations"),
    ("f64s", "effort"),
    ("time", "time_from_start"),
)
_FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    JOINT_STATE: (("time", "stamp"), ("string", "frame_id"), ("strings", "name"), ("f64s", "position"), ("f64s", "velocity"), ("f64s", "effort")),
    TRAJECTORY_POINT: _POINT,
    STRING: (("string", "data"),),
    TRAJECTORY: (("time", "stamp"), ("string", "frame_id"), ("strings", "joint_names"), ("one", "points"), *_POINT),
}

FAST_TYPES = frozenset({JOINT_STATE, TRAJECTORY_POINT, STRING})
"""Message types whose runs the one-joint collector decodes and encodes as columns. :func:`layout` walks a one-point
``JointTrajectory`` too (an arm's reference, :mod:`ilic_cli.io.jointros`), which that collector does not take as columns:
its trajectories may hold any number of points."""

MAX_STRINGS = 4096
"""Most strings in one ``name`` list that a layout accepts."""


@dataclass(frozen=True)
class Layout:
    """Where the values of one CDR message lie.

    Attributes
    ----------
    size : int
        Message size in bytes (with the 4-byte encapsulation header).
    times : dict
        Time field -> offset of its int32 seconds (uint32 nanoseconds follow).
    arrays : dict
        float64 sequence -> (offset of the first value, count).
    strings : dict
        String field -> its text; ``name`` -> tuple of texts.
    varying : ndarray of bool
        True for the bytes that hold values (times, floats), False for structural bytes.
    """

    size: int
    times: dict[str, int]
    arrays: dict[str, tuple[int, int]]
    strings: dict[str, Any]
    varying: np.ndarray


def layout(data: bytes, msgtype: str) -> Layout | None:
    """Walk one message of ``msgtype``; return its layout, or None when it cannot be walked.

    None means: not a type of :data:`FAST_TYPES`, not little-endian CDR, or
    malformed (lengths past the end, a string without NUL or not UTF-8,
    bytes left over). The caller then decodes the message with ``rosbags``.
    """
    fields = _FIELDS.get(msgtype)
    if fields is None or len(data) < 4 or data[:4] != LITTLE_ENDIAN:
        return None
    size = len(data)
    varying = np.zeros(size, dtype=bool)
    times: dict[str, int] = {}
    arrays: dict[str, tuple[int, int]] = {}
    strings: dict[str, Any] = {}
    pos = 4  # alignment counts from the end of the encapsulation header

    def align(at: int, n: int) -> int:
        return 4 + ((at - 4 + n - 1) & -n)

    def u32(at: int) -> int | None:
        if at + 4 > size:
            return None
        return int(struct.unpack_from("<I", data, at)[0])

    def text(at: int) -> tuple[str, int] | None:
        at = align(at, 4)
        length = u32(at)
        if length is None or length < 1 or at + 4 + length > size or data[at + 4 + length - 1] != 0:
            return None
        try:
            value = data[at + 4 : at + 3 + length].decode("utf-8")
        except UnicodeDecodeError:
            return None
        return value, at + 4 + length

    for kind, name in fields:
        if kind == "time":
            pos = align(pos, 4)
            if pos + 8 > size:
                return None
            times[name] = pos
            varying[pos : pos + 8] = True
            pos += 8
        elif kind == "string":
            got = text(pos)
            if got is None:
                return None
            strings[name], pos = got
        elif kind == "one":
            pos = align(pos, 4)
            if u32(pos) != 1:
                return None
            pos += 4
        elif kind == "strings":
            pos = align(pos, 4)
            count = u32(pos)
            if count is None or count > MAX_STRINGS:
                return None
            pos += 4
            items = []
            for _ in range(count):
                got = text(pos)
                if got is None:
                    return None
                value, pos = got
                items.append(value)
            strings[name] = tuple(items)
        else:  # float64 sequence
            pos = align(pos, 4)
            count = u32(pos)
            if count is None:
                return None
            pos += 4
            if count:
                pos = align(pos, 8)
                if pos + 8 * count > size:
                    return None
                varying[pos : pos + 8 * count] = True
            arrays[name] = (pos, count)
            pos += 8 * count
    if pos != size:
        return None
    return Layout(size, times, arrays, strings, varying)


def rows_view(buf: np.ndarray, base: int, stride: int, count: int, size: int) -> np.ndarray:
    """``count`` messages of ``size`` bytes at ``base + i * stride`` in ``buf``, as a (count, size) view."""
    return np.lib.stride_tricks.as_strided(buf[base:], shape=(count, size), strides=(stride, 1), writeable=False)


def matching_rows(buf: np.ndarray, base: int, stride: int, count: int, lay: Layout) -> int:
    """Number of leading messages of the run whose structural bytes equal the first one's.

    Messages that start 8-byte aligned at a stride of whole words (the
    sqlite3 reader's padded rows) are compared a word at a time, their value
    bytes and the bytes past them masked out (:func:`_matching_words`); others
    byte by byte: the same count.
    """
    words = (lay.size + 7) // 8
    if count > 1 and stride % 8 == 0 and (buf.ctypes.data + base) % 8 == 0 and base + (count - 1) * stride + 8 * words <= buf.nbytes:
        return _matching_words(buf, base, stride, count, lay, words)
    rows = rows_view(buf, base, stride, count, lay.size)
    fixed = np.flatnonzero(~lay.varying)
    same = (rows[:, fixed] == rows[0, fixed]).all(axis=1)
    bad = np.flatnonzero(~same)
    return int(bad[0]) if len(bad) else count


def _matching_words(buf: np.ndarray, base: int, stride: int, count: int, lay: Layout, words: int) -> int:
    """:func:`matching_rows` of aligned messages, a 64-bit word at a time."""
    mask = np.zeros(8 * words, dtype=np.uint8)
    mask[: lay.size] = np.where(lay.varying, 0, 0xFF)
    rows = np.ndarray((count, words), dtype=np.uint64, buffer=buf, offset=base, strides=(stride, 8))
    diff = rows ^ rows[0]
    diff &= mask.view(np.uint64)
    bad = np.flatnonzero(diff.any(axis=1))
    return int(bad[0]) if len(bad) else count


def column(buf: np.ndarray, offset: int, stride: int, count: int, dtype: str, width: int = 1, *, copy: bool = True) -> np.ndarray:
    """A copy of ``count`` values (``width`` per message) of ``dtype`` at ``offset + i * stride``; ``copy=False``: a (count, width) view of ``buf``."""
    item = np.dtype(dtype).itemsize
    view = np.ndarray((count, width), dtype=dtype, buffer=buf, offset=offset, strides=(stride, item))
    if not copy:
        return view
    return view.copy() if width > 1 else view[:, 0].copy()


def times_ns(buf: np.ndarray, offset: int, stride: int, count: int) -> np.ndarray:
    """``sec * 1e9 + nanosec`` (int64) of a time field at ``offset + i * stride``."""
    sec = column(buf, offset, stride, count, "<i4").astype(np.int64)
    nsec = column(buf, offset + 4, stride, count, "<u4").astype(np.int64)
    return sec * 1_000_000_000 + nsec


def fill_rows(template: bytes, count: int) -> np.ndarray:
    """``count`` copies of ``template`` as a writable (count, len(template)) uint8 array."""
    return np.tile(np.frombuffer(template, dtype=np.uint8), (count, 1))


def put(rows: np.ndarray, offset: int, dtype: str, values: np.ndarray) -> None:
    """Write ``values`` (one per row, or (rows, width)) of ``dtype`` at byte ``offset`` of every row."""
    values = np.asarray(values)
    width = 1 if values.ndim == 1 else values.shape[1]
    item = np.dtype(dtype).itemsize
    view = np.ndarray((rows.shape[0], width), dtype=dtype, buffer=rows, offset=offset, strides=(rows.strides[0], item))
    view[...] = values.reshape(rows.shape[0], width)
