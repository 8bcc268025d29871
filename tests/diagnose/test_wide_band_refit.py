"""The closed-loop refit of a resonance searched at the log's rate, in the band that sees it (``refit.wide_band``, issue 29)."""

from __future__ import annotations

from typing import Any

import pytest

import ilic_cli.diagnosis.refit as refit_module
from ilic_cli.diagnosis.core import diagnose
from ilic_cli.diagnosis.fits import METHOD, Refit
from ilic_cli.diagnosis.verdicts import RefitOutcome
from tests.corpus.robot import build, case_named

FLEX_500 = "rev0.5/trapezoid/500Hz/sensor/flexibility/s510"
"""A 28 Hz mode behind the 0.5 kg·m² joint, 0.4 of its inertia behind the spring (damping ratio 0.1), at 500 Hz: the rows keep 33 Hz."""


def _flexibility(seed: int) -> tuple[dict[str, float], dict[str, float], Refit]:
    built = build(case_named(FLEX_500, seed))
    diag = diagnose(built.log)
    (f,) = diag.findings
    assert f.effect.id == "flexibility" and f.plant_effect is not None and diag.refit is not None and diag.refit.accepted
    return f.plant_effect, built.effects["flexibility"], diag.refit


def test_a_500_hz_resonance_is_refitted_where_the_output_error_sees_it() -> None:
    """Seed 6510: the inverse model's damping ratio is 0.138 for 0.10 (the position's noise), and the refit in the rows' band
    kept it, the load behind the spring making up for it: 0.509 of the inertia for 0.4, the stiffness 19 % off. In the 67 Hz
    band its resonance and damping are searched on the closed loop (planted: the rows' band, fails): within 5 % (measured 1.2 %)."""
    plant, truth, refit = _flexibility(6510)
    assert refit.reason.startswith("in the 66.7 Hz band that sees the resonance: refitted on the closed loop")
    assert {s.parameter for s in refit.searches if s.accepted} == {"f_res", "damping_ratio"}
    for k in ("stiffness", "load_fraction", "damping"):
        assert plant[k] == pytest.approx(truth[k], rel=0.05), k


def test_where_didim_fails_in_that_band_the_output_error_fit_there_stands() -> None:
    """Seed 21510: DIDIM's iterate leaves the plant in the 67 Hz band; the inverse model's estimate replays there, and the
    output-error fit from it is kept (planted: no output-error fit after a failed DIDIM, the refit then in the rows' band, the
    stiffness 8 % low and the damping 19 % high; measured 1.8 %, -9.1 % and the load -0.9 %)."""
    plant, truth, refit = _flexibility(21510)
    assert refit.reason.startswith("in the 66.7 Hz band that sees the resonance: the closed-loop refit failed")
    assert "refitted instead by a closed-loop output-error fit" in refit.reason and refit.outcome is RefitOutcome.OUTPUT_ERROR
    assert "in the rows' band" not in refit.reason
    for k in ("stiffness", "load_fraction"):
        assert plant[k] == pytest.approx(truth[k], rel=0.05), k
    assert plant["damping"] == pytest.approx(truth["damping"], rel=0.15)


def test_where_the_refit_fails_in_that_band_the_rows_band_refit_stands(monkeypatch: pytest.MonkeyPatch) -> None:
    """The refit in the 67 Hz band failed (made to fail here: no log of the corpus's seeds was found where the output-error fit
    after a failed DIDIM fails too): the refit in the rows' band, the resonance the inverse model's, is kept, not the inverse
    model's estimate (planted: no rows' band refit, the load 27 % low; measured -3.0 % on seed 21510)."""
    real = refit_module.closed_loop_refit

    def failing_in_the_wide_band(*args: Any, **kwargs: Any) -> Refit:
        if kwargs["ls"].band_hz is None:  # the band that sees the resonance (refit.wide_band)
            return Refit(False, "the closed-loop refit failed (made to)", list(args[4]), (), outcome=RefitOutcome.FAILED)
        return real(*args, **kwargs)

    monkeypatch.setattr(refit_module, "closed_loop_refit", failing_in_the_wide_band)
    plant, truth, refit = _flexibility(21510)
    assert refit.reason.startswith("in the 66.7 Hz band that sees the resonance, the closed-loop refit failed (made to)")
    assert "; in the rows' band: refitted" in refit.reason and refit.method == METHOD and not refit.searches
    assert plant["load_fraction"] == pytest.approx(truth["load_fraction"], rel=0.05)
