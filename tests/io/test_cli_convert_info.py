"""``ilic info`` and ``ilic convert`` behaviour, and the data-quality rules."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ilic_cli import quality, timebase
from ilic_cli.io import read_log, write_log
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli
from tests.conftest import make_synthetic_log


# -- ilic info on the real recording -------------------------------------------
def test_info_emps_markdown(emps_mat: Path) -> None:
    result = run_cli("info", str(emps_mat))
    assert result.status == 0, result.stderr
    out = result.stdout
    assert "- samples: 24841" in out
    assert "- sample rate: 1000 Hz (1 kHz" in out
    assert "- duration: 24.84 s" in out
    assert "- drive gain: 35.1507 N/V" in out
    assert "kind=pd, kp=160.18, kv=243.45" in out
    assert "| vir | V |" in out and "| tau | N |" in out
    assert "no problems found" in out
    assert result.stderr == ""


def test_info_emps_json(emps_mat: Path) -> None:
    result = run_cli("info", str(emps_mat), "--format", "json")
    assert result.status == 0, result.stderr
    data = json.loads(result.stdout)  # stdout is nothing but JSON
    assert data["samples"] == 24841
    assert data["sample_rate_hz"] == 1000.0
    assert data["duration_s"] == pytest.approx(24.84, abs=1e-9)
    assert data["drive_gain"] == pytest.approx(35.15, abs=0.01)
    assert data["controller"] == {"kind": "pd", "kp": 160.18, "kv": 243.45}
    assert data["format"] == "mat"
    channels = {c["name"]: c for c in data["channels"]}
    assert set(channels) == {"t", "q", "q_ref", "tau", "vir"}
    assert channels["vir"]["unit"] == "V"
    assert channels["vir"]["min"] == pytest.approx(-4.325661900120147)
    q = data["quality"]
    assert q["ok"] is True and q["gaps"] == 0 and q["irregular"] is False
    assert q["saturation_limit"] is None
    assert q["frozen_runs"] == []
    assert q["jitter"] < 1e-3


def test_info_pulses_file_has_pulses(emps_pulses_mat: Path) -> None:
    data = json.loads(run_cli("info", str(emps_pulses_mat), "--format", "json").stdout)
    pulses = next(c for c in data["channels"] if c["name"] == "pulses")
    assert (pulses["min"], pulses["max"]) == (0.0, 5.0)
    assert data["samples"] == 24841


def test_info_shows_scenario_and_true_parameters(tmp_path: Path) -> None:
    path = write_log(make_synthetic_log(samples=2000), tmp_path / "sim.mcap")
    data = json.loads(run_cli("info", str(path), "--format", "json").stdout)
    assert data["scenario"] == {"name": "unit-test", "seed": 3}
    assert data["true_parameters"]["M"] == 95.0
    assert data["format"] == "mcap"
    md = run_cli("info", str(path)).stdout
    assert "- scenario: name=unit-test, seed=3" in md
    assert "- true parameters: M=95" in md


def test_info_reports_quality_warnings(tmp_path: Path) -> None:
    log = make_synthetic_log(samples=3000)
    vir = np.clip(log.channels["vir"] * 40, -10.0, 10.0)
    t = log.t.copy()
    t[1500:] += 0.005  # five dropped samples
    bad = log.with_channels(vir=vir, tau=log.meta["drive_gain"] * vir, t=t)
    path = write_log(bad, tmp_path / "bad.csv")
    data = json.loads(run_cli("info", str(path), "--format", "json").stdout)
    codes = {f["code"] for f in data["quality"]["findings"] if f["severity"] == "warning"}
    assert {"gaps", "saturation"} <= codes
    assert data["quality"]["dropped_samples"] == 5
    assert data["quality"]["saturation_limit"] == 10.0
    assert data["quality"]["ok"] is False


# -- ilic convert ---------------------------------------------------------------------
def test_convert_summary_and_rosbag2_folder(tmp_path: Path, synthetic_log: RunLog) -> None:
    src = write_log(synthetic_log, tmp_path / "in.csv")
    result = run_cli("convert", str(src), str(tmp_path / "bag"), "--storage", "mcap")
    assert result.status == 0, result.stderr
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert lines[-1].startswith("ilic: wrote ") and "(rosbag2)" in lines[-1] and "400 samples" in lines[-1]
    assert sorted(p.name for p in (tmp_path / "bag").iterdir()) == ["bag.mcap", "metadata.yaml"]
    assert np.array_equal(read_log(tmp_path / "bag").channels["q"], synthetic_log.channels["q"])


def test_convert_explicit_formats(tmp_path: Path, synthetic_log: RunLog) -> None:
    src = write_log(synthetic_log, tmp_path / "in.data", "csv")
    result = run_cli("convert", str(src), str(tmp_path / "out.bin"), "--input-format", "csv", "--format", "mcap")
    assert result.status == 0, result.stderr
    assert (tmp_path / "out.bin").read_bytes()[:8] == b"\x89MCAP0\r\n"
    back = read_log(tmp_path / "out.bin", "mcap")
    assert np.array_equal(back.t, synthetic_log.t)


def test_convert_replaces_existing_output(tmp_path: Path, synthetic_log: RunLog) -> None:
    src = write_log(synthetic_log, tmp_path / "in.csv")
    (tmp_path / "out.mat").write_bytes(b"old")
    assert run_cli("convert", str(src), str(tmp_path / "out.mat")).status == 0
    assert len(read_log(tmp_path / "out.mat")) == len(synthetic_log)


def _jittered(samples: int = 1500) -> RunLog:
    log = make_synthetic_log(samples=samples)
    rng = np.random.default_rng(7)
    t = log.t + rng.uniform(-2e-4, 2e-4, samples)  # 20 % jitter, still increasing
    return log.with_channels(t=t)


def test_convert_keeps_irregular_sampling_with_a_warning(tmp_path: Path) -> None:
    """Truly irregular stamps (steps of 0.2 to 1.8 periods) are kept with a warning; stamp jitter of a fixed-rate loop is kept silently."""
    log = make_synthetic_log(samples=1500)
    steps = np.random.default_rng(7).uniform(0.2e-3, 1.8e-3, len(log) - 1)
    irregular = log.with_channels(t=np.concatenate([[0.0], np.cumsum(steps)]))
    src = write_log(irregular, tmp_path / "irregular.csv")
    result = run_cli("convert", str(src), str(tmp_path / "kept.mcap"))
    assert result.status == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if line.startswith("ilic: warning: ")]
    assert len(warnings) == 1 and "irregular sampling" in warnings[0] and "--resample" in warnings[0]
    assert np.array_equal(read_log(tmp_path / "kept.mcap").t, irregular.t)
    jittered = write_log(_jittered(), tmp_path / "jittered.csv")
    result = run_cli("convert", str(jittered), str(tmp_path / "jittered.mcap"))
    assert result.status == 0 and "warning" not in result.stderr, result.stderr


def test_convert_resample(tmp_path: Path) -> None:
    log = _jittered()
    src = write_log(log, tmp_path / "irregular.csv")
    result = run_cli("convert", str(src), str(tmp_path / "uniform.csv"), "--resample", "500")
    assert result.status == 0, result.stderr
    assert "warning" not in result.stderr
    out = read_log(tmp_path / "uniform.csv")
    step = np.diff(out.t)
    assert np.allclose(step, 0.002, rtol=0, atol=1e-12)
    assert out.t[0] == log.t[0] and out.t[-1] <= log.t[-1]
    assert out.meta["sample_rate_hz"] == 500.0
    assert out.meta["resampled"]["from_samples"] == 1500
    assert np.allclose(out.channels["q"], np.interp(out.t, log.t, log.channels["q"]))
    assert quality.assess_log(out).irregular is False


def test_convert_resample_must_be_positive(tmp_path: Path, synthetic_log: RunLog) -> None:
    src = write_log(synthetic_log, tmp_path / "in.csv")
    result = run_cli("convert", str(src), str(tmp_path / "out.csv"), "--resample", "0")
    assert result.status == 2
    assert result.stderr.startswith("ilic: error: ") and len(result.stderr.splitlines()) == 1
    assert not (tmp_path / "out.csv").exists()


def test_commands_do_not_import_heavy_libraries() -> None:
    code = (
        "import sys\n"
        "import ilic_cli.cli, ilic_cli.commands.convert, ilic_cli.commands.info\n"
        "heavy = [m for m in ('numpy', 'pandas', 'scipy', 'rosbags', 'mcap') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=Path(__file__).parents[2])
    assert out.stdout.strip() == ""


def test_help_lists_convert_and_info() -> None:
    for cmd in ("convert", "info"):
        result = run_cli(cmd, "--help")
        assert result.status == 0
        assert "--input-format" in result.stdout and "--joint" in result.stdout
    assert "--resample" in run_cli("convert", "--help").stdout


# -- quality rules --------------------------------------------------------------------
@pytest.mark.parametrize(
    ("step", "expected"),
    [(0.0009999839611225525, 1000.0), (0.001000008, 1000.0), (0.003, 1 / 0.003), (0.002, 500.0), (1 / 1234.0, 1234.0), (0.00081037, 1234.0)],
)
def test_nominal_rate(step: float, expected: float) -> None:
    t = np.arange(200) * step
    assert timebase.nominal_rate_hz(t) == pytest.approx(expected, rel=1e-9)


def test_nominal_rate_needs_two_samples() -> None:
    assert timebase.nominal_rate_hz(np.array([0.0])) is None


def test_gaps_and_jitter() -> None:
    t = np.arange(1000) * 0.001
    t[500:] += 0.003  # 3 samples dropped in one gap
    stats = timebase.sampling_stats(t)
    assert stats["gaps"] == 1 and stats["dropped_samples"] == 3 and stats["irregular"] is True
    assert stats["jitter"] < 1e-9
    clean = timebase.sampling_stats(np.arange(1000) * 0.001)
    assert clean["gaps"] == 0 and clean["irregular"] is False


def test_saturation_rule() -> None:
    x = np.sin(np.linspace(0, 20, 5000)) * 14
    clipped = np.clip(x, -10, 10)
    share, limit = quality.saturation(clipped)
    assert limit == 10.0 and share > 0.1
    # a free signal touches its max once: no plateau
    assert quality.saturation(x)[1] is None
    # a plateau at a value that is no configured limit is not called saturation
    assert quality.saturation(np.clip(x, -9.8734, 9.8734))[1] is None
    assert quality.is_round_limit(2.5) and quality.is_round_limit(24.0) and not quality.is_round_limit(4.3256)


def test_frozen_sensor_rule() -> None:
    t = np.arange(3000) * 0.001
    q_ref = np.sin(t)
    q = q_ref.copy()
    assert quality.frozen_runs(t, q, q_ref) == []
    q[1000:1400] = q[1000]  # stuck for 0.4 s while the reference moves
    runs = quality.frozen_runs(t, q, q_ref)
    assert len(runs) == 1 and runs[0]["samples"] == 400 and runs[0]["start_s"] == pytest.approx(1.0)
    # standing still with the reference: not frozen
    q_ref2 = q_ref.copy()
    q_ref2[1000:1400] = q_ref2[1000]
    assert quality.frozen_runs(t, q, q_ref2) == []


def test_short_log_is_reported() -> None:
    report = quality.assess(np.arange(50) * 0.001)
    assert [f.code for f in report.findings if f.severity == "warning"] == ["short"]
    assert report.to_dict()["ok"] is False


def test_output_file_gets_normal_permissions(tmp_path: Path, synthetic_log: RunLog) -> None:
    import os

    mask = os.umask(0o022)
    os.umask(mask)
    src = write_log(synthetic_log, tmp_path / "in.csv")
    for name in ("out.mcap", "out.mat"):
        assert run_cli("convert", str(src), str(tmp_path / name)).status == 0
        assert (tmp_path / name).stat().st_mode & 0o777 == 0o666 & ~mask
