"""The replay's per-fold search of a nonlinear value (``ilic_cli.diagnosis.decide.fold_value``) on a known training error."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.decide import fold_value
from ilic_cli.diagnosis.select import SEARCH_STEPS, Step
from ilic_cli.effects import EFFECTS

DELAY = EFFECTS["delay"]
GRID = np.arange(-0.025, 0.025 + 0.00025, 0.0005)  # the delay's grid at 1 kHz


def _error(optimum_s: float, calls: list[float]):  # noqa: ANN202
    def training_error(steps: list[Step]) -> float:
        (st,) = steps
        calls.append(float(st.value))
        return 1.0 + ((float(st.value) - optimum_s) / 1e-3) ** 2

    return training_error


def test_the_optimum_within_the_range_is_taken() -> None:
    calls: list[float] = []
    got = fold_value([], Step(DELAY, -1.66e-3), GRID, _error(-1.0e-3, calls))
    assert got.value == pytest.approx(-1.0e-3, abs=0.06e-3)
    # the range: SEARCH_STEPS grid steps either side of the inverse value, nothing beyond
    half = SEARCH_STEPS["delay"] * 0.5e-3
    assert min(calls) >= -1.5e-3 - half - 1e-9 and max(calls) <= -1.5e-3 + half + 1e-9


def test_an_optimum_on_the_edge_keeps_the_inverse_value() -> None:
    got = fold_value([], Step(DELAY, -1.66e-3), GRID, _error(-8.0e-3, []))
    assert got.value == -1.66e-3


def test_no_lower_error_keeps_the_inverse_value() -> None:
    flat = lambda steps: 1.0  # noqa: E731
    assert fold_value([], Step(DELAY, -1.66e-3), GRID, flat).value == -1.66e-3
