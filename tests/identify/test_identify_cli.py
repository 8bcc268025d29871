"""``ilic identify`` on synthetic logs: JSON contract, outputs, unexcited windows, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import write_log
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli

TRUE = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}


def synthetic(duration_s: float = 18.6, seed: int = 0, constant_after: float | None = None) -> RunLog:
    """Open-loop synthetic run: smooth exciting reference, exact inverse dynamics plus noise."""
    fs = 1000.0
    t = np.arange(int(duration_s * fs)) / fs
    w = 2 * np.pi / 6.2
    q_ref = 0.08 * np.sin(w * t) + 0.03 * np.sin(3 * w * t)
    qd_ref = 0.08 * w * np.cos(w * t) + 0.09 * w * np.cos(3 * w * t)
    qdd_ref = -0.08 * w**2 * np.sin(w * t) - 0.27 * w**2 * np.sin(3 * w * t)
    if constant_after is not None:
        late = t >= constant_after
        i0 = int(np.argmax(late))
        qd_ref = np.where(late, 0.05, qd_ref)
        qdd_ref = np.where(late, 0.0, qdd_ref)
        q_ref = np.where(late, q_ref[i0] + 0.05 * (t - t[i0]), q_ref)
    rng = np.random.default_rng(seed)
    tau = TRUE["M"] * qdd_ref + TRUE["Fv"] * qd_ref + TRUE["Fc"] * np.sign(qd_ref) + TRUE["offset"] + rng.normal(0, 1.0, t.size)
    q = q_ref + rng.normal(0, 1e-7, t.size)
    return RunLog({"t": t, "q": q, "q_ref": q_ref, "qd_ref": qd_ref, "qdd_ref": qdd_ref, "tau": tau}, meta={"sample_rate_hz": fs})


@pytest.fixture()
def log_path(tmp_path: Path) -> Path:
    p = tmp_path / "synthetic.csv"
    write_log(synthetic(), p)
    return p


def test_json_stdout_is_only_json_and_recovers_truth(log_path: Path) -> None:
    res = run_cli("identify", str(log_path), "--format", "json")
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["model"] == "rigid-offset"
    for name, value in TRUE.items():
        assert doc["ls"]["parameters"][name]["value"] == pytest.approx(value, rel=0.03)
    assert len(doc["ilic"]["windows"]) == 3
    for w in doc["ilic"]["windows"]:
        assert set(w) >= {"k", "t_start", "t_end", "parameters", "essential", "relative_error_pct", "tracking_error_ratio"}
        for name in ("M", "Fv", "Fc"):
            assert w["parameters"][name]["value"] == pytest.approx(TRUE[name], rel=0.01)
            assert w["essential"][name] is True


def test_out_folder_has_reports_model_and_plots(log_path: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    res = run_cli("identify", str(log_path), "--out", str(out), "--plots", "svg")
    assert res.status == 0, res.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["force.svg", "model.json", "parameters.svg", "report.csv", "report.json", "report.md", "tracking.svg"]
    model = json.loads((out / "model.json").read_text())
    assert model["parameters"]["M"] == pytest.approx(95.0, rel=0.03)
    assert "| M (kg) |" in res.stdout


def test_csv_format(log_path: Path) -> None:
    res = run_cli("identify", str(log_path), "--format", "csv", "--method", "ilic")
    assert res.status == 0, res.stderr
    lines = res.stdout.strip().splitlines()
    assert lines[0].startswith("method,k,t_start,t_end,parameter,value,std,rel_std_pct,essential")
    assert len(lines) == 1 + 3 * 4


def test_unexcited_window_is_reported_not_crashed(tmp_path: Path) -> None:
    p = tmp_path / "unexcited.csv"
    write_log(synthetic(duration_s=18.6, constant_after=12.4), p)
    res = run_cli("identify", str(p), "--method", "ilic", "--format", "json")
    assert res.status == 0, res.stderr
    assert "NaN" not in res.stdout
    doc = json.loads(res.stdout)
    last = doc["ilic"]["windows"][-1]
    assert last["essential"]["M"] is False
    assert last["essential"]["Fc"] is False or last["essential"]["Fv"] is False
    assert "not excited" in last["note"] or "not essential" in last["note"]
    assert "window k=3" in res.stderr


def test_missing_reference_channel_for_ilic(tmp_path: Path) -> None:
    log = synthetic()
    p = tmp_path / "noref.csv"
    write_log(RunLog({k: v for k, v in log.channels.items() if k in ("t", "q", "tau")}, meta=log.meta), p)
    res = run_cli("identify", str(p), "--method", "ilic")
    assert res.status == 2
    assert res.stderr.strip() == f"ilic: error: {p}: IDIM-ILIC cannot run: the log has no reference position (q_ref)"
    # the default (both) falls back to IDIM-LS and says so
    res = run_cli("identify", str(p), "--format", "json")
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["ilic"] is None and doc["ls"]["parameters"]["M"]["value"] > 0
    assert "IDIM-ILIC not run: the log has no reference position (q_ref); IDIM-LS only" in res.stderr


def test_a_reference_that_does_not_track_is_refused(tmp_path: Path) -> None:
    """Another joint's reference (here the measured motion reversed) is not fitted into nonsense."""
    log = synthetic(duration_s=13.0)
    wrong = log.with_channels(q_ref=log["q_ref"][::-1].copy())
    p = write_log(wrong, tmp_path / "wrong.csv")
    res = run_cli("identify", str(p), "--method", "ilic")
    assert res.status == 2 and "the reference does not track the measured joint (tracking error ratio" in res.stderr
    res = run_cli("identify", str(p), "--format", "json")
    assert res.status == 0 and json.loads(res.stdout)["ilic"] is None and "IDIM-ILIC not run" in res.stderr


def test_log_shorter_than_window(tmp_path: Path) -> None:
    p = tmp_path / "short.csv"
    write_log(synthetic(duration_s=3.0), p)
    res = run_cli("identify", str(p), "--method", "ilic")
    assert res.status == 2
    assert "shorter than one window" in res.stderr and res.stderr.count("\n") == 1


def test_missing_file(tmp_path: Path) -> None:
    res = run_cli("identify", str(tmp_path / "nope.mat"))
    assert res.status == 2
    assert res.stderr == f"ilic: error: {tmp_path / 'nope.mat'}: no such file or folder\n"
    assert res.stdout == ""
