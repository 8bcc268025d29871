"""The vectorised MCAP and ROS 2 bag paths against the per-message ones, bit for bit.

Files come from our writers (bulk and per-message) and from independent
writers (``mcap-ros2-support``'s ROS 2 writer, ``rosbags``' ROS 2 bag writer
with messages built here); each is read with ``fast=True`` and ``fast=False``
and the columns must have the same bits, the metadata and units be equal.
Files whose message layout changes midway (a joint name, a second joint,
frame ids of varying length) exercise the per-message fallback of the fast
readers.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ilic_cli.errors import ChoiceError
from ilic_cli.io import Selection, WriteOptions, read_log, rosbulk, rosschema, write_log
from ilic_cli.runlog import RunLog
from tests.conftest import make_synthetic_log

N = 3000
T0_NS = 1_700_000_000_000_000_000
JOINT_STATE = "sensor_msgs/msg/JointState"
POINT = "trajectory_msgs/msg/JointTrajectoryPoint"
STRING = "std_msgs/msg/String"


def assert_same(a: RunLog, b: RunLog) -> None:
    """Same channels in the same order with the same bits, same units and metadata."""
    assert list(a.channels) == list(b.channels)
    for name in a.channels:
        x, y = a.channels[name], b.channels[name]
        assert x.dtype == y.dtype == np.float64, name
        assert np.array_equal(x.view(np.uint64), y.view(np.uint64)), name
    assert a.units == b.units
    assert a.meta == b.meta


def read_both(path: Path, selection: Selection | None = None) -> RunLog:
    """Read ``path`` on both paths; check they agree; return the fast result."""
    fast = read_log(path, selection=selection, fast=True)
    slow = read_log(path, selection=selection, fast=False)
    assert_same(fast, slow)
    return fast


def assert_log_equals_source(back: RunLog, log: RunLog) -> None:
    assert list(back.channels) == list(log.channels)
    for name, values in log.channels.items():
        assert np.array_equal(back.channels[name].view(np.uint64), values.view(np.uint64)), name
    assert back.units == log.units
    assert {k: v for k, v in back.meta.items() if k != "source"} == log.meta


# -- our writers ------------------------------------------------------------------
OURS = [
    ("mcap", "log.mcap", {}),
    ("rosbag2-sqlite3", "bag", {"storage": "sqlite3"}),
    ("rosbag2-mcap", "bag", {"storage": "mcap"}),
]


@pytest.mark.parametrize(("fmt", "name", "extra"), OURS, ids=[o[0] for o in OURS])
@pytest.mark.parametrize("fast_writer", [True, False], ids=["bulk-writer", "per-message-writer"])
def test_our_files_read_identically(tmp_path: Path, fmt: str, name: str, extra: dict[str, Any], fast_writer: bool) -> None:
    log = make_synthetic_log(samples=N)
    path = write_log(log, tmp_path / name, options=WriteOptions(fast=fast_writer, **extra))
    assert_log_equals_source(read_both(path), log)


def test_minimal_log_without_reference_or_velocity(tmp_path: Path) -> None:
    t = np.linspace(-0.5, 0.5, 1001)
    log = RunLog({"t": t, "q": t**2, "tau": np.cos(t)}, {"q": "rad"}, {"joint": "elbow"})
    for name, extra in (("m.mcap", {}), ("s_bag", {"storage": "sqlite3"}), ("m_bag", {"storage": "mcap"})):
        assert_log_equals_source(read_both(write_log(log, tmp_path / name, options=WriteOptions(**extra))), log)


@pytest.mark.parametrize(("name", "extra"), [("log.mcap", {}), ("bag", {"storage": "sqlite3"})], ids=["mcap", "rosbag2-sqlite3"])
def test_bulk_writer_gives_the_per_message_writers_bytes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, name: str, extra: dict[str, Any]) -> None:
    """Same log -> the same files from the bulk and the per-message writer (several chunks).

    The sqlite3 storage through its SQL path: written as B-tree pages, its rows are the same, not its bytes (tests/io/test_sqlitewrite.py).
    """
    monkeypatch.setattr(rosbulk.BulkSqlite3Storage, "pages", False)
    log = make_synthetic_log(samples=12000)
    (tmp_path / "bulk").mkdir()
    (tmp_path / "each").mkdir()
    bulk = write_log(log, tmp_path / "bulk" / name, options=WriteOptions(fast=True, **extra))
    each = write_log(log, tmp_path / "each" / name, options=WriteOptions(fast=False, **extra))
    files = sorted(p.name for p in bulk.iterdir()) if bulk.is_dir() else [""]
    assert files == (sorted(p.name for p in each.iterdir()) if each.is_dir() else [""])
    for file in files:
        assert (bulk / file).read_bytes() == (each / file).read_bytes(), file


def test_bulk_mcap_storage_bag_is_standard(tmp_path: Path) -> None:
    """rosbags reads the bulk-written MCAP storage; mcap-ros2-support decodes it; the summary is complete."""
    import mcap_ros2.decoder as decoder_module
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    log = make_synthetic_log(samples=N)
    bag = write_log(log, tmp_path / "bag", options=WriteOptions(storage="mcap"))
    with Reader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        ts = rosschema.typestore("ros2")
        states = [ts.deserialize_cdr(data, JOINT_STATE) for conn, _, data in reader.messages() if conn.topic == "/joint_states"]
    assert counts == {"/ilic/metadata": 1, "/joint_states": N, "/joint_reference": N, "/ilic/extras": N}
    assert np.array_equal([s.position[0] for s in states], log.channels["q"])
    with open(bag / "bag.mcap", "rb") as stream:
        reader = make_reader(stream, decoder_factories=[decoder_module.DecoderFactory()], validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and len(summary.chunk_indexes) >= 1
        assert summary.channels[1].metadata.keys() == {"offered_qos_profiles"}
        efforts = [m.decoded_message.effort[0] for m in reader.iter_decoded_messages(topics=["/joint_states"])]
        assert [m.name for m in reader.iter_metadata()] == ["rosbag2"]
    assert np.array_equal(efforts, log.channels["tau"])


# -- independent writers ----------------------------------------------------------
def _dict_messages(log: RunLog, joint: str) -> list[tuple[str, int, dict[str, Any]]]:
    """The ilic topics of ``log`` as plain dicts (for mcap-ros2-support), in log-time order."""
    from ilic_cli.io.rosencode import encode

    _, messages = encode(log, joint)
    meta_text = rosschema.typestore("ros2").deserialize_cdr(next(messages)[2], STRING).data
    ns = (np.rint(log.t * 1e9)).astype(np.int64) + T0_NS
    ch = log.channels
    extras = [name for name in ch if name not in {"t", "q", "qd", "tau", "q_ref", "qd_ref", "qdd_ref"}]
    out: list[tuple[str, int, dict[str, Any]]] = [("/ilic/metadata", int(ns[0]), {"data": meta_text})]
    for i, stamp in enumerate(ns.tolist()):
        head = {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": ""}
        out.append(("/joint_states", stamp, {"header": head, "name": [joint], "position": [ch["q"][i]], "velocity": [ch["qd"][i]], "effort": [ch["tau"][i]]}))
        since = stamp - int(ns[0])
        out.append(
            (
                "/joint_reference",
                stamp,
                {
                    "positions": [ch["q_ref"][i]],
                    "velocities": [ch["qd_ref"][i]],
                    "accelerations": [ch["qdd_ref"][i]],
                    "effort": [],
                    "time_from_start": {"sec": since // 10**9, "nanosec": since % 10**9},
                },
            )
        )
        out.append(
            (
                "/ilic/extras",
                stamp,
                {"header": head, "name": ["t_s", *extras], "position": [log.t[i], *(ch[e][i] for e in extras)], "velocity": [], "effort": []},
            )
        )
    return out


def write_mcap_ros2(path: Path, messages: list[tuple[str, int, dict[str, Any]]], chunk_size: int) -> None:
    """Write messages with mcap-ros2-support's writer (its own CDR encoder)."""
    from mcap_ros2.writer import Writer

    types = {"/ilic/metadata": STRING, "/joint_reference": POINT}
    with open(path, "wb") as stream:
        writer = Writer(stream, chunk_size=chunk_size)
        schemas = {}
        for msgtype in (STRING, JOINT_STATE, POINT):
            schemas[msgtype] = writer.register_msgdef(msgtype, rosschema.message_definition(msgtype)[0])
        for seq, (topic, stamp, message) in enumerate(messages):
            writer.write_message(topic, schemas[types.get(topic, JOINT_STATE)], message, log_time=stamp, publish_time=stamp, sequence=seq)
        writer.finish()


