"""Messages of a container -> per-topic NumPy columns (:class:`Collector` and its sinks).

Container modules stream every message once into a :class:`Collector`, which
decodes it with the ``rosbags`` type store and keeps only NumPy columns of the
values (no Python object per message). Only the built-in message types are
decoded: definitions stored in a file are never compiled or executed.

Containers that hold messages back to back (MCAP chunks, sqlite3 blobs) hand
whole runs to :meth:`_Sink.add_run`, which decodes runs of same-layout ROS 2
messages as columns (:mod:`ilic_cli.io.cdrcols`) and the rest one by one. The columns themselves
are :mod:`ilic_cli.io.roscolumns`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io import cdrcols
from ilic_cli.io.container import short_text
from ilic_cli.io.roscolumns import Arrays, Numbers, Series, sort_series
from ilic_cli.io.rosschema import (
    CONTROLLER_LAYOUTS,
    CONTROLLER_STATE,
    JOINT_STATE,
    ROS1,
    ROS2,
    STRING,
    TRAJECTORY,
    TRAJECTORY_POINT,
    RawTopic,
    controller_typestore,
    typestore,
)
from ilic_cli.io.rostopics import Collected

BLOCK = 8192
"""Messages buffered as Python values before they are packed into NumPy blocks."""

MIN_RUN = 4
"""Fewest same-layout messages decoded as columns (unless they are all that is left of a run)."""

MAX_SKIP = 255
"""Most messages decoded alone before a layout is tried again (irregular topics)."""


class _Sink:
    """Decodes the messages of one topic into columns; the first failure is kept, raised on use."""

    arrays: tuple[str, ...] = ()

    def __init__(self, topic: RawTopic) -> None:
        ts = typestore(topic.kind)
        self.topic = topic
        self.count = 0
        self.error: str | None = None
        self._deserialize = ts.deserialize_ros1 if topic.kind == ROS1 else ts.deserialize_cdr
        self._log_ns = Numbers(np.int64)
        self._arrays = {name: Arrays() for name in self.arrays}
        self._last: tuple[cdrcols.Layout, np.ndarray, np.ndarray] | None = None
        self._window = 256
        self._skip = 0
        self._backoff = 1

    def reserve(self, n: int) -> None:
        """Expect about ``n`` messages (a hint from the file's summary; see :meth:`ilic_cli.io.roscolumns.Blocks.reserve`)."""
        self._log_ns.reserve(n)
        for column in self._arrays.values():
            column.expected = n
        self._reserve_extra(n)

    def _reserve_extra(self, n: int) -> None:
        pass

    def add(self, log_ns: int, data: bytes | memoryview) -> None:
        """Decode one message (``log_ns``, raw ``data``) into the columns."""
        if self.error is not None:
            return
        try:
            msg = self._deserialize(data, self.topic.msgtype)
            self._take(msg)
        except Exception as exc:  # noqa: BLE001 - any decoding failure is bad input
            self.error = f"message {self.count} on {self.topic.name} cannot be decoded as {self.topic.msgtype} ({type(exc).__name__}: {short_text(exc)})"
            return
        self._log_ns.items.append(log_ns)
        self.count += 1
        if len(self._log_ns.items) >= BLOCK:
            self._flush()

    def add_run(self, buf: np.ndarray, base: int, stride: int, count: int, size: int, log_ns: np.ndarray) -> None:
        """Decode ``count`` messages of ``size`` bytes at ``base + i * stride`` in ``buf``.

        Runs of ROS 2 messages with one layout become columns at once; a
        message that starts no such run (another layout, encoding or type, a
        malformed message) is decoded alone by :meth:`add`, so a run that
        changes layout midway is split where it changes. Runs shorter than
        :data:`MIN_RUN` do not pay: their messages are decoded alone, and after
        each such run more of the following messages are (1, 3, 7, ... up to
        :data:`MAX_SKIP`) before a layout is tried again.
        """
        fast = self.topic.kind == ROS2 and self.topic.msgtype in cdrcols.FAST_TYPES
        i = 0
        while i < count and self.error is None:
            start = base + i * stride
            first = bytes(buf[start : start + size])
            left = count - i
            lay = None
            tried = False
            if fast and self._skip:
                self._skip -= 1
            elif fast:
                tried = True
                lay = self._layout(first, walk=left > 1)
            todo = min(left, self._window)
            n = cdrcols.matching_rows(buf, start, stride, todo, lay) if lay is not None else 0
            if n == 0 or (n < MIN_RUN and n < left):
                # no layout, or a run too short to pay: its messages alone
                for k in range(max(n, 1)):
                    at = start + k * stride
                    self.add(int(log_ns[i + k]), first if k == 0 else bytes(buf[at : at + size]))
                i += max(n, 1)
                if tried:
                    self._skip = self._backoff - 1
                    self._backoff = min(2 * self._backoff, MAX_SKIP + 1)
                continue
            self._backoff = 1
            self._window = min(self._window * 2, 1 << 20) if n == todo else 256
            assert lay is not None  # n > 0 only with a layout
            self._log_ns.block(np.asarray(log_ns[i : i + n], dtype=np.int64))
            self._columns(buf, start, stride, n, lay)
            self.count += n
            i += n

    @property
    def fields(self) -> tuple[str, ...]:
        """The array fields this sink keeps."""
        return tuple(self._arrays)

    def add_columns(
        self, log_ns: np.ndarray, arrays: Mapping[str, np.ndarray], stamp_ns: np.ndarray | None = None, names: tuple[str, ...] | None = None
    ) -> None:
        """Append ``len(log_ns)`` messages another reader decoded as columns (a vectorised run).

        ``arrays[field]`` is a (messages, width) float64 block for each of
        :attr:`fields` (a missing one: width 0); a JointState sink also takes
        the messages' ``stamp_ns`` and their ``names``. The messages go after
        those added so far, and :meth:`finish` orders and checks them all alike.
        """
        m = len(log_ns)
        if self.error is not None or m == 0:
            return
        self._flush()
        self._log_ns.block(np.asarray(log_ns, dtype=np.int64))
        for name, column in self._arrays.items():
            values = arrays.get(name)
            column.block(np.empty((m, 0)) if values is None else np.asarray(values, dtype=np.float64).reshape(m, -1))
        self._columns_added(m, stamp_ns, names)
        self.count += m

    def _columns_added(self, m: int, stamp_ns: np.ndarray | None, names: tuple[str, ...] | None) -> None:
        pass

    def _layout(self, data: bytes, walk: bool = True) -> cdrcols.Layout | None:
        """Layout of ``data``: the last run's when the structural bytes are the same, else walked and checked.

        ``walk=False`` (a lone message) only tries the last run's layout: a
        new one would cost more than decoding the message by itself.
        """
        last = self._last
        if last is not None and last[0].size == len(data):
            lay, fixed, structure = last
            if np.array_equal(np.frombuffer(data, dtype=np.uint8)[fixed], structure):
                return lay
        if not walk:
            return None
        walked = cdrcols.layout(data, self.topic.msgtype)
        if walked is None or not self._agrees(walked, data):
            return None
        fixed = np.flatnonzero(~walked.varying)
        self._last = (walked, fixed, np.frombuffer(data, dtype=np.uint8)[fixed].copy())
        return walked

    def _agrees(self, lay: cdrcols.Layout, data: bytes) -> bool:
        """Whether ``rosbags`` decodes ``data`` to the values ``lay`` finds (a check per run)."""
        try:
            msg = self._deserialize(data, self.topic.msgtype)
            buf = np.frombuffer(data, dtype=np.uint8)
            for name, (offset, count) in lay.arrays.items():
                ours = cdrcols.column(buf, offset, 0, 1, "<f8", count).reshape(-1) if count else np.empty(0)
                theirs = np.asarray(getattr(msg, name), dtype=np.float64)
                if name in self._arrays and ours.view(np.int64).tolist() != theirs.view(np.int64).tolist():
                    return False
            return self._agrees_extra(lay, msg, buf)
        except Exception:  # noqa: BLE001 - the per-message decoder reports the problem
            return False

    def _agrees_extra(self, lay: cdrcols.Layout, msg: Any, buf: np.ndarray) -> bool:
        return True

    def _columns(self, buf: np.ndarray, start: int, stride: int, n: int, lay: cdrcols.Layout) -> None:
        for name, column in self._arrays.items():
            offset, count = lay.arrays[name]
            if count:  # views of the run, copied once: into the column's reserved array, else into a block of their own
                column.block(cdrcols.column(buf, start + offset, stride, n, "<f8", count, copy=False), owned=False)
            else:
                column.block(np.empty((n, 0)))

    def _take(self, msg: Any) -> None:
        for name, column in self._arrays.items():
            column.append(getattr(msg, name))

    def _flush(self) -> None:
        self._log_ns.flush()
        for column in self._arrays.values():
            column.flush()

    def finish(self) -> Series:
        """Return the columns, sorted by log time (stable)."""
        series = Series(self.topic, self._log_ns.array())
        for name, column in self._arrays.items():
            series.fields[name] = column.columns()
        self._extra(series)
        sort_series(series)
        return series

    def _extra(self, series: Series) -> None:
        pass


class _JointStateSink(_Sink):
    arrays: tuple[str, ...] = ("position", "velocity", "effort")

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        self._stamp = Numbers(np.int64)
        self._name_id = Numbers(np.int32, small=True)
        self._names: dict[tuple[str, ...], int] = {}

    def _take_header(self, msg: Any, names: Any) -> None:
        """Keep the message's ``header.stamp`` and the id of its joint ``names``."""
        stamp = msg.header.stamp
        self._stamp.items.append(int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec))
        self._take_names(names)

    def _take_names(self, names: Any) -> None:
        key = tuple(names)
        nid = self._names.get(key)
        if nid is None:
            nid = self._names[key] = len(self._names)
        self._name_id.items.append(nid)

    def _take(self, msg: Any) -> None:
        self._take_header(msg, msg.name)
        position, velocity, effort = msg.position, msg.velocity, msg.effort
        arrays = self._arrays
        arrays["position"].append(position)
        arrays["velocity"].append(velocity)
        arrays["effort"].append(effort)

    def _flush(self) -> None:
        super()._flush()
        self._stamp.flush()
        self._name_id.flush()

    def _reserve_extra(self, n: int) -> None:
        self._stamp.reserve(n)

    def _agrees_extra(self, lay: cdrcols.Layout, msg: Any, buf: np.ndarray) -> bool:
        stamp = msg.header.stamp
        ours = int(cdrcols.times_ns(buf, lay.times["stamp"], 0, 1)[0])
        return ours == int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec) and tuple(str(x) for x in msg.name) == lay.strings["name"]

    def _columns(self, buf: np.ndarray, start: int, stride: int, n: int, lay: cdrcols.Layout) -> None:
        super()._columns(buf, start, stride, n, lay)
        key = lay.strings["name"]
        nid = self._names.get(key)
        if nid is None:
            nid = self._names[key] = len(self._names)
        self._stamp.block(cdrcols.times_ns(buf, start + lay.times["stamp"], stride, n))
        self._name_id.block(np.full(n, nid, dtype=np.int32))

    def _columns_added(self, m: int, stamp_ns: np.ndarray | None, names: tuple[str, ...] | None) -> None:
        assert stamp_ns is not None and names is not None, "JointState columns need their stamps and names"
        nid = self._names.get(names)
        if nid is None:
            nid = self._names[names] = len(self._names)
        self._stamp.block(np.asarray(stamp_ns, dtype=np.int64))
        self._name_id.block(np.full(m, nid, dtype=np.int32))

    def _extra(self, series: Series) -> None:
        series.stamp_ns = self._stamp.array()
        series.name_id = self._name_id.array()
        series.names = [tuple(str(x) for x in key) for key in self._names]


