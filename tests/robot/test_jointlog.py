"""n-joint logs: the typed value, the wide CSV and ROS 2 bags (sqlite3, MCAP) round trip losslessly; joints are read by name."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ilic_cli.errors import LogError
from ilic_cli.io import jointlogs
from ilic_cli.io.jointros import read_ros
from ilic_cli.jointlog import JointLog

N = 300


def _log(reference: bool = True) -> JointLog:
    rng = np.random.default_rng(7)
    refs = {r: rng.standard_normal((3, N)) for r in ("q_ref", "qd_ref", "qdd_ref")} if reference else {}
    return JointLog(
        t=np.arange(N) / 1000.0 + 12.5,
        joints=("a", "ref_b", "c"),
        kinds=("revolute", "prismatic", "revolute"),
        q=rng.standard_normal((3, N)) * 1e3,
        tau=rng.standard_normal((3, N)) / 7.0,
        meta={"controller": {"kind": "pd", "kp": 3.5}},
        **refs,
    )


@pytest.mark.parametrize("name", ["log.csv", "log.mcap", "bag"])
def test_round_trip_is_lossless(tmp_path: Path, name: str) -> None:
    log = _log()
    jointlogs.write(log, tmp_path / name)
    back = jointlogs.read(tmp_path / name)
    assert back.joints == log.joints and back.kinds == log.kinds
    for k in ("q", "tau", "q_ref", "qd_ref", "qdd_ref"):
        assert np.array_equal(getattr(back, k), getattr(log, k)), k
    if name.endswith(".csv"):
        assert np.array_equal(back.t, log.t)  # repr-exact floats
    else:
        assert np.max(np.abs(back.t - log.t)) < 1e-9  # nanosecond stamps
    assert back.controller is not None and back.controller.kind == "pd" and back.controller.kp == 3.5
    assert back.provenance.source == str(tmp_path / name)
    if name == "bag":
        assert next((tmp_path / name).glob("*.db3")).is_file()


def test_csv_without_reference_and_selection(tmp_path: Path) -> None:
    log = _log(reference=False)
    jointlogs.write(log, tmp_path / "x.csv")
    back = jointlogs.read(tmp_path / "x.csv", joints=["c", "a"])
    assert back.joints == ("c", "a") and not back.has_reference
    assert np.array_equal(back.q, log.q[[2, 0]]) and np.array_equal(back.tau, log.tau[[2, 0]])
    with pytest.raises(LogError, match=r"no joint zz in the log \(it has a, ref_b, c\)"):
        jointlogs.read(tmp_path / "x.csv", joints=["zz"])


def test_csv_without_effort_is_refused(tmp_path: Path) -> None:
    (tmp_path / "x.csv").write_text("t,q_a,q_b,tau_a\n0,1,2,3\n0.001,1,2,3\n")
    with pytest.raises(LogError, match="no tau_<joint> column for b"):
        jointlogs.read(tmp_path / "x.csv")


FOREIGN_JOINTS = ["gripper", "elbow", "base_yaw", "shoulder"]
"""The joints of another writer's bag: more than arm2 moves, in another order."""


