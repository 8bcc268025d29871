"""Bad input: one line ``ilic: error: FILE: problem``, exit 2, no traceback, nothing written."""

from __future__ import annotations

import random
import shutil
import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from ilic_cli.errors import LogError
from ilic_cli.io import WriteOptions, read_log, write_log
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli
from tests.conftest import make_synthetic_log

N = 40


def _log() -> RunLog:
    return make_synthetic_log(samples=N)


def _csv(path: Path, header: str, rows: list[str]) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


def _good_csv_rows() -> list[str]:
    return [f"{i * 0.001!r},{i * 0.1!r},{1.5 + i!r}" for i in range(N)]


def _mat(path: Path, **variables: object) -> Path:
    t = np.arange(N, dtype=float).reshape(-1, 1) * 1e-3
    base: dict[str, object] = {"t": t, "qm": t * 2, "qg": t * 2, "vir": t + 1, "gtau": np.array([[35.0]]), "kp": np.array([[1.0]]), "kv": np.array([[2.0]])}
    base.update(variables)
    scipy.io.savemat(path, {k: v for k, v in base.items() if v is not None})
    return path


def _mcap_chunk_offset(path: Path) -> int:
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and summary.chunk_indexes
    return summary.chunk_indexes[0].chunk_start_offset


def case_missing(d: Path) -> Path:
    return d / "absent.mcap"


def case_empty(d: Path) -> Path:
    (d / "empty.mcap").write_bytes(b"")
    return d / "empty.mcap"