class _ControllerStateSink(_JointStateSink):
    """ros2_control's controller state: its joint names, and the reference, feedback and output points as columns.

    Decoded per message (no column fast path). A ROS 2 topic takes the first
    layout of :data:`~ilic_cli.io.rosschema.CONTROLLER_LAYOUTS` that decodes
    its first message exactly and keeps it; ``desired``/``actual`` are read
    as ``reference``/``feedback`` (the older fields, or the newer ones left
    empty).
    """

    arrays = (
        "reference.positions",
        "reference.velocities",
        "reference.accelerations",
        "feedback.positions",
        "feedback.velocities",
        "feedback.effort",
        "output.effort",
    )

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        if topic.kind == ROS2:
            self._layouts = [controller_typestore(name).deserialize_cdr for name in CONTROLLER_LAYOUTS]
            self._deserialize = self._any_layout

    def _any_layout(self, data: bytes | memoryview, msgtype: str) -> Any:
        failure: Exception | None = None
        for deserialize in self._layouts:
            try:
                msg = deserialize(data, msgtype)
            except Exception as exc:  # noqa: BLE001 - not this layout
                failure = failure or exc
                continue
            self._layouts = [deserialize]  # one layout per topic
            return msg
        assert failure is not None
        raise failure

    @staticmethod
    def _point(msg: Any, new: str, old: str) -> Any:
        point = getattr(msg, new, None)
        if point is None or (len(point.positions) == 0 and hasattr(msg, old)):
            point = getattr(msg, old)
        return point

    def _take(self, msg: Any) -> None:
        self._take_header(msg, msg.joint_names)
        reference, feedback = self._point(msg, "reference", "desired"), self._point(msg, "feedback", "actual")
        output = getattr(msg, "output", None)
        arrays = self._arrays
        arrays["reference.positions"].append(reference.positions)
        arrays["reference.velocities"].append(reference.velocities)
        arrays["reference.accelerations"].append(reference.accelerations)
        arrays["feedback.positions"].append(feedback.positions)
        arrays["feedback.velocities"].append(feedback.velocities)
        arrays["feedback.effort"].append(feedback.effort)
        arrays["output.effort"].append(output.effort if output is not None else ())


