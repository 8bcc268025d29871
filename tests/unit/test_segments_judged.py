"""The open-loop segments' fit of a Stribeck friction judged (``strategies.stribeck._segments_judged``), on its own: a fit that
explains the recording to its noise refutes the friction when its level is not enough standard deviations above zero, or when
its impulse ``Fs·vs`` is below the least the closed-loop search tries (what that search reads as no friction). The diagnosis
shows the second rule on one log only (``tests/diagnose/test_independent_loop.py``: the independent simulator's 12 kg
trapezoid at 250 Hz, seed 23, the segments' Fs 0.0104 N at vs 43 mm/s), whose false friction a change of the inverse
model's rows can take away (zeroing the dwells before the decimation did, on seeds 1-90: docs/methods.md); its figures
are those of this test."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ilic_cli.diagnosis.strategies.stribeck import _segments_judged
from ilic_cli.diagnosis.verdicts import RefitOutcome


def _judged(level: float, level_std: float, vs: float, least_impulse: float) -> tuple[object, str | None]:
    fit = SimpleNamespace(
        consistent=True,
        segments=12,
        rms_m=0.5e-6,
        rms_start_m=3e-6,
        iterations=4,
        values=np.array([12.0, 35.0, 4.0, level]),
        std=np.array([0.01, 0.1, 0.01, level_std]),
    )
    step = SimpleNamespace(level=(5.2, 0.1), effect=SimpleNamespace(column_names=("stribeck",)), value=vs)
    data = SimpleNamespace(joint="prismatic")
    names = ("M", "Fv", "Fc", "stribeck")
    return _segments_judged(fit, [step], step, [], [], [0], names, names, data, 250.0, 5e-7, (0.5, 2.0), least_impulse)  # type: ignore[arg-type]


def test_a_level_above_zero_whose_impulse_is_below_the_search_s_least_refutes_the_friction() -> None:
    refit, refuted = _judged(0.0104, 0.001, 0.043, least_impulse=0.0104 * 0.043 / 0.24)  # 11 sd above zero, a quarter of the least
    assert refuted is not None and refit.outcome is RefitOutcome.SEGMENTS_REFUTED and not refit.accepted  # type: ignore[attr-defined]
    assert "below the least the closed-loop search tries" in refuted and "0.0104 +- 0.001 N" in refuted


def test_a_level_not_above_zero_refutes_the_friction() -> None:
    refit, refuted = _judged(0.0015, 0.001, 0.043, least_impulse=1e-6)
    assert refuted is not None and refit.outcome is RefitOutcome.SEGMENTS_REFUTED  # type: ignore[attr-defined]
    assert "is not 2 standard deviations above zero" in refuted