@pytest.mark.parametrize("chunk_size", [1 << 20, 3000], ids=["default-chunks", "small-chunks"])
def test_mcap_from_mcap_ros2_support(tmp_path: Path, chunk_size: int) -> None:
    """Our topics written by another encoder; small chunks cut samples and runs at chunk ends."""
    log = make_synthetic_log(samples=N)
    path = tmp_path / "other.mcap"
    write_mcap_ros2(path, _dict_messages(log, "axis"), chunk_size)
    back = read_both(path)
    assert_log_equals_source(back, log)


def _foreign_states(joints_of: Any, n: int, frame_of: Any = lambda i: "base") -> list[tuple[str, int, dict[str, Any]]]:
    out = []
    for i in range(n):
        ns = T0_NS + i * 2_000_000
        joints = joints_of(i)
        values = [10.0 * k + i * 0.001 for k in range(len(joints))]
        out.append(
            (
                "/robot/joint_states",
                ns,
                {
                    "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": frame_of(i)},
                    "name": list(joints),
                    "position": values,
                    "velocity": [v * 0.5 for v in values],
                    "effort": [v * 2.0 for v in values],
                },
            )
        )
    return out


def test_multi_joint_mcap_from_mcap_ros2_support(tmp_path: Path) -> None:
    path = tmp_path / "arm.mcap"
    write_mcap_ros2(path, _foreign_states(lambda i: ["shoulder", "elbow", "wrist"], N), 5000)
    log = read_both(path, Selection(joint="elbow"))
    i = np.arange(N)
    assert np.array_equal(log.channels["q"], 10.0 + i * 0.001)
    assert np.array_equal(log.channels["tau"], (10.0 + i * 0.001) * 2.0)
    assert log.meta["joint"] == "elbow" and log.meta["start_time_ns"] == T0_NS


