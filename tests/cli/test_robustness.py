"""Robustness across commands: the error contract, inputs never overwritten, data-quality
warnings and saturation masking in identification, hostile files, no code execution,
progress bars only on a terminal.

Per-format bad inputs for ``convert``/``info`` live in ``tests/io/test_io_errors.py``;
here the same builders are run through every other command that reads a log.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
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
from tests.identify.test_identify_cli import TRUE, synthetic
from tests.io.test_io_errors import CASES, assert_one_line_error

ROOT = Path(__file__).parents[2]
MODEL = {"ilic_model": 1, "model": "rigid-offset", "parameters": {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0}}


def _model_file(folder: Path) -> Path:
    path = folder / "model.json"
    path.write_text(json.dumps(MODEL), encoding="utf-8")
    return path


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# -- 1. error contract over every command that reads a log -----------------------
# command -> argv builder (bad log path, scratch folder for outputs)
READERS: dict[str, Callable[[Path, Path], list[str]]] = {
    "identify": lambda log, d: ["identify", str(log)],
    "identify --out": lambda log, d: ["identify", str(log), "--out", str(d / "report")],
    "replay": lambda log, d: ["replay", str(log), "--model", str(_model_file(d)), "-o", str(d / "replayed.mcap")],
    "diagnose": lambda log, d: ["diagnose", str(log), "--no-simulation"],
}
BAD_INPUTS = [
    "missing file",
    "empty file",
    "truncated mcap",
    "not an mcap",
    "truncated bag",
    "rosbag2 without metadata",
    "NaN sample",
    "text in numeric column",
    "mat 2-D qm",
    "not a mat file",
]


@pytest.mark.parametrize("case", BAD_INPUTS)
@pytest.mark.parametrize("command", list(READERS))
def test_every_reading_command_refuses_bad_input_in_one_line(tmp_path: Path, command: str, case: str) -> None:
    inputs, scratch = tmp_path / "in", tmp_path / "scratch"
    inputs.mkdir()
    scratch.mkdir()
    builder, words = CASES[case]
    bad = builder(inputs)
    args = READERS[command](bad, scratch)
    before = _listing(scratch)
    res = run_cli(*args)
    assert res.status == 2, (command, case, res)
    assert_one_line_error(res.stderr, bad.name, words)
    assert res.stdout == ""
    assert _listing(scratch) == before  # nothing written, no temporary left


# bad usage: wrong option values, unknown options, missing arguments
USAGE = [
    ["info"],
    ["info", "x.mcap", "--format", "yaml"],
    ["convert", "only-one.mcap"],
    ["convert", "a.mcap", "b.mcap", "--resample", "-5"],
    ["identify", "x.mcap", "--method", "magic"],
    ["identify", "x.mcap", "--window", "0"],
    ["identify", "x.mcap", "--no-such-option"],
    ["simulate"],
    ["simulate", "-o", "x.mcap", "--seed", "abc"],
    ["replay", "x.mcap"],
    ["replay", "x.mcap", "--model", "m.json", "-o", "y.mcap", "--substeps", "zero"],
    ["diagnose"],
    ["diagnose", "x.mcap", "--alpha", "2"],
    ["nonexistent-command"],
]


@pytest.mark.parametrize("args", USAGE, ids=[" ".join(a) for a in USAGE])
def test_bad_usage_is_one_line_exit_2(args: list[str]) -> None:
    res = run_cli(*args)
    assert res.status == 2, res
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilic: error: "), res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""


def _good_log(folder: Path) -> Path:
    return write_log(make_synthetic_log(samples=2000), folder / "good.csv")


# command -> (argv for a good log, dotted function the command reaches, made to fail)
INTERNAL: dict[str, tuple[Callable[[Path, Path], list[str]], str]] = {
    "info": (lambda log, d: ["info", str(log)], "ilic_cli.quality.assess_log"),  # imported by the command at call time
    "convert": (lambda log, d: ["convert", str(log), str(d / "out.mcap")], "ilic_cli.commands.convert.write_log"),
    "identify": (lambda log, d: ["identify", str(log)], "ilic_cli.commands.identify.identify_with"),
    "simulate": (
        lambda log, d: ["simulate", "--scenario", "paper-sim", "--duration", "1", "-o", str(d / "sim.mcap")],
        "ilic_cli.commands.simulate.run_scenario",
    ),
    "replay": (lambda log, d: ["replay", str(log), "--model", str(_model_file(d)), "-o", str(d / "replay.mcap")], "ilic_cli.commands.common.read_log"),
    "diagnose": (lambda log, d: ["diagnose", str(log)], "ilic_cli.commands.common.read_log"),
}
"""Command -> (arguments, the name the command module calls, patched there to fail)."""


@pytest.mark.parametrize("command", list(INTERNAL))
def test_internal_failure_is_exit_1_one_line_traceback_only_with_debug(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, command: str) -> None:
    import importlib

    build, target = INTERNAL[command]
    module_name, func = target.rsplit(".", 1)
    module = importlib.import_module(module_name)

    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(module, func, boom)
    log = _good_log(tmp_path)
    args = build(log, tmp_path)
    res = run_cli(*args)
    assert res.status == 1, res
    lines = [line for line in res.stderr.splitlines() if not line.startswith(("ilic: warning:", "ilic: simulating", "ilic: replaying"))]
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("ilic: error: internal error: RuntimeError: simulated bug")
    assert "--debug" in lines[0] and "Traceback" not in res.stderr
    debug = run_cli("--debug", *args)
    assert debug.status == 1
    assert "Traceback (most recent call last)" in debug.stderr and "RuntimeError: simulated bug" in debug.stderr


# -- 2. inputs are never overwritten -------------------------------------------------
def test_replay_refuses_output_over_its_input(tmp_path: Path) -> None:
    log = write_log(make_synthetic_log(samples=500), tmp_path / "run.mcap")
    before = log.read_bytes()
    res = run_cli("replay", str(log), "--model", str(_model_file(tmp_path)), "-o", str(log))
    assert res.status == 2, res
    assert_one_line_error(res.stderr, "run.mcap", ("overwrite the input",))
    assert log.read_bytes() == before


@pytest.mark.parametrize("name", ["report.csv", "report.json"])
def test_identify_out_refuses_to_overwrite_its_input_and_writes_nothing(tmp_path: Path, name: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    log = out / name
    write_log(synthetic(duration_s=13.0), out / "run.csv").rename(log)
    before = log.read_bytes()
    res = run_cli("identify", str(log), "--out", str(out), "--plots", "none", "--input-format", "csv")
    assert res.status == 2, res
    assert "overwrite the input" in res.stderr and res.stderr.count("\n") == 1
    assert log.read_bytes() == before
    assert _listing(out) == [name]  # no report written next to it


# -- 3. data quality before identification; saturation masking ---------------------
def test_identify_reports_quality_warnings(tmp_path: Path) -> None:
    log = synthetic(duration_s=13.0)
    keep = np.ones(len(log), dtype=bool)
    keep[5000:5040] = False  # a 40 ms gap
    gapped = RunLog({k: v[keep] for k, v in log.channels.items()}, meta=dict(log.meta))
    path = write_log(gapped, tmp_path / "gap.csv")
    res = run_cli("identify", str(path), "--format", "json")
    assert res.status == 0, res.stderr
    warnings = [line for line in res.stderr.splitlines() if line.startswith("ilic: warning: ")]
    assert any("data quality" in w and "gap" in w for w in warnings), res.stderr
    assert any("gap" in w for w in json.loads(res.stdout)["warnings"])


def test_identify_short_log_is_a_clear_error(tmp_path: Path) -> None:
    path = write_log(synthetic(duration_s=0.08), tmp_path / "tiny.csv")
    res = run_cli("identify", str(path), "--method", "ls")
    assert res.status == 2
    assert_one_line_error(res.stderr, "tiny.csv", ("too few samples",))


def _saturated(limit: float = 1.8) -> RunLog:
    """The synthetic run with the logged drive command clipped at +/-limit V.

    The motion follows the true force; the logged force (gain x command) is the
    clipped value, as when the command is recorded after its limiter.
    """
    log = synthetic(duration_s=18.6, seed=0)
    gain = 35.0
    vir = np.clip(log["tau"] / gain, -limit, limit)
    out = log.with_channels(vir=vir, tau=gain * vir)
    out.meta["drive_gain"] = gain
    return out


def test_saturated_samples_are_masked_with_a_warning(tmp_path: Path) -> None:
    log = _saturated()
    path = write_log(log, tmp_path / "saturated.mcap")
    res = run_cli("identify", str(path), "--format", "json")
    assert res.status == 0, res.stderr
    warnings = [line for line in res.stderr.splitlines() if line.startswith("ilic: warning: ")]
    masked = [w for w in warnings if "saturated drive:" in w]
    assert len(masked) == 1, res.stderr
    assert re.search(r"1\d\.\d+ % of the samples masked", masked[0]), masked[0]
    assert "IDIM-LS uses" in masked[0] and "IDIM-ILIC rows masked in 3 of 3" in masked[0]
    assert any("saturated at +/-1.8" in w for w in warnings)
    doc = json.loads(res.stdout)
    for name in ("M", "Fv", "Fc", "offset"):
        assert doc["ls"]["parameters"][name]["value"] == pytest.approx(TRUE[name], rel=0.02), name
        for w in doc["ilic"]["windows"]:
            assert w["parameters"][name]["value"] == pytest.approx(TRUE[name], rel=0.01), (name, w["k"])
    # without the mask the same data give biased estimates
    from ilic_cli.idim_ilic import ILICSettings, identify_ilic
    from ilic_cli.idim_ls import idim_ls
    from ilic_cli.regressor import get_model

    model = get_model("rigid-offset")
    biased_ls = dict(zip(model.names, idim_ls(log.t, log["q"], log["tau"], 1000.0, model).result.theta, strict=True))
    biased_ilic = identify_ilic(log.t, log["q_ref"], log["tau"], 1000.0, model, ILICSettings(), qd_ref=log["qd_ref"], qdd_ref=log["qdd_ref"], q=log["q"])
    assert abs(biased_ls["Fv"] / TRUE["Fv"] - 1) > 0.05
    assert abs(biased_ilic.windows[0].result.theta[1] / TRUE["Fv"] - 1) > 0.05


def test_a_declared_pd_loop_s_clipped_force_is_masked_without_a_vir_channel(tmp_path: Path) -> None:
    """A log without ``vir`` whose PD loop and drive gain are declared (``--controller pd --drive-gain``): its force is the
    drive's command, whose plateau at the limit is masked and said, as with ``vir`` (the same rows and estimates); ``info``
    reports it too."""
    from ilic_cli.identify import identify

    sat = _saturated()
    pd = {**sat.meta, "controller": {"kind": "pd", "kp": 10.0, "kv": 50.0}}
    with_vir = RunLog(dict(sat.channels), dict(sat.units), pd)
    without = RunLog({k: v for k, v in sat.channels.items() if k != "vir"}, {k: u for k, u in sat.units.items() if k != "vir"}, pd)
    a, b = identify(without, method="ls"), identify(with_vir, method="ls")
    assert a.ls is not None and b.ls is not None
    assert np.array_equal(a.ls.result.theta, b.ls.result.theta) and a.ls.result.rows == b.ls.result.rows
    assert any("saturated at +/-1.8" in w for w in a.warnings) and any("of the samples masked" in w for w in a.warnings), a.warnings
    res = run_cli("info", str(write_log(without, tmp_path / "pd.mcap")), "--format", "json")  # the loop in the file's metadata
    assert res.status == 0, res.stderr
    assert json.loads(res.stdout)["quality"]["saturation_limit"] == pytest.approx(1.8)


def test_saturated_validation_log_is_masked_too() -> None:
    """``--validate`` applies the estimates to the other log with its saturated samples masked (and says so)."""
    from ilic_cli.identify import identify

    clean = synthetic(duration_s=13.0)
    sat = _saturated()
    sat.meta["source"] = "sat.mcap"
    report = identify(clean, method="ls", validate=[sat])
    assert any(w.startswith("validation log sat.mcap: saturated drive:") and "% of the samples masked" in w for w in report.warnings), report.warnings
    assert any(w.startswith("validation log sat.mcap:") and "saturated at +/-1.8" in w for w in report.warnings), report.warnings
    masked = report.validation[0].result
    from ilic_cli.idim_ls import cross_validate
    from ilic_cli.regressor import get_model

    unmasked = cross_validate(report.ls.result.theta, sat.t, sat["q"], sat["tau"], 1000.0, get_model("rigid-offset"))
    assert masked.rows < unmasked.rows
    rms = lambda r: r.error_norm / np.sqrt(r.rows)  # noqa: E731
    assert rms(masked) < 0.75 * rms(unmasked)  # the clipped force is not held against the model (1.75 vs 2.68 N)


def test_no_saturation_means_no_mask_and_identical_results() -> None:
    from ilic_cli.identify import identify
    from ilic_cli.idim_ls import idim_ls
    from ilic_cli.regressor import get_model

    log = synthetic(duration_s=13.0)
    report = identify(log, method="ls")
    plain = idim_ls(log.t, log["q"], log["tau"], 1000.0, get_model("rigid-offset"))
    assert np.array_equal(report.ls.result.theta, plain.result.theta)
    assert np.array_equal(report.ls.result.std, plain.result.std)
    assert not any("saturated" in w for w in report.warnings)
    every = idim_ls(log.t, log["q"], log["tau"], 1000.0, get_model("rigid-offset"), valid=np.ones(len(log), dtype=bool))
    assert np.array_equal(every.result.theta, plain.result.theta)


def test_valid_rows_drop_the_span_of_an_invalid_sample() -> None:
    from ilic_cli.filtering import kept_indices
    from ilic_cli.row_spans import valid_rows

    n, r = 100, 10
    valid = np.ones(n, dtype=bool)
    valid[45] = False
    rows = valid_rows(valid, r)
    kept = kept_indices(n, r)
    assert list(kept[~rows]) == [39, 49]  # the kept samples within r - 1 of sample 45
    batch = valid_rows(np.stack([valid, np.ones(n, dtype=bool)]), r)
    assert np.array_equal(batch[0], rows) and batch[1].all()


# -- 4. hostile files -------------------------------------------------------------------
def _refused(path: Path, *words: str) -> None:
    with pytest.raises(LogError) as info:
        read_log(path)
    message = info.value.message()
    assert "\n" not in message and path.name in message
    for word in words:
        assert word in message, message
    res = run_cli("info", str(path))
    assert res.status == 2
    assert_one_line_error(res.stderr, path.name, words)


def test_ros1_bag_with_garbage_message_definition(tmp_path: Path) -> None:
    good = write_log(make_synthetic_log(samples=50), tmp_path / "good.bag")
    raw = bytearray(good.read_bytes())
    # connection records carry message_definition=... and md5sum=...; garble both (same lengths)
    for key in (b"message_definition=", b"md5sum="):
        at = raw.find(key)
        while at >= 0:
            start = at + len(key)
            for i in range(start, min(start + 32, len(raw))):
                raw[i] = 0x7E  # '~'
            at = raw.find(key, start)
    bad = tmp_path / "garbled.bag"
    bad.write_bytes(bytes(raw))
    _refused(bad)


def test_ros2_bag_metadata_with_bogus_type(tmp_path: Path) -> None:
    bag = write_log(make_synthetic_log(samples=50), tmp_path / "bogus_bag", options=WriteOptions(storage="sqlite3"))
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("sensor_msgs/msg/JointState", "evil_pkg/msg/__import__('os').system('true')"))
    _refused(bag)


def test_ros2_bag_metadata_that_is_not_yaml_mapping(tmp_path: Path) -> None:
    bag = write_log(make_synthetic_log(samples=50), tmp_path / "yaml_bag", options=WriteOptions(storage="sqlite3"))
    (bag / "metadata.yaml").write_text("!!python/object/apply:os.system ['echo pwned > pwned.txt']\n")
    _refused(bag, "ROS 2 bag")
    assert not (Path.cwd() / "pwned.txt").exists()


def _mat_with(path: Path, **variables: object) -> Path:
    n = 40
    t = np.arange(n, dtype=float).reshape(-1, 1) * 1e-3
    base: dict[str, object] = {"t": t, "qm": t * 2, "vir": t + 1, "gtau": np.array([[35.0]])}
    base.update(variables)
    scipy.io.savemat(path, base)
    return path


@pytest.mark.parametrize(
    ("name", "variables", "words"),
    [
        ("struct_qm.mat", {"qm": {"a": 1.0}}, ("'qm'", "cell array or struct")),
        ("cell_t.mat", {"t": np.array([[1.0], ["x"]], dtype=object)}, ("'t'",)),
        ("complex_vir.mat", {"vir": np.ones((40, 1)) * (1 + 2j)}, ("'vir'",)),
        ("cube_qm.mat", {"qm": np.ones((40, 2, 2))}, ("'qm'", "column vector")),
        ("empty_qm.mat", {"qm": np.zeros((0, 1))}, ("'qm'",)),
        ("text_gain.mat", {"gtau": "35"}, ("'gtau'", "scalar")),
        ("inf_gain.mat", {"gtau": np.array([[np.inf]])}, ("'gtau'", "not finite")),
        ("bool_t.mat", {"t": np.ones((40, 1), dtype=bool)}, ("duplicated timestamps",)),
        ("meta_not_json.mat", {"ilic_meta": "{not json", "ilic_units": "{}"}, ("ilic_meta", "JSON")),
        ("units_not_object.mat", {"ilic_units": "[1, 2]"}, ("ilic_units",)),
    ],
)
def test_mat_with_wrong_shapes_and_types(tmp_path: Path, name: str, variables: dict[str, object], words: tuple[str, ...]) -> None:
    _refused(_mat_with(tmp_path / name, **variables), *words)


def test_csv_hostile_text(tmp_path: Path) -> None:
    path = tmp_path / "hostile.csv"
    path.write_text("t,q,tau\n0,0,0\n0.001,__import__('os'),1\n", encoding="utf-8")
    _refused(path, "line 3", "column 'q'", "is not a number")
    latin = tmp_path / "latin.csv"
    latin.write_bytes(b"t,q,tau\n0,0,\xff\n")
    _refused(latin, "UTF-8")


def test_mcap_chunk_that_expands_beyond_the_limit_is_refused_before_decompression(tmp_path: Path) -> None:
    """A zstd chunk of 256 MiB of zeros with an honest size: refused from its header, no allocation."""
    import zstandard
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "bomb.mcap"
    payload = bytes(2**20)  # 1 MiB of zeros, 256 messages
    with open(path, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD, chunk_size=2**29)
        writer.start("ros2", "bomb")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = writer.register_channel("/junk", "cdr", schema)
        for i in range(256):
            writer.add_message(channel, log_time=i, publish_time=i, data=payload)
        writer.finish()
    assert path.stat().st_size < 2**20  # 256 MiB of content in a small file
    assert zstandard is not None
    _refused(path, "declares", "limit")


def test_ros1_chunk_that_expands_beyond_the_limit_is_refused(tmp_path: Path) -> None:
    from rosbags.rosbag1 import Writer

    from ilic_cli.io import rosschema

    ts = rosschema.typestore("ros1")
    string = ts.types["std_msgs/msg/String"]
    path = tmp_path / "bomb.bag"
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.LZ4)
    with writer:
        conn = writer.add_connection("/junk", "std_msgs/msg/String", typestore=ts)
        writer.write(conn, 1, bytes(ts.serialize_ros1(string(data="a" * 64 * 2**20), "std_msgs/msg/String")))
    assert path.stat().st_size < 2**20
    _refused(path, "decompresses to more than")


def test_mcap_channel_with_unknown_encoding_is_named(tmp_path: Path) -> None:
    from mcap.writer import Writer

    path = tmp_path / "json.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start("", "other")
        schema = writer.register_schema("sensor_msgs/msg/JointState", "jsonschema", b"{}")
        channel = writer.register_channel("/joint_states", "json", schema)
        writer.add_message(channel, log_time=1, publish_time=1, data=b'{"position": [1]}')
        writer.finish()
    _refused(path, "encoding 'json'")


def test_no_reader_executes_file_content() -> None:
    """No pickle, eval, exec or unsafe YAML anywhere in the package; .mat via loadmat only."""
    forbidden = re.compile(
        r"\b(pickle|cPickle|marshal|shelve|eval|exec|(?<!re\.)compile|__import__|yaml\.load|yaml\.unsafe_load|yaml\.full_load|"
        r"get_types_from_msg|get_types_from_idl)\s*\(|import pickle|numpy\.load|np\.load\("
    )
    hits = []
    for path in sorted((ROOT / "ilic_cli").rglob("*.py")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            code = line.split("#", 1)[0]
            if forbidden.search(code):
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert hits == []
    # scipy.io.loadmat reads MATLAB objects as plain structured arrays (never unpickles them);
    # the reader refuses anything that is not a numeric vector, scalar or text.
    mat_source = (ROOT / "ilic_cli" / "io" / "mat.py").read_text(encoding="utf-8")
    assert "scipy.io.loadmat(" in mat_source and "allow_pickle" not in mat_source


def test_mat_object_and_function_classes_are_refused_not_run(tmp_path: Path) -> None:
    """A MATLAB object variable (mxOBJECT_CLASS) comes back as data and is refused."""
    from scipy.io.matlab import MatlabObject

    obj = MatlabObject(np.array([(1.0,)], dtype=[("x", object)]), "containers.Map")
    path = _mat_with(tmp_path / "object.mat", qm=obj)
    _refused(path, "'qm'")


# -- 5. progress bars: only on a terminal, never when piped or in CI --------------------
def test_piped_output_has_no_progress_bar(tmp_path: Path) -> None:
    path = write_log(make_synthetic_log(samples=3000), tmp_path / "run.mcap")
    env = {k: v for k, v in __import__("os").environ.items() if k != "CI"}
    code = "import ilic_cli.commands.common as c; c.PROGRESS_MIN_BYTES = 0; from ilic_cli.cli import main; main()"
    for args in (["info", str(path)], ["convert", str(path), str(tmp_path / "out.csv")]):
        res = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
        assert res.returncode == 0, res.stderr
        for stream in (res.stdout, res.stderr):
            assert "\r" not in stream and "reading run.mcap" not in stream and "[#" not in stream


def test_progress_bar_on_a_terminal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from ilic_cli.commands import common

    path = write_log(make_synthetic_log(samples=3000), tmp_path / "run.mcap")
    monkeypatch.setattr(common, "PROGRESS_MIN_BYTES", 0)
    monkeypatch.setattr(common, "progress_enabled", lambda: True)
    res = run_cli("info", str(path))
    assert res.status == 0
    assert "\r  reading run.mcap [" in res.stderr and "100 %" in res.stderr
    assert "\r" not in res.stdout


def test_progress_is_disabled_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    from ilic_cli.commands import common

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    monkeypatch.setenv("CI", "1")
    assert common.progress_enabled() is False
    monkeypatch.delenv("CI")
    assert common.progress_enabled() is True


def test_reader_keeps_no_python_object_per_message(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Decoded columns are NumPy blocks: memory per message stays near the values' size."""
    import tracemalloc

    from ilic_cli.io import roscollect

    monkeypatch.setattr(roscollect, "BLOCK", 1000)

    path = write_log(make_synthetic_log(samples=20000), tmp_path / "run.mcap")
    read_log(path)  # warm up imports and type stores
    tracemalloc.start()
    log = read_log(path)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    per_sample = peak / len(log)
    assert per_sample < 600, per_sample  # 9 channels x 8 bytes plus columns; was over 2 kB