class _TrajectorySink(_JointStateSink):
    """A ``JointTrajectory``'s points, one row each: stamp = ``header.stamp`` (else log time) + ``time_from_start``."""

    arrays = ("positions", "velocities", "accelerations")

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        self._message = Numbers(np.int64)

    def add(self, log_ns: int, data: bytes | memoryview) -> None:
        """Decode one message into a row per point."""
        if self.error is not None:
            return
        try:
            msg = self._deserialize(data, self.topic.msgtype)
            stamp = msg.header.stamp
            start = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec) or log_ns
            for point in msg.points:
                since = point.time_from_start
                self._stamp.items.append(start + int(since.sec) * 1_000_000_000 + int(since.nanosec))
                self._take_names(msg.joint_names)
                for name in self.arrays:
                    self._arrays[name].append(getattr(point, name))
                self._message.items.append(self.count)
                self._log_ns.items.append(log_ns)
        except Exception as exc:  # noqa: BLE001 - any decoding failure is bad input
            self.error = f"message {self.count} on {self.topic.name} cannot be decoded as {self.topic.msgtype} ({type(exc).__name__}: {short_text(exc)})"
            return
        self.count += 1
        if len(self._log_ns.items) >= BLOCK:
            self._flush()

    def _flush(self) -> None:
        super()._flush()
        self._message.flush()

    def _extra(self, series: Series) -> None:
        super()._extra(series)
        series.message_id = self._message.array()