def foreign_states(ts: Any, ros1: bool = False) -> tuple[list[tuple[int, Any]], np.ndarray, np.ndarray]:
    """50 JointState messages of :data:`FOREIGN_JOINTS` at 500 Hz in ``ts``'s types (``ros1``: with a header ``seq``), and their positions and efforts."""
    State, Header, Time = ts.types["sensor_msgs/msg/JointState"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(3)
    pos, eff = rng.standard_normal((50, 4)), rng.standard_normal((50, 4))
    messages = []
    for k in range(50):
        ns = 1_000_000_000 + k * 2_000_000
        stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
        header = Header(seq=k, stamp=stamp, frame_id="") if ros1 else Header(stamp=stamp, frame_id="")
        messages.append((ns, State(header=header, name=FOREIGN_JOINTS, position=pos[k], velocity=pos[k], effort=eff[k])))
    return messages, pos, eff


def test_bag_by_rosbags_with_more_joints_than_the_urdf_is_read_by_name(tmp_path: Path) -> None:
    """Issue 30's Done-when: a bag written by rosbags' writer, 4 joints in another order, read for arm2's shoulder and elbow."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    messages, pos, eff = foreign_states(ts)
    for storage in (StoragePlugin.SQLITE3, StoragePlugin.MCAP):
        path = tmp_path / storage.name
        with Writer(path, version=9, storage_plugin=storage) as writer:
            conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
            for ns, msg in messages:
                writer.write(conn, ns, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
        log = jointlogs.read(path, joints=["shoulder", "elbow"])
        assert log.joints == ("shoulder", "elbow") and log.kinds == ("revolute", "revolute")
        assert np.array_equal(log.q, pos[:, [3, 1]].T) and np.array_equal(log.tau, eff[:, [3, 1]].T)
        assert log.fs_hz == pytest.approx(500.0) and not log.has_reference
        with pytest.raises(LogError, match=r"no joint wrist in /joint_states \(it has gripper, elbow, base_yaw, shoulder\)"):
            jointlogs.read(path, joints=["shoulder", "wrist"])


def test_bad_logs_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="no such file"):
        jointlogs.read(tmp_path / "none.csv")
    (tmp_path / "x.txt").write_text("t\n")
    with pytest.raises(LogError, match="not an n-joint log"):
        jointlogs.read(tmp_path / "x.txt")
    with pytest.raises(LogError, match="shape"):
        JointLog(t=np.arange(3.0), joints=("a",), kinds=("revolute",), q=np.zeros((1, 2)), tau=np.zeros((1, 3)))
    with pytest.raises(LogError, match="joint types"):
        JointLog(t=np.arange(3.0), joints=("a",), kinds=("spherical",), q=np.zeros((1, 3)), tau=np.zeros((1, 3)))


def test_an_arms_sample_rate_is_the_time_bases_one_definition() -> None:
    """A fixed-rate loop whose stamps jitter (steps 0.8, 0.8, 1.4 ms): the nominal rate is 1 kHz (the mean step), as
    :func:`ilic_cli.timebase.nominal_rate_hz` gives a one-joint log; a median period would say 1250 Hz."""
    from ilic_cli.timebase import nominal_rate_hz

    steps = np.tile([0.8e-3, 0.8e-3, 1.4e-3], 400)
    t = np.concatenate([[0.0], np.cumsum(steps)])
    log = JointLog(t=t, joints=("a",), kinds=("revolute",), q=np.zeros((1, len(t))), tau=np.zeros((1, len(t))))
    assert log.fs_hz == nominal_rate_hz(t) == 1000.0


@pytest.mark.parametrize("reference", [True, False])
def test_mcap_file_holds_rosbags_messages_and_indexes_them(tmp_path: Path, reference: bool) -> None:
    """write_mcap lays the samples out by numpy: every message byte for byte as rosbags' writer's, over several chunks, each indexed."""
    import struct

    from mcap.reader import make_reader
    from mcap.records import Chunk, MessageIndex
    from mcap.stream_reader import StreamReader

    log = _log(reference)
    jointlogs.write_mcap(log, tmp_path / "new.mcap", chunk_bytes=10_000)
    jointlogs.write_bag(log, tmp_path / "bag", "mcap")

    def messages(path: Path) -> tuple[list[tuple[str, int, int, bytes]], object]:
        with path.open("rb") as f:
            reader = make_reader(f)
            found = [(c.topic, m.log_time, m.publish_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=False)]
            return found, reader.get_summary()

    ours, summary = messages(tmp_path / "new.mcap")
    theirs, their_summary = messages(next((tmp_path / "bag").glob("*.mcap")))
    assert ours == theirs and len(ours) == N * (2 if reference else 1) + 1
    assert summary.statistics.chunk_count > 4 and summary.statistics.channel_message_counts == their_summary.statistics.channel_message_counts
    assert [(s.name, s.data) for s in summary.schemas.values()] == [(s.name, s.data) for s in their_summary.schemas.values()]
    indexed, chunk = 0, None
    with (tmp_path / "new.mcap").open("rb") as f:
        for record in StreamReader(f, emit_chunks=True, validate_crcs=True).records:
            chunk = record if isinstance(record, Chunk) else chunk
            if isinstance(record, MessageIndex):
                assert chunk is not None
                for ns, offset in record.records:
                    assert struct.unpack_from("<BQHIQ", chunk.data, offset)[::2] == (0x05, record.channel_id, ns)
                    indexed += 1
    assert indexed == len(ours)
    # read back as columns (its own layout): the per-message reader's log, bit for bit; any other byte layout is left to that reader
    fast, slow = jointlogs.read_own_mcap(tmp_path / "new.mcap"), read_ros(tmp_path / "new.mcap")
    assert fast is not None and fast.joints == slow.joints and fast.kinds == slow.kinds and fast.meta == slow.meta
    for name in ("t", "q", "tau", "q_ref", "qd_ref", "qdd_ref"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert (a is None and b is None) if not reference and name.endswith("ref") else np.array_equal(a, b), name
    data = bytearray((tmp_path / "new.mcap").read_bytes())
    at = data.rindex(b"ref_b")  # a joint's name in the last sample's records: no longer the layout the names give
    data[at + 4] = ord("B")
    (tmp_path / "other.mcap").write_bytes(bytes(data))
    assert jointlogs.read_own_mcap(tmp_path / "other.mcap") is None and jointlogs.read_own_mcap(next((tmp_path / "bag").glob("*.mcap"))) is None
    (tmp_path / "cut.mcap").write_bytes(bytes(data[: len(data) // 2]))  # damaged: the per-message reader's one-line error
    assert jointlogs.read_own_mcap(tmp_path / "cut.mcap") is None
    with pytest.raises(LogError, match="cannot read the ROS log"):
        jointlogs.read(tmp_path / "cut.mcap")


@pytest.mark.parametrize("reference", [True, False])
def test_sqlite_bag_read_as_columns_is_the_per_message_log(tmp_path: Path, reference: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """A ROS 2 sqlite3 bag of one layout per topic is read as columns: bit for bit the per-message reader's log."""
    from ilic_cli.io import jointros

    log = _log(reference)
    jointlogs.write_bag(log, tmp_path / "bag", "sqlite3")
    fast = jointros._sqlite_columns(tmp_path / "bag", None, None)
    chosen = jointros._sqlite_columns(tmp_path / "bag", None, ["c", "a"])  # joints asked for in another order: their own columns
    assert chosen is not None and np.array_equal(chosen.q, log.q[[2, 0]]) and np.array_equal(chosen.tau, log.tau[[2, 0]])
    assert not reference or all(np.array_equal(getattr(chosen, r), getattr(log, r)[[2, 0]]) for r in ("q_ref", "qd_ref", "qdd_ref"))
    monkeypatch.setattr(jointros, "_sqlite_columns", lambda *args: None)
    slow = jointros.read_ros(tmp_path / "bag")
    assert fast is not None and (fast.joints, fast.kinds, fast.meta) == (slow.joints, slow.kinds, slow.meta)
    for name in ("t", "q", "tau", "q_ref", "qd_ref", "qdd_ref"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert (a is None and b is None) if not reference and name.endswith("ref") else np.array_equal(a, b), name


def test_mcap_file_of_a_log_starting_before_time_zero_is_refused(tmp_path: Path) -> None:
    log = _log()
    early = JointLog(t=log.t - 13.0, joints=log.joints, kinds=log.kinds, q=log.q, tau=log.tau)
    with pytest.raises(LogError, match="time starts at -0.5 s: an MCAP log time is unsigned"):
        jointlogs.write(early, tmp_path / "early.mcap")
    assert not (tmp_path / "early.mcap").exists()
