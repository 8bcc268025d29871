"""An estimate on the edge of its search range is never a finding (it would be found beyond the range searched)."""

from __future__ import annotations

import numpy as np

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.select import at_edge
from ilic_cli.effects import EFFECTS
from ilic_cli.simulation.scenarios import Overrides, run_scenario


def test_at_edge_of_the_grid_and_of_a_secondary_bound() -> None:
    grid = np.geomspace(0.001, 0.1, 21)
    stribeck = EFFECTS["stribeck"]
    assert "at the lower end" in (at_edge(stribeck, grid, 0.001) or "")
    assert "at the lower end" in (at_edge(stribeck, grid, 0.00111) or "")  # within half a (log) step
    assert at_edge(stribeck, grid, 0.00135) is None
    assert "at the upper end" in (at_edge(stribeck, grid, 0.1) or "")
    assert at_edge(stribeck, grid, 0.01) is None
    delay = EFFECTS["delay"]
    lin = np.arange(-0.025, 0.02501, 0.0005)
    assert at_edge(delay, lin, -0.0249) is not None and at_edge(delay, lin, -0.0005) is None  # linear scan: in plain steps
    flex = EFFECTS["flexibility"]
    f = np.geomspace(2.0, 40.0, 40)
    assert "damping_ratio = 0.4998 at a bound" in (at_edge(flex, f, (16.8, 0.4998)) or "")
    assert at_edge(flex, f, (16.8, 0.05)) is None


def test_a_clean_ctc_log_has_no_finding() -> None:
    """paper-sim with no extra physics (1 N force noise): the low-speed Stribeck fit is rejected (below Coulomb, or on the bottom of its grid)."""
    log = run_scenario("paper-sim", Overrides(duration_s=25.0, seed=3, effects={"noise": {"tau_std": 1.0}}))
    diag = diagnose(log, settings=DiagnoseSettings(simulate=False))
    assert diag.conclusion == "no significant mismatch", diag.to_dict()["selection"]
    reasons = [ev.reason for step in diag.tried for ev in step]
    assert any(r.startswith(("at the edge of its search range: vs = ", "physically impossible: static friction below Coulomb")) for r in reasons), reasons
