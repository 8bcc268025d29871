"""One vocabulary of physics: parameters and effects defined once and used the same way everywhere.

- every model structure with every plant effect round-trips exactly through a model file, ``ilic replay``
  and ``ilic identify --model``;
- the plant's compiled form of each built-in effect covers its definition's parameters (tests/vocabulary/test_compiled_forms.py:
  and agrees with it, sliding, stuck and at break-away);
- the library names no command-line flag;
- diagnose masks saturated samples exactly as identify does.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest

from ilic_cli import parameters
from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.effects import EFFECTS, plant_ids
from ilic_cli.errors import ParameterError
from ilic_cli.identify import identify
from ilic_cli.io import read_log, write_log
from ilic_cli.modelfile import load_model_file, model_document
from plant import kernel
from plant.dynamics import SLOTS, RigidParameters, plant_model, plant_vector
from tests.clirun import run_cli
from tests.conftest import make_synthetic_log

ROOT = Path(__file__).resolve().parents[2]

STRUCTURE_VALUES = {
    "rigid": {"M": 93.25, "Fv": 201.125, "Fc": 19.875},
    "rigid-offset": {"M": 96.5, "Fv": 198.75, "Fc": 20.625, "offset": -3.1648},
    "asymmetric": {"M": 95.1089, "Fv_pos": 166.7061, "Fc_pos": 20.144, "Fv_neg": 240.4236, "Fc_neg": 20.6277},
}


def _odd_values(eid: str) -> dict[str, float]:
    """Non-default, exactly representable values of an effect's parameters (each within its range)."""
    out = {}
    for p in EFFECTS[eid].params:
        out[p.name] = p.default * 1.25 if p.default != 0 else 0.375e-6
    return out


@pytest.mark.parametrize("structure", list(parameters.STRUCTURES))
@pytest.mark.parametrize("eid", [None, *plant_ids()])
def test_model_file_round_trip_every_structure_and_effect(tmp_path: Path, structure: str, eid: str | None) -> None:
    """A model file replayed by ``ilic replay`` carries every parameter into the plant exactly, and
    ``ilic identify --model`` takes its structure (and its effect's columns) back."""
    values = STRUCTURE_VALUES[structure]
    effects = {} if eid is None else {eid: _odd_values(eid)}
    doc = model_document(structure, values, method="test", effects=effects)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    log_path = write_log(make_synthetic_log(samples=1500), tmp_path / "log.mcap")
    if structure == "asymmetric" and eid == "asymmetric_friction":
        res = run_cli("replay", str(log_path), "--model", str(path), "-o", str(tmp_path / "r.mcap"))
        assert res.status == 2 and "asymmetric_friction must be given once" in res.stderr and str(path) in res.stderr
        return
    res = run_cli("replay", str(log_path), "--model", str(path), "-o", str(tmp_path / "r.mcap"))
    assert res.status == 0, res.stderr
    sim = read_log(tmp_path / "r.mcap")
    plant_effects = dict(sim.meta["effects"])
    asym = plant_effects.pop("asymmetric_friction", None) if structure == "asymmetric" else None
    assert parameters.from_plant(sim.meta["true_parameters"], asym, structure) == values
    assert plant_effects == effects
    # re-read by identify: the structure, and the effect as a regressor column where it has one
    loaded = load_model_file(path)
    assert loaded["parameters"] == values and loaded["effects"] == effects
    with_columns = eid is not None and bool(EFFECTS[eid].columns)
    res = run_cli("identify", str(log_path), "--model", str(path), "--method", "ls", "--format", "json")
    assert res.status == 0, res.stderr
    report = json.loads(res.stdout)
    assert report["model"] == structure
    names = list(report["ls"]["parameters"])
    assert names[: len(parameters.STRUCTURES[structure])] == list(parameters.STRUCTURES[structure])
    if with_columns:
        assert list(report["effects"]) == [eid] and names[len(parameters.STRUCTURES[structure]) :] == list(EFFECTS[eid].column_names)  # type: ignore[index]
    elif eid is not None and EFFECTS[eid].shift:  # a drive lag: no column, the regressor evaluated that much later (stated_lag_s)
        assert report["effects"] == {eid: effects[eid][eid]} and names == list(parameters.STRUCTURES[structure]) and "not identified" not in res.stderr
    elif eid is not None:
        assert report["effects"] == {} and f"not identified as regressor columns: {eid}" in res.stderr


