"""Topics and their decoded columns: what a container's one pass gives (:class:`Collected`, from :meth:`ilic_cli.io.roscollect.Collector.finish`).

:func:`ilic_cli.io.rosdecode.decode` asks it for the columns of the topics it
selects; a topic's first decoding error is raised only when its columns are
asked for, so an unreadable topic that is not used does not fail the read.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ilic_cli.errors import LogError
from ilic_cli.io.roscolumns import Series
from ilic_cli.io.rosschema import ROS1, ROS2, RawTopic


class Collected:
    """Topics and their decoded columns (from :meth:`Collector.finish`)."""

    def __init__(self, path: Path, topics: dict[str, RawTopic], sinks: dict[str, Any]) -> None:
        self.path = path
        self.topics = topics
        self._sinks = sinks
        self._series: dict[str, Series] = {}

    def adopt(self, other: Collected) -> None:
        """Take the decoded topics of ``other`` (a second pass over the same file) that have none here."""
        for name, sink in other._sinks.items():
            self._sinks.setdefault(name, sink)

    def series(self, name: str) -> Series:
        """The columns of topic ``name``; raises the topic's first decoding error."""
        if name in self._series:
            return self._series[name]
        topic = self.topics[name]
        if topic.kind not in (ROS1, ROS2):
            raise LogError(self.path, f"topic {topic.name} uses message encoding '{topic.kind}'; only ROS 2 CDR and ROS 1 messages can be read")
        sink = self._sinks.get(name)
        if sink is None:
            raise LogError(self.path, f"topic {topic.name} has unsupported message type {topic.msgtype}")
        if sink.error is not None:
            raise LogError(self.path, sink.error)
        series = self._series[name] = sink.finish()
        del self._sinks[name]
        return series

    def release(self, name: str) -> None:
        """Free the columns of topic ``name``."""
        self._series.pop(name, None)
        self._sinks.pop(name, None)
