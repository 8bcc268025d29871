"""The vectorised ROS 1 bag and CSV paths give exactly what the per-message paths give.

ROS 1 bags written by ilic (vectorised and per-message writers) and by the
independent ``rosbags`` Writer -- several joints, several (compressed) chunks,
layout changes in mid-stream, other topics in between, damaged files -- are
read with ``fast=True`` and ``fast=False``; the columns must be bit-identical
and the metadata equal, or both reads must refuse the file with the same
message. The same for CSV files written by ilic and by ``pandas.to_csv``.
"""

from __future__ import annotations

import dataclasses
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from ilic_cli.errors import LogError
from ilic_cli.io import Selection, WriteOptions, container, csvlog, ros1chunks, ros1fast, rosbag1, rosschema
from ilic_cli.runlog import RunLog
from tests.conftest import make_synthetic_log

JS = "sensor_msgs/msg/JointState"
JTP = "trajectory_msgs/msg/JointTrajectoryPoint"


@dataclasses.dataclass(frozen=True)
class Options:
    """``WriteOptions`` with the ``fast`` switch (until ``io.WriteOptions`` has it)."""

    storage: str = "sqlite3"
    joint: str = "axis"
    fast: bool = True


def assert_same_bits(a: np.ndarray, b: np.ndarray, what: str = "") -> None:
    assert a.dtype == b.dtype == np.float64, what
    assert a.shape == b.shape, what
    assert np.array_equal(a, b, equal_nan=True), what
    assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), what  # -0.0 and NaN payloads too


def assert_same_log(a: RunLog, b: RunLog) -> None:
    assert list(a.channels) == list(b.channels)
    for name in a.channels:
        assert_same_bits(a.channels[name], b.channels[name], name)
    assert a.units == b.units
    assert a.meta == b.meta


def outcome(read: Callable[[], RunLog]) -> RunLog | str:
    """The log, or the one-line message of the LogError (any other exception fails the test)."""
    try:
        return read()
    except LogError as exc:
        message = exc.message()
        assert "\n" not in message
        return message


def assert_same_outcome(first: RunLog | str, second: RunLog | str) -> None:
    if isinstance(first, str) or isinstance(second, str):
        assert first == second
    else:
        assert_same_log(first, second)


def wild_log(samples: int, seed: int = 5) -> RunLog:
    """A log whose values use every kind of float64 bit pattern (subnormals, -0.0, huge, tiny)."""
    rng = np.random.default_rng(seed)
    base = make_synthetic_log(samples=samples, seed=seed)
    bits = rng.integers(0, 2**64, samples, dtype=np.uint64).view(np.float64)
    bits = np.where(np.isfinite(bits), bits, 1.0)
    special = np.array([-0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 1e-5, 1e16])
    bits[: min(6, samples)] = special[: min(6, samples)]
    return base.with_channels(vir=bits, pulses=rng.normal(size=samples) * 1e-300)


# -- ROS 1: our writers ---------------------------------------------------------------
@pytest.mark.parametrize("samples", [1, 37, 6000])  # 6000 samples: two 1 MiB chunks
def test_fast_ros1_writer_writes_the_per_message_writers_bytes(tmp_path: Path, samples: int) -> None:
    log = wild_log(samples)
    fast, slow = tmp_path / "fast.bag", tmp_path / "slow.bag"
    rosbag1.write(log, fast, Options(fast=True))
    rosbag1.write(log, slow, Options(fast=False))
    assert fast.read_bytes() == slow.read_bytes()
    if samples == 6000:
        from rosbags.rosbag1 import Reader

        with Reader(fast) as reader:
            assert len(reader.chunk_infos) >= 2
            assert reader.topics["/joint_states"].msgcount == samples


def _sparse_logs() -> list[RunLog]:
    """Logs with few channels, negative times, strided arrays, a unicode joint and channel name."""
    t = np.linspace(-1.5, 2.5, 401)
    matrix = np.random.default_rng(2).normal(size=(401, 3))
    return [
        RunLog({"t": t, "q": t**2, "tau": np.cos(t)}, {"q": "rad"}, {"joint": "coude_é"}),
        RunLog({"t": t, "q": matrix[:, 0], "tau": matrix[:, 1], "q_ref": matrix[:, 2]}),  # strided columns, a partial reference
        RunLog({"t": t, "q": t, "qd": t * 2, "tau": t, "q_ref": t + 1, "qdd_ref": -t, "température": t * 3}),
    ]