def test_asymmetric_diagnosis_keeps_every_friction_parameter() -> None:
    """The asymmetric base model's friction parameters reach the model file (they used to be dropped,
    and a replay then ran with the default Fv = 200, Fc = 20)."""
    log = make_synthetic_log(samples=4000)
    diag = diagnose(log, settings=DiagnoseSettings(model="asymmetric", simulate=False))
    assert set(diag.model_file["parameters"]) == {"M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"}
    for name, value in zip(diag.augmented.names, diag.augmented.theta, strict=True):
        if name in parameters.PARAMETERS:
            assert diag.model_file["parameters"][name] == pytest.approx(float(value), rel=0, abs=0)
    rigid, effects = plant_model(diag.model_file["parameters"], diag.model_file["effects"])
    assert rigid.Fv == 0.0 and effects["asymmetric_friction"]["Fv_neg"] == diag.model_file["parameters"]["Fv_neg"]


def test_structures_and_columns_come_from_the_parameter_vocabulary() -> None:
    from ilic_cli.regressor import MODELS
    from plant.controllers import CHI_LAYOUT

    for name, model in MODELS.items():
        assert model.names == parameters.STRUCTURES[name]
        assert model.units == tuple(parameters.unit(n) for n in model.names)
    assert set(CHI_LAYOUT) == set(parameters.PARAMETERS)
    assert parameters.unit("Fv", "revolute") == "N·m·s/rad" and parameters.unit("Fv") == "N·s/m" and parameters.unit("M", "revolute") == "kg·m²"
    assert parameters.structure_of(["M", "Fv", "Fc", "offset", "ripple_sin"]) == "rigid-offset"
    with pytest.raises(ParameterError, match="structure = 'flexible' must be one of rigid, rigid-offset, asymmetric"):
        parameters.structure_names("flexible")


def test_compiled_effects_cover_every_parameter_of_their_definition() -> None:
    for eid in plant_ids():
        effect = EFFECTS[eid]
        assert eid in SLOTS, f"{eid} has no compiled form"
        if eid in ("delay", "noise"):  # the drive lag slot and the noise drawn up front
            continue
        assert set(SLOTS[eid]) == set(effect.names), eid


LIBRARY = [p for p in sorted((ROOT / "ilic_cli").rglob("*.py")) + sorted((ROOT / "plant").rglob("*.py")) if "commands" not in p.parts and p.name != "cli.py"]


def _raised_strings(tree: ast.AST) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None:
            out += [c.value for c in ast.walk(node.exc) if isinstance(c, ast.Constant) and isinstance(c.value, str)]
    return out


def test_no_library_module_raises_a_message_naming_a_flag() -> None:
    """Only the command line speaks of flags: the library raises domain errors (parameter, value, rule)."""
    flag = re.compile(r"(^|[\s'\"(])--[a-z]")
    offenders = {str(p.relative_to(ROOT)): s for p in LIBRARY for s in _raised_strings(ast.parse(p.read_text())) if flag.search(s)}
    assert not offenders, offenders
    assert len(LIBRARY) > 30


def test_a_fitted_invalid_plant_is_reported_without_a_flag() -> None:
    with pytest.raises(ParameterError) as err:
        plant_vector(*plant_model({"M": 95.0, "Fv": 200.0, "Fc": -0.02}, {}))
    assert err.value.message() == "Fc = -0.02 must be >= 0"


