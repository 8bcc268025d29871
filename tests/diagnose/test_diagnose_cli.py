"""``ilic diagnose`` command line: output contract, model file round trip, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.diagnosis.null import REPLAY_ALPHA
from ilic_cli.io import write_log
from ilic_cli.modelfile import load_model_file
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli
from tests.conftest import import_or_skip

import_or_skip("plant.closed_loop")
from tests.diagnose.test_diagnose_effects import simulated_log  # noqa: E402


@pytest.fixture(scope="module")
def ripple_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log, _ = simulated_log({"position_ripple": {"A": 1.5, "L": 0.012, "phase": -1.0}}, seed=21, traj_seed=31, duration_s=12.4)
    path = tmp_path_factory.mktemp("logs") / "ripple.csv"
    write_log(log, path)
    return path


def test_json_stdout_only_and_model_file_round_trip(ripple_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    r = run_cli("diagnose", str(ripple_log), "--format", "json", "--out", str(out), "--no-simulation")
    assert r.status == 0, r.stderr
    doc = json.loads(r.stdout)  # nothing but the document on stdout
    assert [f["effect"] for f in doc["findings"]] == ["position_ripple"]
    f = doc["findings"][0]
    assert {"effect", "explanation", "parameters", "located", "evidence"} <= set(f)
    assert f["parameters"]["L"]["value"] == pytest.approx(0.012, rel=0.15)
    assert {"value", "std"} <= set(f["parameters"]["A"])
    assert f["evidence"]["p_adjusted"] < 1e-3
    assert doc["replay_sensor_noise"] is None  # nothing was replayed
    model = load_model_file(out / "model.json")
    assert set(model["effects"]) == {"position_ripple"}
    assert model["effects"]["position_ripple"]["A"] == pytest.approx(1.5, rel=0.15)
    # the written model is accepted back: diagnosing from it finds nothing more
    r2 = run_cli("diagnose", str(ripple_log), "--model", str(out / "model.json"), "--format", "json", "--no-simulation")
    assert r2.status == 0, r2.stderr
    assert json.loads(r2.stdout)["findings"] == []


def test_markdown_in_plain_words(ripple_log: Path) -> None:
    r = run_cli("diagnose", str(ripple_log), "--no-simulation")
    assert r.status == 0, r.stderr
    assert "Left out: position-dependent force ripple" in r.stdout
    assert "Relative force error" in r.stdout


def test_the_replays_sensor_noise_is_stated(ripple_log: Path, tmp_path: Path) -> None:
    """The log is quantised on 0.05 um (the EMPS encoder's step): the replays that decide carry it, and the report says so (the
    JSON on stdout and the Markdown report of the same run)."""
    r = run_cli("diagnose", str(ripple_log), "--format", "json", "--out", str(tmp_path / "d"))
    assert r.status == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["settings"]["replay_noise"] is True and doc["decisions"]
    assert doc["replay_sensor_noise"]["quantization"]["resolution"] == pytest.approx(5e-8, rel=1e-6)
    # the replay test by default: Diebold-Mariano, named as such, at the level it ran at (the Monte-Carlo null: tests/diagnose/test_null.py)
    assert doc["decisions"][0]["test"]["test"].startswith("Diebold-Mariano") and doc["settings"]["replay_test"]["null"] == "dm"
    assert doc["settings"]["replay_test"]["alpha"] == REPLAY_ALPHA == 0.05
    md = (tmp_path / "d" / "report.md").read_text()
    assert "Every replay here carries the recording's sensor noise, estimated from its position (less what the loop adds" in md
    assert "encoder step 0.05 um" in md
    # --no-replay-noise: noise-free replays, the same finding (tests/diagnose/test_null.py's Monte-Carlo run of this log)


def test_against_a_simulated_log(ripple_log: Path, tmp_path: Path) -> None:
    sim, _ = simulated_log({}, seed=22, traj_seed=31, duration_s=12.4)
    path = tmp_path / "sim.csv"
    write_log(sim, path)
    r = run_cli("diagnose", str(ripple_log), "--against", str(path), "--format", "json")
    assert r.status == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["simulation"]["source"].endswith("sim.csv")
    assert doc["fit"]["simulation_force_relative_error_pct"]["before"] > 0


@pytest.mark.parametrize(
    "args, text",
    [
        (("missing.mat",), "no such file"),
        (("LOG", "--model", "missing.json"), "no such file"),
        (("LOG", "--effects", "gremlins"), "unknown effect"),
        (("LOG", "--out", "FILE"), "--out must be a folder"),
    ],
)
def test_bad_input_one_line_exit_2(ripple_log: Path, tmp_path: Path, args: tuple[str, ...], text: str) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    argv = [str(ripple_log) if a == "LOG" else str(afile) if a == "FILE" else a for a in args]
    r = run_cli("diagnose", *argv, "--no-simulation")
    assert r.status == 2
    assert r.stdout == ""
    assert text in r.stderr and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr


def test_log_too_short(tmp_path: Path) -> None:
    t = np.arange(200) / 1000.0
    path = tmp_path / "short.csv"
    write_log(RunLog({"t": t, "q": 0.01 * t, "tau": np.ones_like(t)}, meta={"sample_rate_hz": 1000.0}), path)
    r = run_cli("diagnose", str(path), "--no-simulation")
    assert r.status == 2 and "Traceback" not in r.stderr
