"""n-joint logs in every format (issue 30, item 1): CSV, MCAP, ROS 2 bags (sqlite3, MCAP), ROS 1 ``.bag`` and ``.mat`` round trip
bit for bit; ``ilic convert`` converts an arm's log between them, and IDIM-LS gives the same estimates on each."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.cli import main
from ilic_cli.errors import LogError
from ilic_cli.io import jointlogs
from ilic_cli.jointlog import REFERENCES, JointLog
from tests.robot.test_jointlog import FOREIGN_JOINTS, foreign_states

N = 200
FIXTURES = Path(__file__).parents[2] / "fixtures"
OUTPUTS = {
    "csv": ("x.csv", []),
    "mcap": ("x.mcap", []),
    "rosbag1": ("x.bag", []),
    "mat": ("x.mat", []),
    "sqlite3": ("bag", []),
    "bagmcap": ("bagm", ["--storage", "mcap"]),
}
"""Each n-joint format: an output name and the options of ``ilic convert`` that write it."""


def _log(reference: bool = True) -> JointLog:
    """3 joints (one prismatic, one named like a reference column), stamps in whole nanoseconds (what every ROS container holds)."""
    rng = np.random.default_rng(11)
    refs = {r: rng.standard_normal((3, N)) * (k + 1) for k, r in enumerate(REFERENCES)} if reference else {}
    return JointLog(
        t=(2_000_000_000 + np.arange(N) * 1_000_000 + rng.integers(0, 300, N)) * 1e-9,
        joints=("a", "ref_b", "c"),
        kinds=("revolute", "prismatic", "revolute"),
        q=rng.standard_normal((3, N)) * 1e3,
        tau=rng.standard_normal((3, N)) / 7.0,
        meta={"controller": {"kind": "pd", "kp": 3.5}, "scenario": "π test"},
        **refs,
    )


def _same(back: JointLog, log: JointLog) -> None:
    assert back.joints == log.joints and back.kinds == log.kinds
    for k in ("t", "q", "tau", *REFERENCES):
        a, b = getattr(back, k), getattr(log, k)
        assert (a is None and b is None) or (a is not None and b is not None and a.dtype == np.float64 and np.array_equal(a, b)), k
    assert {k: v for k, v in back.meta.items() if k != "source"} == {k: v for k, v in log.meta.items() if k != "source"}


@pytest.mark.parametrize("reference", [True, False])
@pytest.mark.parametrize("kind", ["csv", "mcap", "rosbag1", "mat", "sqlite3", "bagmcap"])
def test_every_format_round_trips_n_joints_bit_for_bit(tmp_path: Path, kind: str, reference: bool) -> None:
    log = _log(reference)
    name, options = OUTPUTS[kind]
    storage = "mcap" if options else "sqlite3"
    jointlogs.write(log, tmp_path / name, storage=storage)
    back = jointlogs.read(tmp_path / name)
    _same(back, log)
    assert back.provenance.source == str(tmp_path / name) and jointlogs.declares_joints(tmp_path / name)
    assert [p.name for p in tmp_path.iterdir()] == [name]  # the temporary name is gone
    if kind == "rosbag1":
        assert (tmp_path / name).read_bytes().startswith(b"#ROSBAG V2.0\n")  # a ROS 1 bag file, not a ROS 2 bag folder named .bag
    if kind in ("rosbag1", "mat"):  # the same log, the same bytes
        jointlogs.write(log, tmp_path / ("again" + name[1:]))
        assert (tmp_path / name).read_bytes() == (tmp_path / ("again" + name[1:])).read_bytes()


def test_mat_layout_is_what_an_engineer_loads(tmp_path: Path) -> None:
    import scipy.io

    log = _log()
    jointlogs.write(log, tmp_path / "arm.mat")
    m = scipy.io.loadmat(str(tmp_path / "arm.mat"), simplify_cells=True)
    assert m["t"].shape == (N,) and m["q"].shape == (N, 3) and m["qdd_ref"].shape == (N, 3)  # simplify_cells squeezes t's (N, 1)
    assert np.array_equal(m["q"][:, 1], log.q[1]) and np.array_equal(m["qd_ref"][:, 2], log.qd_ref[2])  # type: ignore[index]
    assert list(m["joint_names"]) == ["a", "ref_b", "c"] and list(m["joint_types"]) == ["revolute", "prismatic", "revolute"]
    assert json.loads(m["metadata"])["scenario"] == "π test"


def test_one_joint_emps_mat_is_not_an_arms_log(tmp_path: Path) -> None:
    """A one-joint .mat (ilic's EMPS layout) keeps to the one-joint chain: it declares no joints, and the n-joint reader says why it refuses it."""
    from ilic_cli.io import WriteOptions, write_log
    from ilic_cli.runlog import RunLog

    t = np.arange(50) * 1e-3
    write_log(RunLog({"t": t, "q": np.sin(t), "tau": np.cos(t)}, {"q": "rad"}, {"joint": "a"}), tmp_path / "one.mat", "mat", WriteOptions())
    assert not jointlogs.declares_joints(tmp_path / "one.mat")
    with pytest.raises(LogError, match="not an n-joint .mat: no joint_names"):
        jointlogs.read(tmp_path / "one.mat")


def test_ros1_bag_by_rosbags_writer_with_more_joints_is_read_by_name(tmp_path: Path) -> None:
    """A ROS 1 bag of another writer (rosbags', Noetic types, 4 joints in another order, no metadata): the joints asked for, by name."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    State, Header, Time = ts.types["sensor_msgs/msg/JointState"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Time"]
    messages, pos, eff = foreign_states(ts, ros1=True)
    names = FOREIGN_JOINTS
    with Writer(tmp_path / "other.bag") as writer:
        conn = writer.add_connection("/arm/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for ns, msg in messages:
            writer.write(conn, ns, ts.serialize_ros1(msg, "sensor_msgs/msg/JointState"))
    log = jointlogs.read(tmp_path / "other.bag", joints=["shoulder", "elbow"])
    assert log.joints == ("shoulder", "elbow") and log.kinds == ("revolute", "revolute") and not log.has_reference
    assert np.array_equal(log.q, pos[:, [3, 1]].T) and np.array_equal(log.tau, eff[:, [3, 1]].T) and log.fs_hz == pytest.approx(500.0)
    assert log.meta["types_assumed"] == ["shoulder", "elbow"] and not jointlogs.declares_joints(tmp_path / "other.bag")
    with pytest.raises(LogError, match=r"no joint wrist in /arm/joint_states \(it has gripper, elbow, base_yaw, shoulder\)"):
        jointlogs.read(tmp_path / "other.bag", joints=["shoulder", "wrist"])
    for text, problem in [("not json", "cannot read the ROS log: Expecting value"), ("[1]", "/ilic/metadata is not a JSON object")]:
        bad = tmp_path / f"bad{len(text)}.bag"
        with Writer(bad) as writer:
            conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
            info = writer.add_connection("/ilic/metadata", "std_msgs/msg/String", typestore=ts)
            writer.write(info, 1, ts.serialize_ros1(ts.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"))
            header = Header(seq=0, stamp=Time(sec=1, nanosec=0), frame_id="")
            state = State(header=header, name=names, position=pos[0], velocity=pos[0], effort=eff[0])
            writer.write(conn, 2, ts.serialize_ros1(state, "sensor_msgs/msg/JointState"))
        with pytest.raises(LogError, match=problem):
            jointlogs.read(bad)


def run(capsys: pytest.CaptureFixture[str], *args: str | Path) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main([str(a) for a in args])
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


@pytest.mark.parametrize("source", list(OUTPUTS))
def test_convert_an_arms_log_between_every_pair_of_formats(tmp_path: Path, capsys: pytest.CaptureFixture[str], source: str) -> None:
    """``ilic convert`` of a 3-joint log from ``source`` to every other format, by the log's own declaration (no --urdf, no --joints)."""
    log = _log()
    name, options = OUTPUTS[source]
    src = tmp_path / "in" / name
    src.parent.mkdir()
    jointlogs.write(log, src, storage="mcap" if options else "sqlite3")
    for target, (out_name, out_options) in OUTPUTS.items():
        if target == source:
            continue
        code, out, err = run(capsys, "convert", src, tmp_path / out_name, *out_options)
        assert code == 0 and out == "", err
        assert err.startswith(f"ilic: wrote {tmp_path / out_name} (") and "3 joints a, ref_b, c, with reference" in err
        _same(jointlogs.read(tmp_path / out_name), log)


def test_convert_refuses_what_does_not_apply_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = _log()
    jointlogs.write(log, tmp_path / "arm.mat")
    for args, message in [
        (["--resample", "100"], "ilic: error: --resample: applies to a one-joint log; "),
        (["--topic", "/x"], "ilic: error: --topic: applies to a one-joint log; "),
        (["--joint", "a"], f"ilic: error: --joint: {tmp_path / 'arm.mat'} is an arm's log: --joints a converts that joint"),
    ]:
        code, out, err = run(capsys, "convert", tmp_path / "arm.mat", tmp_path / "out.bag", *args)
        assert (code, out) == (2, "") and err.startswith(message) and err.count("\n") == 1, err
    code, out, err = run(capsys, "info", tmp_path / "arm.mat", "--format", "json")  # an arm's .mat: its joints, not the one-joint summary
    assert code == 0 and [(j["name"], j["type"]) for j in json.loads(out)["joints"]] == list(zip(log.joints, log.kinds)), err
    code, _, err = run(capsys, "convert", tmp_path / "arm.mat", tmp_path / "arm.mat")
    assert code == 2 and "output would overwrite the input" in err
    bad = tmp_path / "bad.mat"
    import scipy.io

    scipy.io.savemat(str(bad), {"t": log.t.reshape(-1, 1), "q": log.q.T[:, :2], "tau": log.tau.T, "joint_names": np.array([["a", "b", "c"]], dtype=object)})
    code, out, err = run(capsys, "convert", bad, tmp_path / "out.csv")
    assert (code, out) == (2, "") and err == f"ilic: error: {bad}: q is float64 (200, 2); expected float64 of size 200 x 3\n"
    code, out, err = run(capsys, "convert", tmp_path / "arm.mat", tmp_path / "nowhere" / "out.csv")
    assert (code, out, err) == (2, "", f"ilic: error: {tmp_path / 'nowhere' / 'out.csv'}: no such folder {tmp_path / 'nowhere'}\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arm.mat", "bad.mat"]  # no output, no temporary left
    jointlogs.write(log, tmp_path / "bag")
    code, _, err = run(capsys, "convert", tmp_path / "bag" / "metadata.yaml", tmp_path / "back.mat")  # a path inside a bag folder: the folder
    assert code == 0 and "3 joints a, ref_b, c" in err
    _same(jointlogs.read(tmp_path / "back.mat"), log)


def test_identify_gives_the_same_estimates_on_a_log_converted_to_each_format(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """IDIM-LS of arm2 on one log converted to every format: the same JSON report but for the log's name (the samples are the same bits)."""
    from tests.conftest import import_or_skip

    import_or_skip("pinocchio")
    t = np.arange(2000) * 1_000_000 * 1e-9
    w = np.array([[1.3, 2.9, 5.1], [1.7, 3.3, 4.4]])
    q = np.array([0.5 * np.sin(2 * np.pi * f[:, None] * t).sum(0) for f in w])
    tau = np.array([2.0 * np.cos(2 * np.pi * f[:, None] * t).sum(0) for f in w]) + 0.3 * np.sign(np.gradient(q, axis=1))
    jointlogs.write(JointLog(t=t, joints=("shoulder", "elbow"), kinds=("revolute", "revolute"), q=q, tau=tau), tmp_path / "arm.csv")
    reports = []
    for kind, (name, options) in OUTPUTS.items():
        path = tmp_path / "arm.csv" if kind == "csv" else tmp_path / name
        if kind != "csv":  # the ROS 1 bag through --urdf (the joints read by the URDF's names, their types checked)
            urdf: list[str | Path] = ["--urdf", FIXTURES / "arm2.urdf"] if kind == "rosbag1" else []
            assert run(capsys, "convert", tmp_path / "arm.csv", path, *options, *urdf)[0] == 0
        code, out, err = run(capsys, "identify", path, "--urdf", FIXTURES / "arm2.urdf", "--method", "ls", "--format", "json")
        assert code == 0, err
        doc = json.loads(out)
        assert doc.pop("log") == str(path)
        reports.append(doc)
    assert reports[0]["methods"] and all(r == reports[0] for r in reports[1:])
