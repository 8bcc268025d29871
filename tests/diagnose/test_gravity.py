"""Gravity on a revolute joint is named gravity, not a spring, with its first moments (issue 29, item 4).

Logs of :func:`tests.corpus.revolute_log`: a CTC without gravity compensation on a multisine that swings the link
through about 2.8 rad, a 19-bit encoder, the held command as the torque. Measured (30 s logs, seed 1): the rigid
fit's relative error 2.56 % clean; with gravity 5.30 % (0.08 kg·m², MX 0.006, MY 0.003 kg·m) and 3.80 %
(0.5 kg·m², MX 0.03, MY -0.015 kg·m); ``ilic diagnose`` names gravity on both within 0.5 % (spring: not
significant, or "another effect was accepted first"), and nothing on the clean log.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.select import SelectSettings
from ilic_cli.io import write_log
from tests.clirun import run_cli
from tests.corpus import revolute_log

TOLERANCE = 0.15
"""The issue's: parameters within 15 %."""

SMALL = {"MX": 0.006, "MY": 0.003}
LARGE = {"MX": 0.03, "MY": -0.015}


def _within(found: dict[str, float], truth: dict[str, float]) -> bool:
    return all(abs(found[k] - v) <= TOLERANCE * abs(v) for k, v in truth.items())


def test_diagnose_names_gravity_on_a_small_revolute_joint(tmp_path: Path) -> None:
    """The command line on a CSV log (its units say radians: the joint is revolute)."""
    path = tmp_path / "wrist.csv"
    write_log(revolute_log("small", {"gravity": SMALL}, seed=2, duration_s=12.0), path)
    res = run_cli("diagnose", str(path), "--format", "json", "--out", str(tmp_path / "d"))
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    named = [f["effect"] for f in doc["findings"]]
    assert named == ["gravity"], named
    assert _within(doc["findings"][0]["plant_effect"], SMALL), doc["findings"][0]["plant_effect"]
    assert doc["model_file"]["effects"]["gravity"].keys() == {"MX", "MY"}
    spring = [ev for step in doc["selection"] for ev in step if ev["effect"] == "spring"]
    assert spring and not any(ev["accepted"] for ev in spring)  # tried, and not named
    md = (tmp_path / "d" / "report.md").read_text()  # the same run's Markdown report
    regions = [line for line in md.splitlines() if line.startswith("- position in [")]
    assert regions, md  # a revolute joint's regions in its units: rad, N·m (they said m and N)
    assert all("] rad: mean residual" in line and " N·m (standard error" in line for line in regions), regions
    assert "] m" not in md and "mean residual" in md and " N (standard error" not in md, md


@pytest.mark.parametrize("fs_hz", [500.0, 1000.0])
def test_diagnose_names_gravity_on_a_large_revolute_joint(fs_hz: float) -> None:
    """At 500 Hz and 1 kHz (measured at 2 kHz too: MX, MY 4.7 and 7.3 % off, 36 s, left out here for the suite's time)."""
    diag = diagnose(revolute_log("large", {"gravity": LARGE}, seed=2, duration_s=12.0, fs_hz=fs_hz))
    assert [f.effect.id for f in diag.findings] == ["gravity"], diag.conclusion
    f = diag.findings[0]
    assert f.plant_effect is not None and _within(f.plant_effect, LARGE), f.plant_effect
    assert "first moments" in f.effect.describe(f.parameters)


def test_identify_with_the_gravity_effect_gives_the_first_moments(tmp_path: Path) -> None:
    path = tmp_path / "elbow.csv"
    write_log(revolute_log("large", {"gravity": LARGE}, seed=2, duration_s=12.0), path)
    res = run_cli("identify", str(path), "--method", "ls", "--effect", "gravity", "--format", "json")
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["joint_type"] == "revolute"
    ls = doc["ls"]
    found = {k: v["value"] for k, v in ls["parameters"].items()}
    assert _within({k: found[k] for k in LARGE}, LARGE), found


@pytest.mark.parametrize("seed", [1, 4])
def test_a_clean_revolute_log_gets_no_gravity(seed: int) -> None:
    """Judged by the inverse model alone (no replay: the stricter, since a candidate past its tests is then kept)."""
    diag = diagnose(revolute_log("small", {}, seed=seed, duration_s=12.0), settings=DiagnoseSettings(simulate=False))
    assert "gravity" not in [f.effect.id for f in diag.findings], diag.conclusion
    tried = [ev for step in diag.tried for ev in step if ev.effect == "gravity"]
    assert tried and not any(ev.accepted for ev in tried)  # proposed on this revolute joint, and rejected by the data
    assert diag.drift is not None and not diag.drift.found, diag.drift.sentence()  # nor a drift, on this scale either