def test_simulate_names_the_option_of_a_bad_value(tmp_path: Path) -> None:
    res = run_cli("simulate", "--param", "Fc=-1", "--duration", "1", "-o", str(tmp_path / "x.mcap"))
    assert res.status == 2 and res.stderr.strip() == "ilic: error: --param: Fc = -1 must be >= 0"
    res = run_cli("simulate", "--effect", "stribeck:vs=-1", "--duration", "1", "-o", str(tmp_path / "x.mcap"))
    assert res.status == 2 and res.stderr.strip() == "ilic: error: --effect: stribeck.vs = -1 must be > 0"
    res = run_cli("simulate", "--omega", "-3", "--duration", "1", "-o", str(tmp_path / "x.mcap"))
    assert res.status == 2 and res.stderr.strip() == "ilic: error: --omega: omega = -3 must be a positive number"
    assert not (tmp_path / "x.mcap").exists()


def test_old_model_spelling_is_a_deprecated_structure(tmp_path: Path) -> None:
    log_path = write_log(make_synthetic_log(samples=3000), tmp_path / "log.mcap")
    old = run_cli("identify", str(log_path), "--method", "ls", "--model", "rigid", "--format", "json")
    new = run_cli("identify", str(log_path), "--method", "ls", "--structure", "rigid", "--format", "json")
    assert old.status == 0 and new.status == 0 and old.stdout == new.stdout
    assert "--model rigid is deprecated" in old.stderr and "deprecated" not in new.stderr
    assert json.loads(new.stdout)["model"] == "rigid"


def _saturated_log() -> object:
    log = make_synthetic_log(samples=6000)
    vir = np.clip(log["vir"] * 1.6, -1.8, 1.8)
    return log.with_channels(vir=vir, tau=vir * log.meta["drive_gain"])


def test_diagnose_masks_saturated_samples_exactly_as_identify() -> None:
    log = _saturated_log()
    report = identify(log, method="ls")  # type: ignore[arg-type]
    diag = diagnose(log, settings=DiagnoseSettings(simulate=False))  # type: ignore[arg-type]
    assert any("saturated drive:" in w for w in report.warnings)
    assert any("saturated drive:" in w for w in diag.warnings)
    assert diag.rows_total == report.ls.result.rows  # type: ignore[union-attr]
    unmasked = diagnose(make_synthetic_log(samples=6000), settings=DiagnoseSettings(simulate=False))
    assert unmasked.rows_total > diag.rows_total


@pytest.mark.parametrize("structure", list(parameters.STRUCTURES))
def test_compiled_ctc_law_is_the_regressor_of_its_structure(structure: str) -> None:
    """The kernel's CTC force (eqs. 13, 16, 31) equals ``W(qdd = w, qd = qd_r, sign = (2/pi) atan(alpha qd_r)) @ chi``."""
    from ilic_cli.regressor import Kinematics, get_model
    from plant.controllers import CTCSettings, chi_vector

    rng = np.random.default_rng(2)
    n = 40
    model = get_model(structure)
    theta = rng.uniform(1.0, 50.0, len(model.names))
    ctc = CTCSettings(model=structure, alpha=300.0)
    q_r, qd_r, qdd_r = rng.normal(0, 0.1, n), rng.normal(0, 0.2, n), rng.normal(0, 2.0, n)
    p = plant_vector(RigidParameters(95.0, 200.0, 20.0, 0.0), {})
    x, cs = np.zeros(4), np.zeros(4)
    out = [np.zeros(n) for _ in range(6)]
    z = np.zeros(n)
    assert kernel.run_periods(0, n, x, cs, q_r, qd_r, qdd_r, z, z, p, ctc.vector(), chi_vector(model.names, theta), 10, 1e-3, *out, z) == -1
    q_meas = out[0]
    qd_hat = np.diff(np.r_[q_meas[0], q_meas]) / 1e-3  # eq. 25 (the first period: the memory starts at the first sample)
    w = ctc.Kp * (q_r - q_meas) + ctc.Kv * (qd_r - qd_hat) + qdd_r
    kin = Kinematics(qd=qd_r, qdd=w, sign_qd=(2 / np.pi) * np.arctan(ctc.alpha * qd_r))
    np.testing.assert_allclose(out[1], model.matrix(kin) @ theta, rtol=1e-12, atol=1e-9)