class _PointSink(_Sink):
    arrays = ("positions", "velocities", "accelerations")


class _StringSink(_Sink):
    """Keeps the data of the first message only (later ones are counted, not decoded)."""

    def __init__(self, topic: RawTopic) -> None:
        super().__init__(topic)
        self._text: str | None = None

    def add(self, log_ns: int, data: bytes | memoryview) -> None:
        """Decode the first message; count the others."""
        if self.count == 0 and self.error is None:
            try:
                self._text = str(self._deserialize(data, self.topic.msgtype).data)
            except Exception as exc:  # noqa: BLE001
                self.error = f"message 0 on {self.topic.name} cannot be decoded as {self.topic.msgtype} ({type(exc).__name__}: {short_text(exc)})"
                return
        self._log_ns.items.append(log_ns)
        self.count += 1
        if len(self._log_ns.items) >= BLOCK:
            self._flush()

    def _agrees_extra(self, lay: cdrcols.Layout, msg: Any, buf: np.ndarray) -> bool:
        return str(msg.data) == lay.strings["data"]

    def _columns(self, buf: np.ndarray, start: int, stride: int, n: int, lay: cdrcols.Layout) -> None:
        if self.count == 0:
            self._text = lay.strings["data"]

    def _extra(self, series: Series) -> None:
        series.text = self._text


_SINKS: dict[str, type[_Sink]] = {
    JOINT_STATE: _JointStateSink,
    TRAJECTORY_POINT: _PointSink,
    STRING: _StringSink,
    CONTROLLER_STATE: _ControllerStateSink,
    TRAJECTORY: _TrajectorySink,
}


PER_MESSAGE = frozenset({CONTROLLER_STATE, TRAJECTORY})
"""Types decoded one message at a time only (no column layout): a columnar reader leaves them to a per-message pass."""


class Collector:
    """Streams a container's messages into per-topic columns in one pass.

    Container modules :meth:`declare` every topic (channel, connection) and
    feed the messages of the topics that can matter to the returned sink's
    ``add(log_ns, data)``; :meth:`finish` gives the :class:`Collected` that
    :func:`decode` reads. Only the built-in types of :data:`READ_TYPES` in
    ROS 1 or ROS 2 (CDR) encoding are decoded; memory grows with the decoded
    values (about 60 bytes per JointState message), not with Python objects.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.topics: dict[str, RawTopic] = {}
        self._sinks: dict[str, _Sink | None] = {}

    def declare(self, topic: RawTopic, decode: bool = True) -> _Sink | None:
        """Register ``topic``; return the sink for its messages, or None when they are not read.

        ``decode=False`` registers the topic without a sink: another pass
        decodes it (:meth:`Collected.adopt`).
        """
        known = self.topics.get(topic.name)
        if known is not None and known != topic:
            raise LogError(self.path, f"topic {topic.name} appears with two message types")
        self.topics[topic.name] = topic
        if not decode:
            self._sinks.setdefault(topic.name, None)
        elif topic.name not in self._sinks:
            sink_type = _SINKS.get(topic.msgtype)
            self._sinks[topic.name] = sink_type(topic) if sink_type is not None and topic.kind in (ROS1, ROS2) else None
        return self._sinks[topic.name]

    def finish(self) -> Collected:
        """Return the collected columns."""
        data = {name: sink for name, sink in self._sinks.items() if sink is not None}
        self._sinks = {}
        return Collected(self.path, dict(self.topics), data)
