"""Growing NumPy columns of decoded messages, and :class:`Series`, the columns of one topic."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.io.rosschema import RawTopic

JOIN_BYTES = 1 << 20
"""Small blocks of a column are joined once they hold this many bytes."""


class Blocks:
    """The NumPy blocks of a growing column; small ones are joined into blocks of about :data:`JOIN_BYTES`.

    Runs give many small arrays, which live on the C heap; glibc keeps freed
    heap space, so joining them all only at the end would leave the process
    holding the column twice. Joined blocks are mapped and unmapped whole, and
    the small ones' space is reused for the next.
    """

    __slots__ = ("done", "recent", "recent_bytes", "buffer", "filled")

    def __init__(self) -> None:
        self.done: list[np.ndarray] = []
        self.recent: list[np.ndarray] = []
        self.recent_bytes = 0
        self.buffer: np.ndarray | None = None
        self.filled = 0

    def reserve(self, n: int, dtype: Any) -> None:
        """Expect about ``n`` values: fill one array of that size instead of joining blocks at the end.

        A hint only (from a file's summary): more values spill into blocks, fewer are cut.
        """
        if n > 0 and self.buffer is None and not self.done and not self.recent:
            try:
                self.buffer = np.empty(n, dtype=dtype)
            except (MemoryError, ValueError):
                self.buffer = None
            self.filled = 0

    def put(self, values: np.ndarray) -> bool:
        """Copy ``values`` (any shape, flattened row by row) into the reserved array when they fit in it; False (nothing done) when not."""
        buffer = self.buffer
        end = self.filled + values.size
        if buffer is None or end > len(buffer) or values.dtype != buffer.dtype:
            return False
        buffer[self.filled : end].reshape(values.shape)[...] = values
        self.filled = end
        return True

    def add(self, values: np.ndarray) -> None:
        buffer = self.buffer
        if buffer is not None:
            end = self.filled + len(values)
            if end <= len(buffer) and values.dtype == buffer.dtype:
                buffer[self.filled : end] = values
                self.filled = end
                return
            self.done.append(buffer[: self.filled])
            self.buffer = None
        self.recent.append(values)
        self.recent_bytes += values.nbytes
        if self.recent_bytes >= JOIN_BYTES:
            self._join()

    def _join(self) -> None:
        if self.recent:
            self.done.append(np.concatenate(self.recent) if len(self.recent) > 1 else self.recent[0])
            self.recent = []
            self.recent_bytes = 0

    def concat(self, dtype: Any) -> np.ndarray:
        """All values in one array (and no blocks kept)."""
        buffer, self.buffer = self.buffer, None
        if buffer is not None:
            return buffer if self.filled == len(buffer) else buffer[: self.filled].copy()
        self._join()
        out = np.concatenate(self.done) if len(self.done) > 1 else self.done[0] if self.done else np.empty(0, dtype=dtype)
        self.done = []
        return out


class Numbers:
    """A growing column of scalars packed into NumPy blocks every :data:`BLOCK` items.

    With ``small=True`` (non-negative counts and indices) a block is stored as
    uint8 when its values allow, else as the given dtype. An int64 column
    (log times, stamps) is kept as its first value, step and length while its
    values go up by one step (a recorder's clock: 28.8 MB a topic of a 1-hour,
    1 kHz log that need not be held while the other topics are read); it is
    built when asked for (:meth:`array`), the same values.
    """

    __slots__ = ("dtype", "items", "blocks", "small", "affine")

    def __init__(self, dtype: Any, small: bool = False) -> None:
        self.dtype = dtype
        self.items: list[Any] = []
        self.blocks = Blocks()
        self.small = small
        # (first, step, count) while every value so far is first + step * i; None once one is not
        self.affine: tuple[int, int, int] | None = (0, 0, 0) if not small and np.dtype(dtype) == np.int64 else None

    def reserve(self, n: int) -> None:
        """Expect about ``n`` values (see :meth:`Blocks.reserve`); not for small columns."""
        if not self.small:
            self.blocks.reserve(n, self.dtype)

    def block(self, values: np.ndarray) -> None:
        """Append ``values`` after the items so far."""
        self.flush()
        self._add(values)

    def _add(self, values: np.ndarray) -> None:
        if self.affine is not None and self._extends(values):
            return
        if self.small and len(values) and int(values.max()) < 256 and int(values.min()) >= 0:
            values = values.astype(np.uint8)
        self.blocks.add(values)

    def _extends(self, values: np.ndarray) -> bool:
        """Whether ``values`` go on by the column's step (then only counted); else the column so far is built into blocks."""
        assert self.affine is not None
        first, step, count = self.affine
        m = len(values)
        if m == 0:
            return True
        if values.dtype == np.int64:
            head = int(values[0])
            if count == 0:
                first = head
                step = int(values[1]) - head if m > 1 else 0
            elif count == 1:
                step = head - first
            fits = -(2**63) <= step < 2**63 and -(2**63) <= first + step * (count + m - 1) < 2**63
            if fits and (count == 0 or head == first + step * count) and (m == 1 or bool((np.diff(values) == step).all())):
                self.affine = (first, step, count + m)
                return True
        self.affine = None
        if count:
            self.blocks.add(self._progression(first, step, count))
        return False

    @staticmethod
    def _progression(first: int, step: int, count: int) -> np.ndarray:
        """``first + step * i`` for ``i < count`` (int64, wrapping as NumPy's int64 does: each value fits, so it is exact), built in place."""
        out = np.arange(count, dtype=np.int64)
        out *= np.int64(step)
        out += np.int64(first)
        return out

    def flush(self) -> None:
        if self.items:
            block = np.asarray(self.items, dtype=self.dtype)
            self.items = []
            self._add(block)

    def array(self) -> np.ndarray:
        self.flush()
        if self.affine is not None:
            first, step, count = self.affine
            self.affine = None
            self.blocks = Blocks()
            return self._progression(first, step, count)
        return self.blocks.concat(self.dtype)


class Arrays:
    """A growing column of small float arrays (one per message), flattened into NumPy blocks."""

    __slots__ = ("items", "blocks", "counts", "expected")

    def __init__(self) -> None:
        self.items: list[Any] = []
        self.blocks = Blocks()
        self.counts = Numbers(np.int32, small=True)
        self.expected = 0

    def append(self, values: Any) -> None:
        self.items.append(values)
        self.counts.items.append(len(values))

    def block(self, values: np.ndarray, *, owned: bool = True) -> None:
        """Append one (messages, width) float64 block after the items so far.

        ``owned=False``: ``values`` is a view of another buffer (a run's
        messages), copied here: once, into the reserved array when it fits.
        """
        self.flush()
        if self.expected and values.ndim == 2 and values.shape[1]:
            # the first block tells the width: reserve for the expected messages
            self.blocks.reserve(self.expected * values.shape[1], np.float64)
            self.expected = 0
        if not self.blocks.put(values):
            self.blocks.add(values.reshape(-1) if owned else np.array(values).reshape(-1))
        self.counts.block(np.full(values.shape[0], values.shape[1] if values.ndim == 2 else 1, dtype=np.int32))

    def flush(self) -> None:
        if self.items:
            try:
                block = np.concatenate(self.items).astype(np.float64, copy=False)
            except (ValueError, TypeError):
                block = np.concatenate([np.asarray(v, dtype=np.float64).reshape(-1) for v in self.items])
            self.blocks.add(block)
            self.items = []
        self.counts.flush()

    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        self.flush()
        flat = self.blocks.concat(np.float64)
        return flat, self.counts.array()


@dataclass
class Series:
    """Decoded messages of one topic as columns (no per-message Python objects).

    Attributes
    ----------
    topic : RawTopic
        The topic.
    log_ns : ndarray of int64
        Log time of each message, sorted.
    stamp_ns : ndarray of int64 or None
        ``header.stamp`` of each message (JointState).
    name_id : ndarray of int32 or None
        Index into ``names`` of each message's ``name`` list (JointState).
    names : list of tuple of str
        Distinct ``name`` lists, in order of first appearance.
    fields : dict
        Array field -> ``(flat values, count per message)``.
    text : str or None
        Data of the first message (String).
    message_id : ndarray of int64 or None
        For topics with several rows per message (the points of a
        ``JointTrajectory``): the message each row comes from, in arrival order.
    """

    topic: RawTopic
    log_ns: np.ndarray
    stamp_ns: np.ndarray | None = None
    name_id: np.ndarray | None = None
    names: list[tuple[str, ...]] = field(default_factory=list)
    fields: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    text: str | None = None
    message_id: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.log_ns)

    def values_at(self, fieldname: str, index: np.ndarray | int, keep: np.ndarray | None = None) -> np.ndarray | None:
        """Element ``index[i]`` of ``fieldname`` for the messages ``keep``; None when one is too short."""
        flat, counts = self.fields[fieldname]
        if keep is None and np.ndim(index) == 0 and len(counts):
            # the usual case: every message has the same width -> a strided view, no index arrays
            width = int(counts[0])
            j = int(index)
            if width > j and bool((counts == width).all()):
                return flat if width == 1 else np.ascontiguousarray(flat[j::width])
            if not (counts > j).all():
                return None
        starts = np.cumsum(counts, dtype=np.int64) - counts
        if keep is not None:
            counts, starts = counts[keep], starts[keep]
        if len(counts) == 0 or not (counts > index).all():
            return None
        return flat[starts + index]


def sort_series(series: Series) -> None:
    """Put the messages of ``series`` in log-time order (stable) when they are not."""
    log_ns = series.log_ns
    if len(log_ns) < 2 or bool((log_ns[1:] >= log_ns[:-1]).all()):
        return
    order = np.argsort(log_ns, kind="stable")
    series.log_ns = log_ns[order]
    if series.stamp_ns is not None:
        series.stamp_ns = series.stamp_ns[order]
    if series.name_id is not None:
        series.name_id = series.name_id[order]
    if series.message_id is not None:
        series.message_id = series.message_id[order]
    for name, (flat, counts) in series.fields.items():
        starts = (np.cumsum(counts, dtype=np.int64) - counts)[order]
        counts = counts[order]
        total = int(counts.sum())
        shift = np.repeat(starts - (np.cumsum(counts, dtype=np.int64) - counts), counts)
        series.fields[name] = (flat[np.arange(total, dtype=np.int64) + shift], counts)