def test_a_bad_thread_count_is_one_line_exit_2(monkeypatch: pytest.MonkeyPatch) -> None:
    """``ILIC_THREADS`` (``ilic_cli/parallel.py``) is checked before any work, in the error contract."""
    monkeypatch.setenv("ILIC_THREADS", "many")
    res = run_cli("info", "x.mcap")
    assert res.status == 2 and res.stdout == "", res
    assert res.stderr == "ilic: error: ILIC_THREADS = 'many' must be a whole number of threads, at least 1\n"
    for asked in (["--help"], ["diagnose", "-h"], ["--version"]):  # help is no work: answered all the same
        res = run_cli(*asked)
        assert res.status == 0 and res.stderr == "" and ("Usage: ilic" in res.stdout or "ilic, version" in res.stdout), (asked, res)


def test_a_log_whose_drive_saturates_on_most_rows_is_refused_with_what_left_them_out(tmp_path: Path) -> None:
    """A chirp whose flexible load makes the drive saturate on 36 % of its samples (robot corpus, lin12 500 Hz, seed 12260): 794 of
    its 826 decimated rows touch the limit. ``diagnose`` refuses before any replay and says what left the rows out; it said
    "after leaving out standstill" before, which left out 5 of them (the rows per column, and each count, planted wrong: fails)."""
    import dataclasses

    from ilic_cli.usable import MIN_ROWS_PER_COLUMN
    from tests.corpus.measure import controller_flags, write_csv
    from tests.corpus.robot import build, case_named

    case = case_named("lin12/chirp/500Hz/sensor/flexibility/s260")
    case = dataclasses.replace(case, seed=12260)
    path = write_csv(build(case), tmp_path / "saturating.csv")
    res = run_cli("diagnose", str(path), *controller_flags(case))
    assert res.status == 2 and res.stdout == ""
    assert_one_line_error(res.stderr, "saturating.csv", ("only 16 of 826 decimated rows to fit",))
    assert "794 touch a saturated drive, 5 a sample at rest, 11 more a velocity reversal" in res.stderr, res.stderr
    assert "too few for 4 parameters" in res.stderr and 16 <= MIN_ROWS_PER_COLUMN * 4
