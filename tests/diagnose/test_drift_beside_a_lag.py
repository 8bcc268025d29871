"""A drive lag on a chirp is no friction drift: a trend is a finding only with the force's time shift held and free
(:mod:`ilic_cli.diagnosis.drift_shift`, issue 29).

On a chirp the lag's force grows with time as a trend of Fv does. The independent simulator's 0.08 kg·m² joint, its viscous
friction four times its Coulomb friction at speed, following a chirp with a 1.5 ms drive lag, was named with a friction drift
beside the lag (1 kHz) or in its place (500 Hz, the loop a period late).
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.drift import detect_drift
from ilic_cli.diagnosis.drift_shift import found_both_ways
from tests.diagnose.test_drift import NAMES, TOLERANCE, _chirp

LAG_S = 1.5e-3


@pytest.mark.parametrize("seed", range(3))
def test_a_trend_found_with_the_shift_held_but_not_free_is_no_finding(seed: int) -> None:
    """Rows whose force lags the columns by 1 ms on a chirp: a trend of Fv with no shift modelled, none beside the shift's slope;
    both ways together, no finding, and the reason says which way it was not found. A true warm-up is found both ways and
    stands as found; a result without a finding is returned as it is."""
    t, W, y, slope = _chirp(seed)
    held, free = detect_drift(t, W, y, NAMES), detect_drift(t, W, y, NAMES, nuisance=slope)
    assert held.found and not free.found
    res = found_both_ways(held, free, "held at none", "free")
    assert not res.found and res.relative_error_after_pct is None
    assert res.reason.startswith("a trend of Fv (") and "found with the force's time shift held at none, not with it free (" in res.reason
    assert found_both_ways(free, held, "free", "held at none") is free
    t, W, y, slope = _chirp(seed, fv=lambda t: 200.0 - 50.0 * (1 - np.exp(-t / 6.0)))
    held, free = detect_drift(t, W, y, NAMES), detect_drift(t, W, y, NAMES, nuisance=slope)
    res = found_both_ways(free, held, "free", "held at none")
    assert res is free and res.found and res.findings[0].relative_change == pytest.approx(-0.25, rel=TOLERANCE)


def _chirp_with_a_lag(fs_hz: float, loop: str, seed: int):  # noqa: ANN202
    from tests.corpus.independent import run_loop
    from tests.corpus.robot import Axis, reference

    axis = Axis("rev0.08v", "revolute", {"M": 0.08, "Fv": 0.4, "Fc": 0.1}, 0.5, 2.0, 1.0, 1e-5, 1.2e-5)
    _, q_ref = reference(axis, "chirp", fs_hz, seed, 10.0)
    return run_loop(axis, fs_hz, q_ref, loop, {"delay": {"delay": LAG_S}}, seed, axis.name, substeps=40)  # the corpus's steps


def test_a_lag_kept_is_judged_at_its_stated_value_not_only_beside_its_slope() -> None:
    """1 kHz, seed 9191: the final rows hold the inverse model's -3 ms, and a trend of Fv +5.5 % stood beside the lag's slope; at
    the value the diagnosis states (the closed loop's, -1.6 ms) the trend is +0.5 %: the lag alone is named."""
    diag = diagnose(_chirp_with_a_lag(1000.0, "same", 9191), settings=DiagnoseSettings())
    assert [f.effect.id for f in diag.findings] == ["delay"]
    assert diag.findings[0].parameters["delay"].value == pytest.approx(-LAG_S, rel=0.1)
    assert diag.drift is not None and "found with the force's time shift free, not with it held at -1." in diag.drift.reason


def test_a_lag_no_model_holds_is_not_taken_by_a_drift() -> None:
    """500 Hz, the loop a period late, seed 9193: a trend of Fv -5.2 % on the rigid model, given to the selection, and the
    replay, whose plant's drift stood for the lag, rejected the lag (p = 0.098); the drift was then named in its place. With
    the shift free the trend is +4.1 %, below the 5 % a drift must move: no drift is named. (Nor is the lag: the drift is still
    sought on the rigid model alone, see :mod:`ilic_cli.diagnosis.drift_shift`.)"""
    diag = diagnose(_chirp_with_a_lag(500.0, "previous", 9193), settings=DiagnoseSettings())
    assert "friction_drift" not in [f.effect.id for f in diag.findings]
    assert diag.drift is not None and "found with the force's time shift held at none, not with it free (" in diag.drift.reason
