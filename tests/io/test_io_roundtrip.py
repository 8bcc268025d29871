"""Every log format round-trips: synthetic logs exactly, the real EMPS files through the CLI."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io import Selection, WriteOptions, read_log, rosschema, write_log
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli

# (id, output name, WriteOptions)
FORMATS = [
    ("mat", "log.mat", WriteOptions()),
    ("csv", "log.csv", WriteOptions()),
    ("mcap", "log.mcap", WriteOptions()),
    ("rosbag1", "log.bag", WriteOptions()),
    ("rosbag2-sqlite3", "bag_sqlite3", WriteOptions(storage="sqlite3")),
    ("rosbag2-mcap", "bag_mcap", WriteOptions(storage="mcap")),
]
CLI_FORMATS = [
    ("mat", "x.mat", []),
    ("csv", "x.csv", []),
    ("mcap", "x.mcap", []),
    ("rosbag1", "x.bag", []),
    ("rosbag2-sqlite3", "x_bag", ["--storage", "sqlite3"]),
    ("rosbag2-mcap", "x_bag", ["--storage", "mcap"]),
]


def meta_without_source(log: RunLog) -> dict:
    return {k: v for k, v in log.meta.items() if k != "source"}


@pytest.mark.parametrize(("fmt", "name", "options"), FORMATS, ids=[f[0] for f in FORMATS])
def test_synthetic_round_trip_is_exact(tmp_path: Path, synthetic_log: RunLog, fmt: str, name: str, options: WriteOptions) -> None:
    out = write_log(synthetic_log, tmp_path / name, options=options)
    back = read_log(out)
    assert list(back.channels) == list(synthetic_log.channels)
    for channel, values in synthetic_log.channels.items():
        assert np.array_equal(back.channels[channel], values), channel
    assert back.units == synthetic_log.units
    assert meta_without_source(back) == synthetic_log.meta
    assert back.meta["source"] == str(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]  # no temporary left behind


@pytest.mark.parametrize(("fmt", "name", "options"), FORMATS, ids=[f[0] for f in FORMATS])
def test_minimal_log_round_trips_without_inventing_channels(tmp_path: Path, fmt: str, name: str, options: WriteOptions) -> None:
    t = np.linspace(-0.5, 0.5, 11)  # negative times too
    log = RunLog({"t": t, "q": t**2, "tau": np.cos(t)}, {"q": "rad", "tau": "N*m"}, {"joint": "elbow"})
    back = read_log(write_log(log, tmp_path / name, options=options))
    assert list(back.channels) == ["t", "q", "tau"]
    for channel in ("t", "q", "tau"):
        assert np.array_equal(back.channels[channel], log.channels[channel])
    assert back.units == {"t": "s", "q": "rad", "tau": "N*m"}
    assert meta_without_source(back) == {"joint": "elbow"}


def test_mat_tau_without_drive_gain_is_written_as_tau(tmp_path: Path) -> None:
    t = np.arange(5) * 0.01
    log = RunLog({"t": t, "q": t, "tau": t + 1.0})
    out = write_log(log, tmp_path / "a.mat")
    raw = scipy.io.loadmat(out)
    assert "tau" in raw and "vir" not in raw
    assert np.array_equal(read_log(out).channels["tau"], t + 1.0)


def test_mat_vir_from_tau_when_only_gain_known(tmp_path: Path) -> None:
    t = np.arange(5) * 0.01
    tau = np.array([0.1, 0.2, 0.3, 0.7, 1.1])
    log = RunLog({"t": t, "q": t, "tau": tau}, meta={"drive_gain": 3.0})
    out = write_log(log, tmp_path / "a.mat")
    raw = scipy.io.loadmat(out)
    assert np.allclose(raw["vir"].ravel(), tau / 3.0, rtol=1e-15)
    back = read_log(out)
    assert "vir" not in back.channels  # vir was written for EMPS tools, not invented for us
    assert np.array_equal(back.channels["tau"], tau)


def test_mat_pulses_dtype(tmp_path: Path, synthetic_log: RunLog) -> None:
    out = write_log(synthetic_log, tmp_path / "a.mat")
    assert scipy.io.loadmat(out)["pulses_N"].dtype == np.uint8
    fractional = synthetic_log.with_channels(pulses=synthetic_log.channels["pulses"] + 0.5)
    out2 = write_log(fractional, tmp_path / "b.mat")
    assert scipy.io.loadmat(out2)["pulses_N"].dtype == np.float64
    assert np.array_equal(read_log(out2).channels["pulses"], fractional.channels["pulses"])


@pytest.mark.parametrize("ext", ["mat", "csv", "mcap", "bag"])
def test_writing_twice_gives_identical_bytes(tmp_path: Path, synthetic_log: RunLog, ext: str, monkeypatch: pytest.MonkeyPatch) -> None:
    first = write_log(synthetic_log, tmp_path / f"a.{ext}").read_bytes()
    # a writer that stamped the wall clock would now differ
    monkeypatch.setattr(time, "asctime", lambda *a: "Thu Jan  1 00:00:00 2099")
    monkeypatch.setattr(time, "time", lambda: 4070908800.0)
    second = write_log(synthetic_log, tmp_path / f"b.{ext}").read_bytes()
    assert first == second
    assert len(first) > 1000


def test_mcap_layout_is_standard_ros2(tmp_path: Path, synthetic_log: RunLog) -> None:
    from mcap.reader import make_reader

    out = write_log(synthetic_log, tmp_path / "a.mcap")
    with open(out, "rb") as stream:
        reader = make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].encoding, c.message_encoding) for c in summary.channels.values()}
        assert topics == {
            "/joint_states": ("sensor_msgs/msg/JointState", "ros2msg", "cdr"),
            "/joint_reference": ("trajectory_msgs/msg/JointTrajectoryPoint", "ros2msg", "cdr"),
            "/ilic/extras": ("sensor_msgs/msg/JointState", "ros2msg", "cdr"),
            "/ilic/metadata": ("std_msgs/msg/String", "ros2msg", "cdr"),
        }
        assert all(chunk.uncompressed_crc != 0 for chunk in _chunks(out))
        counts = summary.statistics.channel_message_counts
        by_topic = {summary.channels[cid].topic: n for cid, n in counts.items()}
        assert by_topic["/joint_states"] == len(synthetic_log)
        assert by_topic["/ilic/metadata"] == 1


def _chunks(path: Path) -> list:
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as stream:
        return [r for r in StreamReader(stream, emit_chunks=True).records if isinstance(r, Chunk)]


def test_mcap_decodes_with_an_independent_ros2_decoder(tmp_path: Path, synthetic_log: RunLog) -> None:
    """The ros2msg schemas are complete: mcap-ros2-support (as Foxglove) parses them."""
    import mcap_ros2.decoder as decoder_module
    from mcap.reader import make_reader

    out = write_log(synthetic_log, tmp_path / "a.mcap")
    with open(out, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[decoder_module.DecoderFactory()])
        states = [m.decoded_message for m in reader.iter_decoded_messages(topics=["/joint_states"])]
    assert len(states) == len(synthetic_log)
    assert [s.name for s in states[:2]] == [["axis"], ["axis"]]
    assert np.array_equal([s.position[0] for s in states], synthetic_log.channels["q"])
    assert np.array_equal([s.effort[0] for s in states], synthetic_log.channels["tau"])
    stamps = np.array([s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 for s in states])
    assert np.allclose(stamps, synthetic_log.t, atol=1e-9)


# -- files from other tools -----------------------------------------------------
def _foreign_states(joints: list[str], n: int = 50, t0_ns: int = 1_700_000_000_000_000_000) -> list[tuple[int, object]]:
    ts = rosschema.typestore("ros2")
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    out = []
    for i in range(n):
        ns = t0_ns + i * 2_000_000  # 500 Hz
        values = np.array([10.0 * k + i * 0.001 for k in range(len(joints))])
        out.append(
            (
                ns,
                js(
                    header=header(stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="base"),
                    name=list(joints),
                    position=values,
                    velocity=values * 0.5,
                    effort=values * 2.0,
                ),
            )
        )
    return out


def write_foreign_mcap(path: Path, topics: dict[str, list[str]]) -> None:
    """An MCAP as another tool writes it: plain mcap Writer, one JointState topic per entry."""
    from mcap.writer import Writer

    ts = rosschema.typestore("ros2")
    text, _ = rosschema.message_definition("sensor_msgs/msg/JointState")
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start(profile="ros2", library="other-tool")
        schema = writer.register_schema("sensor_msgs/msg/JointState", "ros2msg", text.encode())
        for topic, joints in topics.items():
            channel = writer.register_channel(topic, "cdr", schema)
            for ns, msg in _foreign_states(joints):
                writer.add_message(channel, log_time=ns, publish_time=ns, data=bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState")))
        writer.finish()


def test_foreign_mcap_with_several_joints_needs_joint(tmp_path: Path) -> None:
    path = tmp_path / "robot.mcap"
    write_foreign_mcap(path, {"/robot/joint_states": ["shoulder", "elbow", "wrist"]})
    with pytest.raises(LogError) as info:
        read_log(path)
    message = info.value.message()
    assert "robot.mcap" in message and "shoulder, elbow, wrist" in message and info.value.choice == "joint"  # type: ignore[attr-defined]
    log = read_log(path, selection=Selection(joint="elbow"))
    i = np.arange(50)
    assert np.allclose(log.channels["q"], 10.0 + i * 0.001, rtol=0, atol=1e-12)
    assert np.allclose(log.channels["qd"], 0.5 * (10.0 + i * 0.001))
    assert np.allclose(log.channels["tau"], 2.0 * (10.0 + i * 0.001))
    assert np.allclose(log.t, i * 0.002, atol=1e-12)  # from header.stamp, relative to the first sample
    assert log.meta["joint"] == "elbow" and log.meta["sample_rate_hz"] == 500.0
    assert log.meta["start_time_ns"] == 1_700_000_000_000_000_000


def test_foreign_mcap_cli_joint_choice(tmp_path: Path) -> None:
    path = tmp_path / "robot.mcap"
    write_foreign_mcap(path, {"/robot/joint_states": ["shoulder", "elbow"]})
    refused = run_cli("convert", str(path), str(tmp_path / "out.csv"))
    assert refused.status == 2
    assert "--joint" in refused.stderr and "shoulder, elbow" in refused.stderr
    ok = run_cli("convert", str(path), str(tmp_path / "out.csv"), "--joint", "shoulder")
    assert ok.status == 0, ok.stderr
    log = read_log(tmp_path / "out.csv")
    assert np.allclose(log.channels["q"], np.arange(50) * 0.001, atol=1e-12)


def test_foreign_mcap_with_several_topics_needs_topic(tmp_path: Path) -> None:
    path = tmp_path / "two.mcap"
    write_foreign_mcap(path, {"/left/joint_states": ["a"], "/right/joint_states": ["b"]})
    with pytest.raises(ChoiceError, match="several sensor_msgs/msg/JointState topics") as info:
        read_log(path)
    assert info.value.choice == "topic"
    refused = run_cli("convert", str(path), str(tmp_path / "out.csv"))
    assert refused.status == 2 and "choose one with --topic" in refused.stderr
    overview = run_cli("info", str(path))  # info lists the topics and says what to choose
    assert overview.status == 0 and "| /left/joint_states |" in overview.stdout and "choose one with --topic" in overview.stdout
    log = read_log(path, selection=Selection(topic="/right/joint_states"))
    assert log.meta["joint"] == "b" and len(log) == 50


def test_foreign_rosbag1_multi_joint(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer

    ts = rosschema.typestore("ros1")
    js = ts.types["sensor_msgs/msg/JointState"]
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    path = tmp_path / "arm.bag"
    with Writer(path) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for i in range(30):
            ns = 5 * 10**9 + i * 10**7
            msg = js(
                header=header(seq=i, stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                name=["j1", "j2"],
                position=np.array([i * 1.0, -i * 1.0]),
                velocity=np.array([], dtype=np.float64),
                effort=np.array([0.5, 0.25]),
            )
            writer.write(conn, ns, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/JointState")))
    with pytest.raises(LogError, match="j1, j2"):
        read_log(path)
    log = read_log(path, selection=Selection(joint="j2"))
    assert np.array_equal(log.channels["q"], -np.arange(30.0))
    assert np.array_equal(log.channels["tau"], np.full(30, 0.25))
    assert "qd" not in log.channels  # empty velocity arrays
    assert log.meta["sample_rate_hz"] == 100.0


# -- the real recordings through the command line ----------------------------
@pytest.mark.parametrize("emps_name", ["DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"])
@pytest.mark.parametrize(("fmt", "name", "extra"), CLI_FORMATS, ids=[f[0] for f in CLI_FORMATS])
def test_emps_round_trip_through_cli(tmp_path: Path, emps_dir: Path, emps_name: str, fmt: str, name: str, extra: list[str]) -> None:
    source = emps_dir / emps_name
    middle = tmp_path / name
    back = tmp_path / "back.mat"
    first = run_cli("convert", str(source), str(middle), *extra)
    assert first.status == 0, first.stderr
    assert first.stdout == ""
    assert "24841 samples" in first.stderr
    second = run_cli("convert", str(middle), str(back))
    assert second.status == 0, second.stderr
    original = scipy.io.loadmat(source)
    result = scipy.io.loadmat(back)
    variables = ["t", "qm", "qg", "vir"] + (["pulses_N"] if "pulses_N" in original else [])
    for var in variables:
        assert result[var].shape == original[var].shape == (24841, 1), var
        np.testing.assert_allclose(result[var], original[var], rtol=1e-9, atol=0, err_msg=var)
    if "pulses_N" in original:
        assert result["pulses_N"].dtype == np.uint8
    for var in ("gtau", "kp", "kv"):
        assert result[var].item() == pytest.approx(original[var].item(), rel=1e-12), var
    log = read_log(back)
    assert log.meta["drive_gain"] == pytest.approx(35.15065188248547, rel=1e-12)
    assert log.meta["controller"] == {"kind": "pd", "kp": 160.18, "kv": 243.45}
    assert log.meta["sample_rate_hz"] == 1000.0


def test_ros1_encoded_mcap_with_reference_at_half_rate(tmp_path: Path) -> None:
    """MCAP with ROS 1 messages (as from ROS 1 tools); the reference is interpolated onto the states."""
    from mcap.writer import Writer

    ts = rosschema.typestore("ros1")
    js, header, stamp = ts.types["sensor_msgs/msg/JointState"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    point, duration = ts.types["trajectory_msgs/msg/JointTrajectoryPoint"], ts.types["builtin_interfaces/msg/Duration"]
    path = tmp_path / "ros1.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start("ros1", "other-tool")
        s1 = writer.register_schema("sensor_msgs/JointState", "ros1msg", rosschema.message_definition("sensor_msgs/msg/JointState", "ros1")[0].encode())
        s2 = writer.register_schema(
            "trajectory_msgs/JointTrajectoryPoint", "ros1msg", rosschema.message_definition("trajectory_msgs/msg/JointTrajectoryPoint", "ros1")[0].encode()
        )
        c1 = writer.register_channel("/arm/states", "ros1", s1)
        c2 = writer.register_channel("/joint_reference", "ros1", s2)
        empty = np.array([], dtype=np.float64)
        for i in range(100):
            ns = 10**9 + i * 10**7
            msg = js(
                header=header(seq=i, stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=""),
                name=["a"],
                position=np.array([i * 1.0]),
                velocity=empty,
                effort=np.array([2.0]),
            )
            writer.add_message(c1, ns, bytes(ts.serialize_ros1(msg, "sensor_msgs/msg/JointState")), ns)
            if i % 2 == 0:
                ref = point(positions=np.array([i + 0.5]), velocities=empty, accelerations=empty, effort=empty, time_from_start=duration(sec=0, nanosec=0))
                writer.add_message(c2, ns, bytes(ts.serialize_ros1(ref, "trajectory_msgs/msg/JointTrajectoryPoint")), ns)
        writer.finish()
    log = read_log(path)
    assert log.meta["topic"] == "/arm/states" and log.meta["ref_topic"] == "/joint_reference"
    assert np.allclose(log.t, np.arange(100) * 0.01, atol=1e-12)
    assert np.allclose(log.channels["q_ref"][:99], np.arange(99) + 0.5)  # linear between the half-rate samples
    assert np.array_equal(log.channels["tau"], np.full(100, 2.0))
