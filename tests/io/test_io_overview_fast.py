"""``ilic info``'s topic overview of a ROS 1 bag from its index records, against ``rosbags``' reader (issue 33).

``rosbags`` builds an object per message when it opens a bag; the overview
reads the counts, the time range and each topic's first message from the
chunk-info and index-data records instead. Both must list the same topics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import overview, ros1fast, rosschema, write_log


def _foreign_bag(path: Path, compression: str | None) -> None:
    """Two JointState topics with different joints, written out of time order, in small (optionally compressed) chunks."""
    from rosbags.rosbag1 import Writer

    ts = rosschema.typestore("ros1")
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    writer = Writer(path)
    if compression:
        writer.set_compression(getattr(Writer.CompressionFormat, compression))
    writer.chunk_threshold = 2000
    with writer:
        left = writer.add_connection("/left/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        right = writer.add_connection("/right/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for i in range(200):
            for conn, names, shift in ((right, ["r1"], 7), (left, ["l1", "l2"], 0)):
                ns = 3 * 10**9 + i * 10**7 + (shift if i % 5 else -(10**8))  # every 5th message earlier than the ones before
                msg = js(
                    header=header(seq=i, stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                    name=names,
                    position=np.full(len(names), float(i)),
                    velocity=np.array([], dtype=np.float64),
                    effort=np.zeros(len(names)),
                )
                writer.write(conn, ns, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/JointState")))


@pytest.mark.parametrize("compression", [None, "LZ4", "BZ2"])
def test_foreign_bag_overview_is_rosbags(tmp_path: Path, compression: str | None) -> None:
    path = tmp_path / "arm.bag"
    _foreign_bag(path, compression)
    fast = overview._bag1(path)
    assert len(ros1fast.summary(path).first) == 2  # read from the index, not through rosbags
    assert fast == overview._bag(path)
    assert [(t.topic, t.count, t.joints) for t in fast] == [("/left/joint_states", 200, ("l1", "l2")), ("/right/joint_states", 200, ("r1",))]


def test_own_bag_overview_is_rosbags(tmp_path: Path) -> None:
    from tests.conftest import make_synthetic_log

    path = write_log(make_synthetic_log(samples=12_000), tmp_path / "own.bag")  # several 1 MiB chunks
    fast = overview._bag1(path)
    assert fast == overview._bag(path)
    assert {t.topic: t.count for t in fast}["/joint_states"] == 12_000


def test_unusual_bag_overview_falls_back_to_rosbags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A bag the index reader refuses (here: a planted refusal) is listed by ``rosbags``, the same."""
    path = tmp_path / "arm.bag"
    _foreign_bag(path, None)
    expected = overview._bag(path)

    def refuse(path: Path) -> ros1fast.BagSummary:
        raise ros1fast.Fallback

    monkeypatch.setattr(ros1fast, "summary", refuse)
    assert overview._bag1(path) == expected


def _foreign_mcap(path: Path, compression: str) -> None:
    """Two JointState topics (the right one on two channels) with different joints, out of time order and with ties, in small chunks."""
    from mcap.writer import CompressionType, Writer

    ts = rosschema.typestore("ros2")
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    with open(path, "wb") as stream:
        writer = Writer(stream, chunk_size=1500, compression=CompressionType[compression.upper() or "NONE"])
        writer.start()
        schema = writer.register_schema("sensor_msgs/msg/JointState", "ros2msg", b"")
        channels = [writer.register_channel(topic, "cdr", schema) for topic in ("/left/joint_states", "/right/joint_states", "/right/joint_states")]
        for i in range(120):
            for k, (channel, names) in enumerate(zip(channels, (["l1", "l2"], ["r1"], ["r2"]))):
                ns = 3 * 10**9 + i * 10**7 + (0 if i % 5 else -(10**8)) + (0 if i % 3 else k)  # earlier every 5th; ties every 3rd except by channel
                msg = js(
                    header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                    name=names,
                    position=np.full(len(names), float(i)),
                    velocity=np.array([], dtype=np.float64),
                    effort=np.zeros(len(names)),
                )
                writer.add_message(channel, log_time=ns, data=bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState")), publish_time=ns)
        writer.finish()


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_mcap_first_messages_are_the_readers(tmp_path: Path, compression: str) -> None:
    """The first message of a topic from the chunk and message indexes is the one ``mcap``'s reader yields first."""
    from mcap.reader import make_reader

    path = tmp_path / "arm.mcap"
    _foreign_mcap(path, compression)
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) > 10
        for topic in ("/left/joint_states", "/right/joint_states"):
            ids = {cid for cid, c in summary.channels.items() if c.topic == topic}
            _, _, first = next(iter(reader.iter_messages(topics=[topic])))
            assert overview._first_data(stream, summary, ids, path) == bytes(first.data)
    assert [(t.topic, t.count, t.joints) for t in overview._mcap(path)] == [
        ("/left/joint_states", 120, ("l1", "l2")),
        ("/right/joint_states", 120, ("r1",)),
        ("/right/joint_states", 120, ("r1",)),
    ]


def test_mcap_overview_without_indexes_is_the_readers_walk(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """When the indexes do not say (here: a planted refusal), the reader's walk gives the same overview."""
    path = tmp_path / "arm.mcap"
    _foreign_mcap(path, "zstd")
    fast = overview._mcap(path)
    monkeypatch.setattr(overview, "_first_data", lambda *args: None)
    assert overview._mcap(path) == fast


def _foreign_ros2_mcap_bag(path: Path) -> None:
    """A ROS 2 bag of MCAP storage by ``rosbags``' own writer: two JointState topics, the first message in time written late."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = rosschema.typestore("ros2")
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection(topic, "sensor_msgs/msg/JointState", typestore=ts) for topic in ("/left/joint_states", "/right/joint_states")]
        for i in range(12000):  # several of rosbags' 1 MiB chunks
            for conn, names in zip(conns, (["l1", "l2"], [f"r{i % 7}"])):
                ns = 2 * 10**9 if i == 10000 else 3 * 10**9 + i * 10**6  # the first in time in a later chunk
                msg = js(
                    header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                    name=names,
                    position=np.full(len(names), float(i)),
                    velocity=np.array([], dtype=np.float64),
                    effort=np.zeros(len(names)),
                )
                writer.write(conn, ns, bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState")))


def test_ros2_mcap_bag_first_messages_are_rosbags(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The first messages of a ROS 2 bag's MCAP storage from its indexes give ``rosbags``' overview."""
    path = tmp_path / "bag"
    _foreign_ros2_mcap_bag(path)
    firsts = overview._mcap_storage_firsts(path)
    assert firsts is not None and firsts("/right/joint_states") is not None  # read from the indexes
    with open(next(path.glob("*.mcap")), "rb") as stream:
        from mcap.reader import make_reader

        summary = make_reader(stream).get_summary()
        assert summary is not None and len(summary.chunk_indexes) > 2
    fast = overview._bag(path)
    monkeypatch.setattr(overview, "_mcap_storage_firsts", lambda path: None)
    assert overview._bag(path) == fast
    right = ("/right/joint_states", 12000, ("r4",))  # message 10000
    assert [(t.topic, t.count, t.joints) for t in fast] == [("/left/joint_states", 12000, ("l1", "l2")), right]