def case_truncated_mcap(d: Path) -> Path:
    good = write_log(_log(), d / "good.mcap")
    bad = d / "truncated.mcap"
    bad.write_bytes(good.read_bytes()[: good.stat().st_size * 2 // 3])
    good.unlink()
    return bad


def case_flipped_mcap_chunk(d: Path) -> Path:
    good = write_log(_log(), d / "good.mcap")
    raw = bytearray(good.read_bytes())
    start = _mcap_chunk_offset(good)
    raw[start + 200] ^= 0x01  # inside the chunk's compressed records
    good.unlink()
    (d / "flipped.mcap").write_bytes(bytes(raw))
    return d / "flipped.mcap"


def case_hostile_mcap_chunk_size(d: Path) -> Path:
    good = write_log(_log(), d / "good.mcap")
    raw = bytearray(good.read_bytes())
    start = _mcap_chunk_offset(good)
    # Chunk record: opcode u8, length u64, start u64, end u64, uncompressed_size u64, ...
    raw[start + 25 : start + 33] = struct.pack("<Q", 2**40)
    good.unlink()
    (d / "hostile.mcap").write_bytes(bytes(raw))
    return d / "hostile.mcap"


def case_not_mcap(d: Path) -> Path:
    (d / "garbage.mcap").write_bytes(b"this is not an mcap file at all" * 10)
    return d / "garbage.mcap"


def case_truncated_bag(d: Path) -> Path:
    good = write_log(_log(), d / "good.bag")
    bad = d / "truncated.bag"
    bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    good.unlink()
    return bad


def case_corrupt_sqlite_rosbag2(d: Path) -> Path:
    bag = write_log(_log(), d / "corrupt_bag", options=WriteOptions(storage="sqlite3"))
    db = next(bag.glob("*.db3"))
    raw = bytearray(db.read_bytes())
    raw[100:4000] = b"\x77" * 3900
    db.write_bytes(bytes(raw))
    return bag


def case_rosbag2_without_metadata(d: Path) -> Path:
    bag = write_log(_log(), d / "no_meta_bag", options=WriteOptions(storage="sqlite3"))
    (bag / "metadata.yaml").unlink()
    return bag


def case_unknown_extension(d: Path) -> Path:
    (d / "run.txt").write_text("t,q,tau\n0,0,0\n")
    return d / "run.txt"


def case_csv_without_tau(d: Path) -> Path:
    return _csv(d / "no_tau.csv", "t,q", [f"{i * 0.001!r},{i * 0.1!r}" for i in range(N)])


def case_csv_nan(d: Path) -> Path:
    rows = _good_csv_rows()
    rows[7] = "0.007,nan,8.5"
    return _csv(d / "nan.csv", "t,q,tau", rows)


def case_csv_duplicated_time(d: Path) -> Path:
    rows = _good_csv_rows()
    rows[5] = rows[4].split(",")[0] + ",0.5,6.5"
    return _csv(d / "dup_time.csv", "t,q,tau", rows)


def case_csv_backwards_time(d: Path) -> Path:
    rows = _good_csv_rows()
    rows[10], rows[11] = rows[11], rows[10]
    return _csv(d / "backwards.csv", "t,q,tau", rows)


def case_csv_text_in_number(d: Path) -> Path:
    rows = _good_csv_rows()
    rows[3] = "0.003,oops,4.5"
    return _csv(d / "text.csv", "t,q,tau", rows)


def case_csv_ragged_row(d: Path) -> Path:
    rows = _good_csv_rows()
    rows[2] = "0.002,0.2"
    return _csv(d / "ragged.csv", "t,q,tau", rows)


def case_mat_2d_qm(d: Path) -> Path:
    t = np.arange(N, dtype=float).reshape(-1, 1)
    return _mat(d / "qm_2d.mat", qm=np.hstack([t, t]))


def case_mat_text_qm(d: Path) -> Path:
    return _mat(d / "qm_text.mat", qm="not numbers")


def case_mat_length_mismatch(d: Path) -> Path:
    return _mat(d / "lengths.mat", qg=np.zeros((N - 1, 1)))


def case_mat_missing_qm(d: Path) -> Path:
    return _mat(d / "no_qm.mat", qm=None)


def case_mat_vector_gain(d: Path) -> Path:
    return _mat(d / "gain.mat", gtau=np.ones((3, 1)))


def case_not_a_mat(d: Path) -> Path:
    (d / "garbage.mat").write_bytes(b"MATLAB? no." * 20)
    return d / "garbage.mat"


# case -> (builder, words the message must contain)
CASES: dict[str, tuple[Callable[[Path], Path], tuple[str, ...]]] = {
    "missing file": (case_missing, ("no such file",)),
    "empty file": (case_empty, ("empty",)),
    "truncated mcap": (case_truncated_mcap, ("truncated or corrupt",)),
    "flipped mcap chunk": (case_flipped_mcap_chunk, ("corrupt",)),
    "hostile mcap chunk size": (case_hostile_mcap_chunk_size, ("declares",)),
    "not an mcap": (case_not_mcap, ("MCAP",)),
    "truncated bag": (case_truncated_bag, ("ROS 1 bag",)),
    "corrupt sqlite rosbag2": (case_corrupt_sqlite_rosbag2, ("ROS 2 bag",)),
    "rosbag2 without metadata": (case_rosbag2_without_metadata, ("metadata.yaml",)),
    "unknown extension": (case_unknown_extension, ("unknown log extension",)),
    "csv without tau": (case_csv_without_tau, ("missing required channel 'tau'",)),
    "NaN sample": (case_csv_nan, ("NaN",)),
    "duplicated timestamp": (case_csv_duplicated_time, ("duplicated timestamps",)),
    "non-monotonic timestamps": (case_csv_backwards_time, ("non-monotonic",)),
    "text in numeric column": (case_csv_text_in_number, ("line 5", "column 'q'", "oops")),
    "ragged csv row": (case_csv_ragged_row, ("line 4", "fields")),
    "mat 2-D qm": (case_mat_2d_qm, ("'qm'", "column vector")),
    "mat text qm": (case_mat_text_qm, ("'qm'", "text")),
    "mat length mismatch": (case_mat_length_mismatch, ("different lengths",)),
    "mat missing qm": (case_mat_missing_qm, ("missing variable 'qm'",)),
    "mat vector gain": (case_mat_vector_gain, ("'gtau'", "scalar")),
    "not a mat file": (case_not_a_mat, ("MATLAB",)),
}


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def assert_one_line_error(stderr: str, name: str, words: tuple[str, ...] = ()) -> None:
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("ilic: error: "), stderr
    assert name in lines[0], stderr
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], f"{word!r} not in {lines[0]!r}"


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_is_refused_cleanly(tmp_path: Path, case: str) -> None:
    builder, words = CASES[case]
    inputs = tmp_path / "in"
    outputs = tmp_path / "out"
    inputs.mkdir()
    outputs.mkdir()
    bad = builder(inputs)
    before = _listing(inputs)
    for out_name in ("converted.csv", "converted.mcap", "converted_bag"):
        result = run_cli("convert", str(bad), str(outputs / out_name))
        assert result.status == 2, (case, result)
        assert_one_line_error(result.stderr, bad.name, words)
        assert result.stdout == ""
    assert _listing(outputs) == []  # no output, no temporary file or folder
    assert _listing(inputs) == before
    info = run_cli("info", str(bad))
    assert info.status == 2
    assert_one_line_error(info.stderr, bad.name, words)


@pytest.mark.parametrize("case", list(CASES))
def test_readers_raise_log_error_only(tmp_path: Path, case: str) -> None:
    builder, _ = CASES[case]
    bad = builder(tmp_path)
    with pytest.raises(LogError) as info:
        read_log(bad)
    assert "\n" not in info.value.message()


def test_output_equal_to_input_is_refused(tmp_path: Path) -> None:
    src = write_log(_log(), tmp_path / "run.csv")
    before = src.read_bytes()
    for target in (str(src), str(tmp_path / "." / "run.csv")):
        result = run_cli("convert", str(src), target)
        assert result.status == 2
        assert_one_line_error(result.stderr, "run.csv", ("overwrite the input",))
    assert src.read_bytes() == before
    assert _listing(tmp_path) == ["run.csv"]


def test_output_equal_to_input_bag_folder_is_refused(tmp_path: Path) -> None:
    bag = write_log(_log(), tmp_path / "bag", options=WriteOptions(storage="sqlite3"))
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    result = run_cli("convert", str(bag), str(bag), "--format", "rosbag2")
    assert result.status == 2
    assert_one_line_error(result.stderr, "bag", ("overwrite the input",))
    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before


@pytest.mark.parametrize(
    ("header", "target", "words"),
    [
        ("t,q,tau,bad name", "out.mat", ("bad name", "MATLAB variable")),
        ("t,q,tau,t_s", "out.mcap", ("t_s", "reserved")),
        ("t,q,tau,t_s", "out.bag", ("t_s", "reserved")),
        ("t,q,tau,t_s", "out_bag", ("t_s", "reserved")),
    ],
)
def test_write_failure_leaves_nothing(tmp_path: Path, header: str, target: str, words: tuple[str, ...]) -> None:
    src = _csv(tmp_path / "in.csv", header, [f"{i * 0.001!r},{i * 0.1!r},{1.5 + i!r},{i!r}" for i in range(N)])
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    result = run_cli("convert", str(src), str(out_dir / target))
    assert result.status == 2
    assert_one_line_error(result.stderr, target, words)
    assert _listing(out_dir) == []


def test_missing_output_folder(tmp_path: Path) -> None:
    src = write_log(_log(), tmp_path / "run.csv")
    result = run_cli("convert", str(src), str(tmp_path / "nowhere" / "x.mcap"))
    assert result.status == 2
    assert_one_line_error(result.stderr, "x.mcap", ("does not exist",))


@pytest.mark.parametrize(
    ("name", "options"),
    [("f.mcap", None), ("f.bag", None), ("f.mat", None), ("f.csv", None), ("f_bag", WriteOptions(storage="sqlite3")), ("m_bag", WriteOptions(storage="mcap"))],
)
def test_mutated_files_never_escape_as_other_exceptions(tmp_path: Path, name: str, options: WriteOptions | None) -> None:
    """Truncations, bit flips and random bytes: either a valid log or a LogError, never a crash."""
    path = write_log(make_synthetic_log(samples=30), tmp_path / name, options=options)
    target = path if path.is_file() else next(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
    original = target.read_bytes()
    rng = random.Random(name)
    refused = 0
    for k in range(60):
        raw = bytearray(original)
        if k % 3 == 0:
            raw = raw[: rng.randrange(1, len(raw))]
        elif k % 3 == 1:
            raw[rng.randrange(len(raw))] ^= 1 << rng.randrange(8)
        else:
            i = rng.randrange(len(raw))
            raw[i : i + 8] = rng.randbytes(8)
        target.write_bytes(bytes(raw))
        try:
            read_log(path)
        except LogError as exc:
            refused += 1
            assert "\n" not in exc.message()
    assert refused >= 20  # every truncation at least is refused


def test_mcap_crc_is_what_refuses_an_uncompressed_flip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without compression only the chunk CRC can notice a flipped value byte."""
    from mcap.writer import CompressionType

    from ilic_cli.io import mcaplog

    monkeypatch.setattr(mcaplog, "_compression", lambda: CompressionType.NONE)
    good = write_log(_log(), tmp_path / "plain.mcap")
    raw = bytearray(good.read_bytes())
    q_bytes = struct.pack("<d", _log().channels["q"][20])
    at = raw.find(q_bytes)
    assert at > 0
    raw[at] ^= 0x01
    bad = tmp_path / "flipped_plain.mcap"
    bad.write_bytes(bytes(raw))
    with pytest.raises(LogError, match="CRC"):
        read_log(bad)
    shutil.copy(good, tmp_path / "copy.mcap")
    assert len(read_log(tmp_path / "copy.mcap")) == N


def test_existing_folder_is_never_replaced(tmp_path: Path) -> None:
    src = write_log(_log(), tmp_path / "run.csv")
    folder = tmp_path / "results"
    folder.mkdir()
    (folder / "keep.txt").write_text("precious")
    for extra in ([], ["--format", "mcap"]):
        result = run_cli("convert", str(src), str(folder), *extra)
        assert result.status == 2
        assert_one_line_error(result.stderr, "results", ("not a ROS 2 bag",))
    assert (folder / "keep.txt").read_text() == "precious"
    assert _listing(folder) == ["keep.txt"]
    # an existing bag folder is replaced like any output file
    bag = tmp_path / "bag"
    assert run_cli("convert", str(src), str(bag)).status == 0
    assert run_cli("convert", str(src), str(bag), "--storage", "mcap").status == 0
    assert sorted(p.name for p in bag.iterdir()) == ["bag.mcap", "metadata.yaml"]


def test_bag_folder_over_existing_file_is_refused(tmp_path: Path) -> None:
    src = write_log(_log(), tmp_path / "run.csv")
    (tmp_path / "plainfile").write_text("x")
    result = run_cli("convert", str(src), str(tmp_path / "plainfile"), "--format", "rosbag2")
    assert result.status == 2
    assert_one_line_error(result.stderr, "plainfile", ("is a folder",))
    assert (tmp_path / "plainfile").read_text() == "x"


@pytest.mark.parametrize("target", ["out.mcap", "out_bag"])
def test_interrupted_bulk_write_stops_its_threads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, target: str) -> None:
    # A signal inside the bulk MCAP writer (also the ROS 2 bag's storage) must stop the chunk-compressing
    # threads: a worker the pool never registered would otherwise keep the process alive at exit.
    import threading

    import ilic_cli.io.mcapframe as mcapframe
    import ilic_cli.io.mcaplog as mcaplog

    real = mcaplog.add_samples

    def interrupted(writer: mcapframe.BulkWriter, *args: object) -> None:
        real(writer, *args)  # type: ignore[arg-type]
        writer._finish_chunk()  # a chunk in the pool for certain
        assert writer.pool is not None
        raise KeyboardInterrupt

    monkeypatch.setattr(mcaplog, "add_samples", interrupted)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(KeyboardInterrupt) as caught:  # held, as the CLI holds it while it reports
        write_log(make_synthetic_log(samples=5000), out_dir / target, options=WriteOptions(storage="mcap"))
    for thread in threading.enumerate():
        if thread.name.startswith("mcap-chunk"):
            thread.join(timeout=5)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("mcap-chunk")]
    assert _listing(out_dir) == []
    assert caught.traceback