@pytest.mark.parametrize(
    ("what", "joints_of", "frame_of", "joint"),
    [
        ("joint renamed midway", lambda i: ["a"] if i < 1700 else ["b"], lambda i: "base", None),
        ("second joint appears", lambda i: ["a"] if i < 1300 else ["a", "b"], lambda i: "base", "a"),
        ("frame ids of varying length", lambda i: ["a"], lambda i: "x" * (i % 7), None),
    ],
    ids=["renamed", "second-joint", "frame-ids"],
)
def test_layout_change_midway_falls_back(tmp_path: Path, what: str, joints_of: Any, frame_of: Any, joint: str | None) -> None:
    path = tmp_path / "change.mcap"
    write_mcap_ros2(path, _foreign_states(joints_of, N, frame_of), 1 << 20)
    if what == "joint renamed midway":
        # two joints over the file: a choice is needed, and each gives its own part
        with pytest.raises(ChoiceError, match="2 joints") as info:
            read_log(path)
        assert info.value.choice == "joint"
        for name, part in (("a", slice(0, 1700)), ("b", slice(1700, N))):
            log = read_both(path, Selection(joint=name))
            assert np.array_equal(log.channels["q"], (np.arange(N) * 0.001)[part])
        return
    log = read_both(path, Selection(joint=joint))
    assert len(log) == N
    assert np.array_equal(log.channels["q"], np.arange(N) * 0.001)
    assert np.array_equal(log.channels["qd"], np.arange(N) * 0.001 * 0.5)


def _write_rosbags_bag(path: Path, storage: str, log: RunLog) -> None:
    """Our topics, messages built and serialised by rosbags, written by rosbags' ROS 2 writer."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = rosschema.typestore("ros2")
    types = {"/ilic/metadata": STRING, "/joint_states": JOINT_STATE, "/joint_reference": POINT, "/ilic/extras": JOINT_STATE}
    time_t, header_t, duration_t = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Duration"]

    def build(topic: str, message: dict[str, Any]) -> Any:
        if topic == "/ilic/metadata":
            return ts.types[STRING](data=message["data"])
        if topic == "/joint_reference":
            tfs = message["time_from_start"]
            arrays = {k: np.array(message[k], dtype=np.float64) for k in ("positions", "velocities", "accelerations", "effort")}
            return ts.types[POINT](**arrays, time_from_start=duration_t(sec=tfs["sec"], nanosec=tfs["nanosec"]))
        head = message["header"]
        return ts.types[JOINT_STATE](
            header=header_t(stamp=time_t(**head["stamp"]), frame_id=head["frame_id"]),
            name=message["name"],
            **{k: np.array(message[k], dtype=np.float64) for k in ("position", "velocity", "effort")},
        )

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=plugin) as writer:
        connections = {topic: writer.add_connection(topic, msgtype, typestore=ts) for topic, msgtype in types.items()}
        for topic, stamp, message in _dict_messages(log, "axis"):
            writer.write(connections[topic], stamp, bytes(ts.serialize_cdr(build(topic, message), types[topic])))


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_bag_from_rosbags_writer(tmp_path: Path, storage: str) -> None:
    log = make_synthetic_log(samples=N)
    path = tmp_path / "bag"
    _write_rosbags_bag(path, storage, log)
    assert_log_equals_source(read_both(path), log)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_foreign_bag_with_layout_change(tmp_path: Path, storage: str) -> None:
    """A bag whose JointState gains a joint midway (rosbags writer): fast and per-message agree."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = rosschema.typestore("ros2")
    js, header_t, time_t = ts.types[JOINT_STATE], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    path = tmp_path / "bag"
    with Writer(path, version=Writer.VERSION_LATEST, storage_plugin=plugin) as writer:
        conn = writer.add_connection("/joint_states", JOINT_STATE, typestore=ts)
        for topic, stamp, m in _foreign_states(lambda i: ["a"] if i < 900 else ["a", "b"], N, lambda i: "base" if i % 500 else "odom"):
            head = m["header"]
            msg = js(
                header=header_t(stamp=time_t(**head["stamp"]), frame_id=head["frame_id"]),
                name=m["name"],
                **{k: np.array(m[k], dtype=np.float64) for k in ("position", "velocity", "effort")},
            )
            writer.write(conn, stamp, bytes(ts.serialize_cdr(msg, JOINT_STATE)))
    log = read_both(path, Selection(joint="a"))
    assert np.array_equal(log.channels["q"], np.arange(N) * 0.001)


