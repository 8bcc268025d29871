"""Adding an effect is one definition: a toy effect works end to end without touching another module.

The toy is a cubic viscous friction ``F3 * qd**3``, defined here and registered in
:data:`ilic_cli.effects.EFFECTS`. Nothing else is edited, and yet it is

- simulated by the plant (``ilic simulate --effect``; the loop is compiled for it),
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
from ilic_cli.effects import Effect, EffectColumn, PlantParam, register, unregister
from ilic_cli.io import read_log
from ilic_cli.runlog import RunLog
from tests.clirun import run_cli

F3 = 800.0
"""Cubic friction of the concealed effect (N/(m/s)^3): about 3 N rms, 11 N at the top speed of paper-sim."""

TOY = Effect(
    "cubic_friction",
    "cubic viscous friction",
    "Shear of a thick lubricant film adds friction growing with the cube of the sliding speed.",
    params=(PlantParam("F3", "N/(m/s)^3", 0.0, "cubic viscous coefficient"),),
    force=lambda q, qd, prm: prm[0] * qd**3,
    form="F3 * qd^3",
    signature="residual odd in velocity, growing fastest at the top speeds",
    signature_kinds=("velocity",),
    columns=(EffectColumn("F3", "N/(m/s)^3", "cubic viscous coefficient"),),
    build=lambda kin, value, fs_hz: np.c_[kin.qd**3],
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


def test_simulated(concealed: Path) -> None:
    """The plant integrated the toy's force: its own states and the logged force hold F3, and nothing without the effect does."""
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