def test_a_vertical_axis_reports_its_constant_force_as_a_weight() -> None:
    """A 12 kg load hanging on the EMPS-like axis (its metadata says ``vertical``): 117.7 N, read as that weight and that mass."""
    from ilic_cli.diagnosis.report import to_markdown
    from ilic_cli.simulation.scenarios import Overrides, run_scenario
    from tests.corpus import CTC_CHI0, NOISE_MODELS, PLANT

    g = 9.80665
    ov = Overrides(
        params={**PLANT, "offset": 12.0 * g},
        effects=dict(NOISE_MODELS["sensor"]),
        ctc={"ilic": False},
        chi0=dict(CTC_CHI0),
        duration_s=30.0,
        seed=3,
        tau_sensor="command",
        trajectory="trapezoid",
        trajectory_seed=3,
    )
    log = run_scenario("paper-sim", ov)
    log.meta.pop("true_parameters")
    settings = DiagnoseSettings(simulate=False, select=SelectSettings(effects=()))  # the rigid fit's constant: no candidate needed
    assert diagnose(log, settings=settings).weight is None  # not said to be vertical: an offset, as before
    log.meta["vertical"] = True
    diag = diagnose(log, settings=settings)
    assert diag.weight is not None
    assert diag.weight["weight"].value == pytest.approx(12.0 * g, rel=0.01) and diag.weight["implied_mass"].value == pytest.approx(12.0, rel=0.01)
    assert diag.to_dict()["weight"]["implied_mass"]["unit"] == "kg"
    assert "the constant force is the load's weight, 117.7 N" in to_markdown(diag)


def test_a_catalogue_effect_on_a_revolute_joint_is_stated_in_its_units() -> None:
    """The catalogue writes its effects in a prismatic axis's units (the EMPS's): on a revolute joint a finding's estimates, its
    sentence and the JSON's units are the joint's (N·m·s/rad, N·m). Before, a 0.2 N·m·s/rad viscous friction read "0 N·s/m"."""
    truth = {"Fv_pos": 0.2, "Fv_neg": 0.3, "Fc_pos": 0.3, "Fc_neg": 0.3}
    diag = diagnose(revolute_log("small", {"asymmetric_friction": truth}, seed=1, duration_s=12.0), settings=DiagnoseSettings(simulate=False))
    (f,) = diag.findings
    assert f.effect.id == "asymmetric_friction" and _within({k: e.value for k, e in f.parameters.items()}, truth)
    assert {k: e.unit for k, e in f.parameters.items()} == {"Fv_pos": "N·m·s/rad", "Fv_neg": "N·m·s/rad", "Fc_pos": "N·m", "Fc_neg": "N·m"}
    assert "viscous friction 0.2 N·m·s/rad forward, 0.3 backward" in f.effect.describe(f.parameters)
    doc = diag.to_dict()
    assert doc["joint_type"] == "revolute" and doc["units"]["dFv_neg"] == "N·m·s/rad" and doc["units"]["M"] == "kg·m²"
    assert doc["findings"][0]["parameters"]["Fc_pos"]["unit"] == "N·m"


def test_a_spring_beside_a_payload_step_is_not_named_gravity() -> None:
    """Robot corpus s9710 (the 0.5 kg·m² trapezoid at 500 Hz under the current loop, a spring and a payload's step): the
    step's prewhitened evidence is far the stronger (F = 371 against gravity's 47), gravity's two columns lowered the raw
    error more (1.93 % against 2.12 %). Ranked by the raw error (planted: fails), gravity was taken first and the spring
    named gravity; ranked by the evidence (``forward_select``), the step first, then the spring, both within 15 %."""
    from tests.corpus.robot import build, case_named

    built = build(case_named("rev0.5/trapezoid/500Hz/current_loop/spring+payload_change/s710", 9710))
    diag = diagnose(built.log)
    found = {f.effect.id: f for f in diag.findings}
    assert "gravity" not in found and {"spring", "payload_change"} <= found.keys(), diag.conclusion
    assert found["spring"].evidence.indistinct_from is None
    assert found["spring"].parameters["k"].value == pytest.approx(built.effects["spring"]["k"], rel=TOLERANCE)
    assert found["payload_change"].parameters["dM"].value == pytest.approx(built.effects["payload_change"]["dM"], rel=TOLERANCE)
