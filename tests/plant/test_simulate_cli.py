"""``ilic simulate`` and ``ilic replay``: logs, metadata, determinism and the error contract."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import read_log
from tests.clirun import run_cli


def test_simulate_writes_readable_log_with_metadata(tmp_path: Path) -> None:
    out = tmp_path / "sim.mcap"
    res = run_cli(
        "simulate",
        "--scenario",
        "paper-sim",
        "--duration",
        "13",
        "--seed",
        "3",
        "-o",
        str(out),
        "--param",
        "M=90",
        "--effect",
        "stribeck:Fs=2,vs=0.02",
        "--noise-tau",
        "0.1",
    )
    assert res.status == 0, res.stderr
    assert res.stdout == ""
    log = read_log(out)
    for ch in ("t", "q", "q_ref", "qd_ref", "qdd_ref", "tau", "M_hat", "Fv_hat", "Fc_hat", "qd_plant", "qdd_plant"):
        assert ch in log, ch
    assert log.units["qdd_plant"] == "m/s^2"
    assert len(log) == 13000
    m = log.meta
    assert m["scenario"]["name"] == "paper-sim"
    assert m["true_parameters"]["M"] == 90.0
    assert m["effects"]["stribeck"] == {"Fs": 2.0, "vs": 0.02}
    assert m["effects"]["noise"]["tau_std"] == 0.1
    assert m["controller"]["kind"] == "ctc" and m["controller"]["alpha"] == 1000.0 and m["controller"]["velocity"] == "backward"
    assert m["simulation"]["seed"] == 3 and m["simulation"]["substeps"] == 10
    assert m["simulation"]["dt"] == pytest.approx(1e-4)
    assert len(m["ilic_windows"]) == 2


def test_simulate_is_bit_identical(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    args = ("simulate", "--scenario", "paper-payload", "--duration", "7", "--seed", "5", "--noise-tau", "0.5", "--noise-q", "1e-7")
    assert run_cli(*args, "-o", str(a)).status == 0
    assert run_cli(*args, "-o", str(b)).status == 0
    assert a.read_bytes() == b.read_bytes()
    c = tmp_path / "c.mcap"
    assert run_cli(*args[:-4], "--seed", "6", "--noise-tau", "0.5", "-o", str(c)).status == 0
    assert a.read_bytes() != c.read_bytes()


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("--scenario", "nope"), "--scenario: scenario = 'nope' must be one of paper-sim"),
        (("--param", "M"), "expected NAME=VALUE"),
        (("--param", "M=abc"), "not a number"),
        (("--param", "Q=1"), "--param: parameter = 'Q' must be a rigid parameter (M, Fv, Fc, offset)"),
        (("--param", "M=-5"), "--param: M = -5 must be > 0"),
        (("--effect", "warp:x=1"), "unknown effect"),
        (("--effect", "stribeck:Fz=1"), "--effect: stribeck.Fz = 1 must be a parameter of 'stribeck' (Fs, vs)"),
        (("--substeps", "0"), "--substeps"),
        (("--duration", "-1"), "--duration"),
        (("--controller", "pd", "--omega", "3"), "do not apply"),
        (("--controller", "pd", "--velocity", "exact"), "do not apply"),
        (("--velocity", "forward"), "--velocity"),
        (("--published-setup",), "emps-benchmark replay only"),
        (("--scenario", "emps-benchmark", "--log", "/nonexistent/x.mat"), "not found"),
    ],
)
def test_simulate_bad_values_exit_2_one_line(tmp_path: Path, args: tuple[str, ...], needle: str) -> None:
    out = tmp_path / "x.mcap"
    res = run_cli("simulate", "--duration", "1", *args, "-o", str(out)) if "--duration" not in args else run_cli("simulate", *args, "-o", str(out))
    assert res.status == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ilic: error:"), res.stderr
    assert needle in lines[0]
    assert not out.exists()


def test_replay_with_model_file(tmp_path: Path) -> None:
    src = tmp_path / "src.mcap"
    assert run_cli("simulate", "--scenario", "paper-sim", "--duration", "7", "-o", str(src), "--param", "M=95").status == 0
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"ilic_model": 1, "model": "rigid", "parameters": {"M": 95.0, "Fv": 200.0, "Fc": 20.0}, "effects": {}}))
    out = tmp_path / "replay.mcap"
    res = run_cli("replay", str(src), "--model", str(model), "-o", str(out))
    assert res.status == 0, res.stderr
    orig, rep = read_log(src), read_log(out)
    # same plant, same logged controller parameters: the replay reproduces the run
    np.testing.assert_allclose(rep["q"], orig["q"], atol=1e-12)
    np.testing.assert_allclose(rep["tau"], orig["tau"], atol=1e-6)
    assert rep.meta["replay_of"] == str(src)
    # a different model gives a different run
    model.write_text(json.dumps({"parameters": {"M": 90.0, "Fv": 180.0, "Fc": 20.0}, "effects": {"spring": {"k": 100.0, "q0": 0.1}}}))
    out2 = tmp_path / "replay2.mcap"
    assert run_cli("replay", str(src), "--model", str(model), "-o", str(out2)).status == 0
    assert np.abs(read_log(out2)["q"] - orig["q"]).max() > 1e-7
    assert read_log(out2).meta["effects"]["spring"]["k"] == 100.0


def test_replay_keeps_the_logged_velocity_estimate(tmp_path: Path) -> None:
    src, out = tmp_path / "src.mcap", tmp_path / "replay.mcap"
    assert run_cli("simulate", "--duration", "7", "--velocity", "exact", "-o", str(src)).status == 0
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"parameters": {"M": 95.0, "Fv": 200.0, "Fc": 20.0}, "effects": {}}))
    res = run_cli("replay", str(src), "--model", str(model), "-o", str(out))
    assert res.status == 0, res.stderr
    orig, rep = read_log(src), read_log(out)
    assert rep.meta["controller"]["velocity"] == "exact"
    np.testing.assert_allclose(rep["q"], orig["q"], atol=1e-12)


def test_replay_refuses_output_over_input_and_bad_model(tmp_path: Path) -> None:
    src = tmp_path / "src.mcap"
    assert run_cli("simulate", "--duration", "1", "-o", str(src)).status == 0
    model = tmp_path / "m.json"
    model.write_text(json.dumps({"M": 95.0, "Fv": 200.0, "Fc": 20.0}))
    before = src.read_bytes()
    res = run_cli("replay", str(src), "--model", str(model), "-o", str(src))
    assert res.status == 2 and "overwrite the input" in res.stderr
    assert src.read_bytes() == before
    model.write_text(json.dumps({"parameters": {"M": 95.0, "Fv": 200.0, "Fc": 20.0}, "effects": {"warp": {}}}))
    res = run_cli("replay", str(src), "--model", str(model), "-o", str(tmp_path / "o.mcap"))
    assert res.status == 2 and "m.json: effect = 'warp' must be one of asymmetric_friction" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_emps_benchmark_scenario(tmp_path: Path) -> None:
    from tests.conftest import require_shared

    folder = require_shared()
    out = tmp_path / "emps.mcap"
    res = run_cli("simulate", "--scenario", "emps-benchmark", "--log", str(folder / "DATA_EMPS_PULSES.mat"), "--duration", "2", "-o", str(out))
    assert res.status == 0, res.stderr
    log = read_log(out)
    assert {"vir", "pulses", "q_ref"} <= set(log.channels)
    assert log.meta["controller"]["kind"] == "pd" and log.meta["controller"]["kp"] == 160.18
    assert log.meta["drive_gain"] == pytest.approx(35.15065188, rel=1e-8)
    assert log.meta["true_parameters"]["offset"] == -3.1648
    assert len(log) == 2001


def test_help_is_quick_and_lists_options() -> None:
    res = run_cli("simulate", "--help")
    assert res.status == 0 and "--scenario" in res.stdout and "--effect" in res.stdout


def test_emps_benchmark_published_setup(tmp_path: Path) -> None:
    from ilic_cli.io import write_log
    from tests.conftest import make_synthetic_log

    ref = tmp_path / "ref.csv"
    log = make_synthetic_log()
    write_log(log, ref)
    out = tmp_path / "pub.mcap"
    res = run_cli("simulate", "--scenario", "emps-benchmark", "--log", str(ref), "--published-setup", "-o", str(out))
    assert res.status == 0, res.stderr
    sim = read_log(out)
    setup = sim.meta["scenario"]["published_setup"]
    assert setup["pulse_input"] == "ramp" and sim.meta["controller"]["pulse_input"] == "ramp"
    assert setup["clock_s"] == pytest.approx(float(read_log(ref).t[9] - read_log(ref).t[8]), rel=1e-12)


def test_simulate_refuses_to_write_over_the_replayed_log(tmp_path: Path) -> None:
    from ilic_cli.io import write_log
    from tests.conftest import make_synthetic_log

    ref = tmp_path / "ref.csv"
    write_log(make_synthetic_log(), ref)
    before = ref.read_bytes()
    res = run_cli("simulate", "--scenario", "emps-benchmark", "--log", str(ref), "-o", str(ref))
    assert res.status == 2
    assert res.stderr.strip() == f"ilic: error: {ref}: output would overwrite the replayed log; choose another output path"
    assert ref.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ref.csv"]