def test_hand_over_between_paths_keeps_order(tmp_path: Path) -> None:
    """Runs and single messages of one topic interleave (layout flips often) and keep their order."""
    path = tmp_path / "flip.mcap"
    write_mcap_ros2(path, _foreign_states(lambda i: ["a"], N, lambda i: "x" if (i // 37) % 2 else ""), 4096)
    log = read_both(path)
    assert np.array_equal(log.channels["q"], np.arange(N) * 0.001)


def _singles(path: Path, monkeypatch: pytest.MonkeyPatch, selection: Selection | None = None) -> int:
    """Messages the fast read decoded one by one (not as part of a run)."""
    from ilic_cli.io import roscollect

    calls = []
    for cls in (roscollect._Sink, roscollect._StringSink):
        original = cls.add
        monkeypatch.setattr(cls, "add", lambda self, log_ns, data, _o=original: (calls.append(1), _o(self, log_ns, data))[1])
    read_log(path, selection=selection)
    monkeypatch.undo()
    return len(calls)


def test_fast_path_takes_runs_and_falls_back_only_where_layout_changes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    log = make_synthetic_log(samples=N)
    for name, extra in (("a.mcap", {}), ("s_bag", {"storage": "sqlite3"}), ("m_bag", {"storage": "mcap"})):
        # at most the lone /ilic/metadata message is decoded by itself
        assert _singles(write_log(log, tmp_path / name, options=WriteOptions(**extra)), monkeypatch) <= 1, name
    other = tmp_path / "other.mcap"
    write_mcap_ros2(other, _dict_messages(log, "axis"), 1 << 20)
    assert _singles(other, monkeypatch) <= 10  # same layout from another encoder: singles only at the end of a chunk
    write_mcap_ros2(other, _dict_messages(log, "axis"), 3000)  # about 7 samples per chunk
    assert _singles(other, monkeypatch) < 3 * N // 10  # only the messages at chunk ends
    flips = tmp_path / "flip.mcap"
    write_mcap_ros2(flips, _foreign_states(lambda i: ["a"] if i < 1000 else ["a", "b"], N), 1 << 20)
    assert _singles(flips, monkeypatch, Selection(joint="a")) <= 10  # two layouts, each decoded as runs
    varying = tmp_path / "varying.mcap"
    write_mcap_ros2(varying, _foreign_states(lambda i: ["a"], N, lambda i: "x" * (i % 7)), 1 << 20)
    assert _singles(varying, monkeypatch) > N // 4  # runs too short to pay (3 of 7 messages): one by one


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_bulk_bag_writer_is_deterministic(tmp_path: Path, storage: str) -> None:
    log = make_synthetic_log(samples=N)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first = write_log(log, tmp_path / "a" / "bag", options=WriteOptions(storage=storage))
    second = write_log(log, tmp_path / "b" / "bag", options=WriteOptions(storage=storage))
    names = sorted(p.name for p in first.iterdir())
    assert names == sorted(p.name for p in second.iterdir()) and len(names) == 2
    for name in names:
        assert (first / name).read_bytes() == (second / name).read_bytes(), name


@pytest.mark.parametrize("hint", [0, 5, 40, 1000])
def test_column_size_hints_are_only_hints(hint: int) -> None:
    """A wrong message count in a summary neither loses nor invents values."""
    from ilic_cli.io.roscolumns import Blocks

    parts = [np.arange(k, k + 7, dtype=np.int64) for k in range(0, 70, 7)]
    blocks = Blocks()
    blocks.reserve(hint, np.int64)
    for part in parts:
        blocks.add(part)
    assert np.array_equal(blocks.concat(np.int64), np.arange(70))