@pytest.mark.parametrize("which", [0, 1, 2])
def test_sparse_logs_same_bytes_and_columns(tmp_path: Path, which: int) -> None:
    log = _sparse_logs()[which]
    fast, slow = tmp_path / "fast.bag", tmp_path / "slow.bag"
    rosbag1.write(log, fast, Options(fast=True))
    rosbag1.write(log, slow, Options(fast=False))
    assert fast.read_bytes() == slow.read_bytes()
    back = rosbag1.read(fast, Selection(), fast=True)
    assert_same_log(back, rosbag1.read(fast, Selection(), fast=False))
    for name, values in log.channels.items():
        assert_same_bits(back.channels[name], np.ascontiguousarray(values), name)


@pytest.mark.parametrize("writer_fast", [True, False])
def test_our_bags_read_the_same_both_ways(tmp_path: Path, writer_fast: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    log = wild_log(6000)
    path = tmp_path / "log.bag"
    rosbag1.write(log, path, Options(fast=writer_fast))
    runs = _count_runs(monkeypatch)
    fast = rosbag1.read(path, Selection(), fast=True)
    assert runs["run"] >= 2  # the vectorised path did the work (one run per chunk at least)
    slow = rosbag1.read(path, Selection(), fast=False)
    assert_same_log(fast, slow)
    assert_same_log(fast, log)  # and both are the log that was written
    for partial in (log.slice(0, 2), log.with_channels().slice(0, 1)):
        rosbag1.write(partial, path, Options(fast=writer_fast))
        assert_same_log(rosbag1.read(path, Selection(), fast=True), rosbag1.read(path, Selection(), fast=False))


def _count_runs(monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Count vectorised runs and records decoded one by one in the fast reader."""
    counts = {"run": 0, "one": 0}
    run, one = ros1chunks._ChunkWalker._run, ros1chunks._ChunkWalker._one

    def counting_run(self: Any, *args: Any) -> int:
        counts["run"] += 1
        return run(self, *args)

    def counting_one(self: Any, *args: Any) -> None:
        counts["one"] += 1
        one(self, *args)

    monkeypatch.setattr(ros1chunks._ChunkWalker, "_run", counting_run)
    monkeypatch.setattr(ros1chunks._ChunkWalker, "_one", counting_one)
    return counts


@pytest.mark.parametrize("compression", ["lz4", "bz2"])
def test_compressed_ilic_bag_from_rosbags_writer(tmp_path: Path, compression: str) -> None:
    from rosbags.rosbag1 import Writer

    log = wild_log(3000)
    path = tmp_path / "c.bag"
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat[compression.upper()])
    writer.chunk_threshold = 64 * 1024
    container.write_bag(writer, log, "axis", rosschema.ROS1)
    ros1fast.collect(path, 2**30, rosbag1._declare)  # no Fallback: the vectorised path reads it
    fast = rosbag1.read(path, Selection(), fast=True)
    assert_same_log(fast, rosbag1.read(path, Selection(), fast=False))
    assert_same_log(fast, log)


# -- ROS 1: bags from the rosbags Writer ----------------------------------------------
def _state(ts: Any, i: int, ns: int, names: list[str], frame: str = "base", velocity: bool = True) -> bytes:
    header = ts.types["std_msgs/msg/Header"]
    stamp = ts.types["builtin_interfaces/msg/Time"]
    values = np.array([10.0 * k + i * 0.001 + 1e-9 * np.sin(i) for k in range(len(names))])
    msg = ts.types[JS](
        header=header(seq=i * 7 + 3, stamp=stamp(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame),
        name=list(names),
        position=values,
        velocity=values * 0.5 if velocity else np.array([], dtype=np.float64),
        effort=values * -2.0,
    )
    return bytes(ts.serialize_ros1(msg, JS))


def _point(ts: Any, i: int, width: int) -> bytes:
    duration = ts.types["builtin_interfaces/msg/Duration"]
    values = np.array([0.5 * k - i * 0.01 for k in range(width)])
    msg = ts.types[JTP](
        positions=values,
        velocities=values * 3.0,
        accelerations=np.array([], dtype=np.float64),
        effort=np.array([], dtype=np.float64),
        time_from_start=duration(sec=i // 100, nanosec=(i % 100) * 10**7),
    )
    return bytes(ts.serialize_ros1(msg, JTP))


def write_foreign_bag(
    path: Path,
    samples: int,
    *,
    names: Callable[[int], list[str]],
    frame: Callable[[int], str] = lambda i: "base",
    chunk_threshold: int = 16 * 1024,
    compression: str | None = None,
    chatter: bool = False,
    reference: bool = True,
) -> None:
    """A bag as a ROS 1 robot records it, through the rosbags Writer."""
    from rosbags.rosbag1 import Writer

    ts = rosschema.typestore("ros1")
    writer = Writer(path)
    if compression:
        writer.set_compression(Writer.CompressionFormat[compression.upper()])
    writer.chunk_threshold = chunk_threshold
    with writer:
        states = writer.add_connection("/arm/joint_states", JS, typestore=ts, callerid="/driver")
        ref = writer.add_connection("/joint_reference", JTP, typestore=ts) if reference else None
        talk = writer.add_connection("/chatter", "std_msgs/msg/Int32", typestore=ts) if chatter else None
        for i in range(samples):
            ns = 1_600_000_000 * 10**9 + i * 2_000_000
            writer.write(states, ns, _state(ts, i, ns, names(i), frame(i), velocity=i % 1000 < 700))
            if ref is not None and i % 2 == 0:
                writer.write(ref, ns, _point(ts, i, len(names(i))))
            if talk is not None and i % 3 == 0:
                writer.write(talk, ns + 1, bytes(ts.serialize_ros1(ts.types["std_msgs/msg/Int32"](data=i), "std_msgs/msg/Int32")))


FOREIGN_CASES: dict[str, dict[str, Any]] = {
    "multi-joint, many chunks": {"names": lambda i: ["shoulder", "elbow", "wrist"]},
    "joint name length changes": {"names": lambda i: ["a" if i < 900 else "a_joint", "elbow"]},
    "joint count changes": {"names": lambda i: ["a", "elbow"] + (["wrist"] if 500 <= i < 1300 else [])},
    "frame_id changes, lz4": {"names": lambda i: ["a", "elbow"], "frame": lambda i: "base" if i % 400 < 200 else "odom_frame", "compression": "lz4"},
    "other topic between, bz2": {"names": lambda i: ["a", "elbow"], "chatter": True, "compression": "bz2", "chunk_threshold": 50_000},
    "one big chunk, no reference": {"names": lambda i: ["elbow"], "chunk_threshold": 1 << 30, "reference": False},
    "frame_id changes every 50, one chunk": {
        "names": lambda i: ["a", "elbow"],
        "frame": lambda i: "base" if (i // 50) % 2 else "odom",
        "chunk_threshold": 1 << 30,
    },
}


@pytest.mark.parametrize("case", list(FOREIGN_CASES))
def test_foreign_bags_read_the_same_both_ways(tmp_path: Path, case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "robot.bag"
    write_foreign_bag(path, 2000, **FOREIGN_CASES[case])
    ros1fast.collect(path, 2**30, rosbag1._declare)  # the vectorised reader takes the file (no Fallback)
    runs = _count_runs(monkeypatch)
    fast = rosbag1.read(path, Selection(joint="elbow"), fast=True)
    assert runs["run"] >= 1
    if "every 50" in case:
        assert runs["run"] >= 40  # a new run after each change
    elif "changes" in case:
        assert runs["one"] >= 1  # the records around the change went message by message
    slow = rosbag1.read(path, Selection(joint="elbow"), fast=False)
    assert_same_log(fast, slow)
    assert len(fast) == 2000
    i = np.arange(2000)
    column = np.array([FOREIGN_CASES[case]["names"](k).index("elbow") for k in i])
    assert np.allclose(fast.channels["q"], 10.0 * column + i * 0.001, rtol=0, atol=1e-8)
    assert np.array_equal(fast.t, (i * 2_000_000).astype(np.float64) / 1e9)
    if "multi" in case:
        with pytest.raises(LogError, match="shoulder, elbow, wrist"):
            rosbag1.read(path, Selection(), fast=True)


def test_damaged_bags_give_the_same_outcome_both_ways(tmp_path: Path) -> None:
    """Flipped bytes anywhere: the same log or the same error from both readers."""
    log = make_synthetic_log(samples=300)
    good = tmp_path / "good.bag"
    rosbag1.write(log, good, Options())
    foreign = tmp_path / "foreign.bag"
    write_foreign_bag(foreign, 300, names=lambda i: ["a", "elbow"], chunk_threshold=4096, chatter=True)
    packed = tmp_path / "packed.bag"
    write_foreign_bag(packed, 300, names=lambda i: ["a", "elbow"], chunk_threshold=4096, compression="lz4")
    rng = random.Random(13)
    refused = 0
    for source in (good, foreign, packed):
        original = source.read_bytes()
        for k in range(90):
            raw = bytearray(original)
            if k % 3 == 0:
                raw = raw[: rng.randrange(1, len(raw))]
            else:
                for _ in range(1 + k % 4):
                    raw[rng.randrange(len(raw))] ^= 1 << rng.randrange(8)
            bad = tmp_path / "bad.bag"
            bad.write_bytes(bytes(raw))
            selection = Selection() if source == good else Selection(joint="elbow")
            fast = outcome(lambda: rosbag1.read(bad, selection, fast=True))
            slow = outcome(lambda: rosbag1.read(bad, selection, fast=False))
            assert_same_outcome(fast, slow)
            refused += isinstance(fast, str)
    assert refused >= 90


def test_chunk_decompression_stays_capped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "c.bag"
    write_foreign_bag(path, 3000, names=lambda i: ["elbow"], compression="bz2", chunk_threshold=1 << 30)
    monkeypatch.setattr(rosbag1, "MAX_EXPANSION", 1)  # every chunk expands past the file size
    for fast in (True, False):
        with pytest.raises(LogError, match="decompresses to more than"):
            rosbag1.read(path, Selection(), fast=fast)


# -- CSV ----------------------------------------------------------------------------
@pytest.mark.parametrize("samples", [1, 40, 70_000])  # 70 000 rows: several blocks of the fast writer
def test_fast_csv_writer_writes_the_row_writers_bytes(tmp_path: Path, samples: int) -> None:
    log = wild_log(samples)
    fast, slow = tmp_path / "fast.csv", tmp_path / "slow.csv"
    csvlog.write(log, fast, Options(fast=True))
    csvlog.write(log, slow, Options(fast=False))
    assert fast.read_bytes() == slow.read_bytes()
    back = csvlog.read(fast, Selection(), fast=True)
    assert_same_log(back, csvlog.read(fast, Selection(), fast=False))
    assert_same_log(back, log)  # the round trip is bit-exact


def _pandas_frame(samples: int) -> pd.DataFrame:
    log = wild_log(samples, seed=9)
    return pd.DataFrame({name: values for name, values in log.channels.items()})


PANDAS_CASES: dict[str, dict[str, Any]] = {
    "default": {},
    "crlf": {"lineterminator": "\r\n"},
    "%.6g": {"float_format": "%.6g"},
    "%.17g": {"float_format": "%.17g"},
    "%.3e": {"float_format": "%.3e"},
}


@pytest.mark.parametrize("case", list(PANDAS_CASES))
def test_pandas_written_csv_reads_the_same_both_ways(tmp_path: Path, case: str) -> None:
    frame = _pandas_frame(5000)
    path = tmp_path / "p.csv"
    frame.to_csv(path, index=False, **PANDAS_CASES[case])
    assert csvlog._read_fast(path, {}) is not None  # the fast reader takes these files
    fast = csvlog.read(path, Selection(), fast=True)
    assert_same_log(fast, csvlog.read(path, Selection(), fast=False))
    if case in ("default", "crlf", "%.17g"):
        for name in frame.columns:
            assert_same_bits(fast.channels[name], frame[name].to_numpy(), name)


@pytest.mark.parametrize(
    "text",
    [
        '\ufeff# units: t=s\n\n# meta: {"a": 1}\nt,q,tau\n0,1,2\n\n1,3,4\n',  # BOM, blank lines
        "t, q ,tau\n0,1,2\r\n1,3,4\r\n\r\n",  # spaces in the header, CRLF, trailing blank line
        "t,q,tau\n0, 1,2\n1,3,4\n",  # a space in a number: row by row
        't,q,tau\n0,"1",2\n1,3,4\n',  # quotes: row by row
        "t,q,tau\n0,nan,2\n1,inf,4\n",  # words: row by row
        "t,q,tau\n0,1_0,2\n1,3,4\n",  # underscores (float() takes them)
        "t,q,tau\n0,TRUE,2\n1,3,4\n",  # pandas would read a boolean word as 1.0
        "t,q,tau\n0,TRUE,2\n1,FALSE,4\n",  # a column of boolean words
        "t,q,tau\n0,1,2\n1,3\n",  # short row
        "t,q,tau\n0,1,2,5\n1,3,4\n",  # long row
        "t,q,tau\n0,1,2\n1,3,4,\n",  # trailing comma
        "t,q,tau\n0,1e,2\n",  # not a number
        "t,q,tau\n",  # no rows
        "t,q,q\n0,1,2\n",  # duplicated column
        "# units: t\nt,q,tau\n0,1,2\n",  # bad units line
        "# meta: {oops\nt,q,tau\n0,1,2\n",  # bad metadata
        "t,q,tau\r0,1,2\r1,3,4\r",  # old Mac line ends
        "t,q,tau\n0,1,2\x0b\n",  # a vertical tab
        "t,q,tau\n1.5e3,-0.0,+.5\n2.,00.25,1E-5\n",  # number spellings the fast path takes
    ],
)
def test_odd_csv_files_give_the_same_outcome_both_ways(tmp_path: Path, text: str) -> None:
    path = tmp_path / "odd.csv"
    path.write_bytes(text.encode("utf-8"))
    assert_same_outcome(outcome(lambda: csvlog.read(path, Selection(), fast=True)), outcome(lambda: csvlog.read(path, Selection(), fast=False)))


def test_damaged_csv_gives_the_same_outcome_both_ways(tmp_path: Path) -> None:
    good = tmp_path / "good.csv"
    csvlog.write(make_synthetic_log(samples=200), good, Options())
    original = good.read_bytes()
    rng = random.Random(7)
    taken = 0
    for k in range(200):
        raw = bytearray(original)
        if k % 4 == 0:
            raw = raw[: rng.randrange(1, len(raw))]
        else:
            for _ in range(1 + k % 3):
                raw[rng.randrange(len(raw))] ^= 1 << rng.randrange(8)
        bad = tmp_path / "bad.csv"
        bad.write_bytes(bytes(raw))
        fast = outcome(lambda: csvlog.read(bad, Selection(), fast=True))
        assert_same_outcome(fast, outcome(lambda: csvlog.read(bad, Selection(), fast=False)))
        taken += csvlog._read_fast(bad, {}) is not None
    assert taken >= 10  # damaged files are still read by the fast path (a flipped digit)


def test_write_options_fast_default_is_the_fast_path(tmp_path: Path) -> None:
    """Without a ``fast`` field (today's WriteOptions) the writers take the fast path, same bytes."""
    log = make_synthetic_log(samples=50)
    for ext, module in (("bag", rosbag1), ("csv", csvlog)):
        a, b = tmp_path / f"a.{ext}", tmp_path / f"b.{ext}"
        module.write(log, a, WriteOptions())
        module.write(log, b, Options(fast=False))
        assert a.read_bytes() == b.read_bytes()
