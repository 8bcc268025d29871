"""Adding an effect is one definition: a toy effect works end to end without touching another module.

The toy is a cubic viscous friction ``F3 * qd**3``, defined here -- its parameter and
its one regressor column, with the column's pointwise form -- and registered in
:data:`ilic_cli.effects.EFFECTS`. It has no force term of its own: its plant force is
its column times its parameter. Nothing else is edited, and yet it is

- simulated by the plant (``ilic simulate --effect``; the loop is compiled for it from
  the column), the simulated force being ``Y @ theta`` of its columns,
- identified as a regressor column (``ilic identify --effect``),
- found by ``ilic diagnose`` in a log where it is concealed,
- written to the model file and replayed by ``ilic replay``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.effects import Effect, EffectColumn, PlantParam, make_effects, register, unregister
from ilic_cli.io import read_log
from ilic_cli.regressor import COLUMNS, Kinematics
from ilic_cli.runlog import RunLog
from plant.generic import kernel_for
from tests.clirun import run_cli
from tests.vocabulary.test_compiled_forms import check_against_definition

F3 = 800.0
"""Cubic friction of the concealed effect (N/(m/s)^3): about 3 N rms, 11 N at the top speed of paper-sim."""

TOY = Effect(
    "cubic_friction",
    "cubic viscous friction",
    "Shear of a thick lubricant film adds friction growing with the cube of the sliding speed.",
    params=(PlantParam("F3", "N/(m/s)^3", 0.0, "cubic viscous coefficient"),),
    form="F3 * qd^3",
    signature="residual odd in velocity, growing fastest at the top speeds",
    signature_kinds=("velocity",),
    columns=(EffectColumn("F3", "N/(m/s)^3", "cubic viscous coefficient", of=lambda q, qd, qdd, t, value: qd**3),),
)


@pytest.fixture(scope="module")
def toy() -> Iterator[Effect]:
    register(TOY)
    yield TOY
    unregister(TOY.id)


@pytest.fixture(scope="module")
def concealed(toy: Effect, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A paper-sim log (CTC, online IDIM-ILIC, 0.5 N force noise) with the toy effect in the plant."""
    path = tmp_path_factory.mktemp("toy") / "toy.mcap"
    res = run_cli(
        "simulate", "--scenario", "paper-sim", "--duration", "25", "--seed", "4", "--noise-tau", "0.5", "--effect", f"cubic_friction:F3={F3}", "-o", str(path)
    )
    assert res.status == 0, res.stderr
    return path


def test_simulated(toy: Effect, concealed: Path, tmp_path: Path) -> None:
    """The plant integrated the toy's force, its columns times its parameter: exactly (noise-free, the logged command),
    in the compiled loop's dynamics (sliding, stuck and at break-away), and in a fit of the concealed log."""
    path = tmp_path / "exact.mcap"
    args = ("--scenario", "paper-sim", "--duration", "4", "--seed", "1", "--tau-sensor", "command", "--effect", f"cubic_friction:F3={F3}")
    res = run_cli("simulate", *args, "-o", str(path))
    assert res.status == 0, res.stderr
    exact = read_log(path)
    truth = exact.provenance.true_parameters
    assert truth is not None
    kin = Kinematics(qd=exact["qd_plant"], qdd=exact["qdd_plant"], q=exact["q"], t=exact.t)
    rigid = np.column_stack([COLUMNS[n].build(kin) for n in ("M", "Fv", "Fc", "offset")]) @ [truth[n] for n in ("M", "Fv", "Fc", "offset")]
    toy_force = toy.matrix(kin) @ [F3]  # Y of the toy's own column, times its parameter
    np.testing.assert_array_equal(toy.plant_force({"F3": F3}, kin), toy_force)
    sliding = np.abs(kin.qd) > 1e-6
    assert sliding.mean() > 0.9 and np.abs(toy_force[sliding]).max() > 5.0
    np.testing.assert_allclose(rigid[sliding] + toy_force[sliding], exact["tau"][sliding], rtol=0, atol=1e-9 * np.abs(exact["tau"]).max())
    assert np.abs(rigid[sliding] - exact["tau"][sliding]).max() > 5.0  # without the toy's column the force is missed
    eff = make_effects({"cubic_friction": {"F3": F3}})
    check_against_definition(kernel_for(eff), eff)  # the loop compiled for it, against its definition

    log = read_log(concealed)
    assert log.meta["effects"]["cubic_friction"] == {"F3": F3}
    qd, qdd = log["qd_plant"], log["qdd_plant"]
    sliding = np.abs(qd) > 1e-3
    W = np.c_[qdd, qd, np.sign(qd), np.ones_like(qd), qd**3][sliding]
    theta = np.linalg.lstsq(W, log["tau"][sliding], rcond=None)[0]
    assert theta[4] == pytest.approx(F3, rel=0.10)  # the centred force sensor and 0.5 N noise bias a fit on the plant states a little
    assert theta[0] == pytest.approx(95.0, rel=0.01)


def test_identified_as_a_regressor_column(concealed: Path, tmp_path: Path) -> None:
    res = run_cli("identify", str(concealed), "--method", "ls", "--effect", "cubic_friction", "--format", "json", "--out", str(tmp_path))
    assert res.status == 0, res.stderr
    report = json.loads(res.stdout)
    est = report["ls"]["parameters"]
    assert list(est) == ["M", "Fv", "Fc", "offset", "F3"]
    assert est["F3"]["value"] == pytest.approx(F3, rel=0.10)
    assert est["M"]["value"] == pytest.approx(95.0, rel=0.01)
    model = json.loads((tmp_path / "model.json").read_text())
    assert model["effects"]["cubic_friction"]["F3"] == est["F3"]["value"]


def test_diagnosed_written_and_replayed(concealed: Path, tmp_path: Path) -> None:
    log: RunLog = read_log(concealed)
    diag = diagnose(log, settings=DiagnoseSettings())
    found = [f.effect.id for f in diag.findings]
    assert "cubic_friction" in found, diag.conclusion
    finding = diag.findings[found.index("cubic_friction")]
    assert finding.parameters["F3"].value == pytest.approx(F3, rel=0.15)
    assert diag.model_file["effects"]["cubic_friction"]["F3"] == finding.parameters["F3"].value
    assert "cubic viscous friction (F3 = " in diag.conclusion or "cubic viscous friction" in diag.conclusion
    sim = diag.fit["simulation_force_relative_error_pct"]
    assert sim["after"] < sim["before"], sim
    # the model file replays: the plant gets the toy effect with the file's value
    model_path = tmp_path / "model.json"
    model_path.write_text(json.dumps(diag.model_file))
    res = run_cli("replay", str(concealed), "--model", str(model_path), "-o", str(tmp_path / "replayed.mcap"))
    assert res.status == 0, res.stderr
    replayed = read_log(tmp_path / "replayed.mcap")
    assert replayed.meta["effects"]["cubic_friction"] == diag.model_file["effects"]["cubic_friction"]
