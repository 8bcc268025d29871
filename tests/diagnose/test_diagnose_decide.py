"""The replay's per-fold search of a nonlinear value (``ilic_cli.diagnosis.decide.fold_value``) on a known training error, and
what the replay's verdict says of the folds whose search ended on the edge of its range."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from ilic_cli.diagnosis.decide import fold_value
from ilic_cli.diagnosis.heldout_replay import HeldoutReplays
from ilic_cli.diagnosis.search import FoldValue
from ilic_cli.diagnosis.select import SEARCH_STEPS, Step
from ilic_cli.diagnosis.verdicts import PROPOSED_BY_INVERSE, Verdict
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
    assert got.step.value == pytest.approx(-1.0e-3, abs=0.06e-3) and got.edge is None
    # the range: SEARCH_STEPS grid steps either side of the inverse value, nothing beyond
    half = SEARCH_STEPS["delay"] * 0.5e-3
    assert min(calls) >= -1.5e-3 - half - 1e-9 and max(calls) <= -1.5e-3 + half + 1e-9


def test_an_optimum_on_the_edge_keeps_the_inverse_value_and_says_where_the_edge_was() -> None:
    got = fold_value([], Step(DELAY, -1.66e-3), GRID, _error(-8.0e-3, []))
    assert got.step.value == -1.66e-3
    assert got.edge is not None and got.edge == pytest.approx(-1.5e-3 - SEARCH_STEPS["delay"] * 0.5e-3, abs=0.06e-3)  # the range's lower end


def test_no_lower_error_keeps_the_inverse_value() -> None:
    flat = lambda steps: 1.0  # noqa: E731
    assert fold_value([], Step(DELAY, -1.66e-3), GRID, flat).step.value == -1.66e-3


def _judged(used: list[FoldValue]) -> Any:
    """:meth:`HeldoutReplays.judge`'s verdict on a lag searched in each fold (``used``: each fold's search), the held-out force error
    falling 10 % -> 8 % at p = 1e-6 (1 kHz)."""
    replays = SimpleNamespace(
        compared=lambda current, after: ((10.0, 8.0), (0.1, 0.1), 1e-6, 0.0), data=SimpleNamespace(joint="prismatic", fs_hz=1000.0), min_delay_periods=0.05
    )
    held = (np.zeros(3), np.zeros(3), used)
    return HeldoutReplays.judge(replays, Step(DELAY, -0.42e-3), [], held, held, True, PROPOSED_BY_INVERSE, 0.05, None, None)  # type: ignore[arg-type]


def test_a_verdict_says_in_how_many_folds_the_search_ended_on_its_edge() -> None:
    """Corpus s3460: a 0.227 ms current loop's lag judged before the Stribeck friction beside it, the closed loop's training error
    falling on to -4 ms in every fold; the inverse model's -0.42 ms replayed there is not the closed loop's estimate, and the
    verdict says so (it read "searched on the closed loop ...: -0.42 ms to -0.42 ms", as if the closed loop agreed)."""
    inverse = Step(DELAY, -0.42e-3)
    verdict, judged = _judged([FoldValue(inverse, -3.93e-3), FoldValue(inverse, -3.83e-3), FoldValue(Step(DELAY, -0.3e-3))])
    assert verdict.verdict is Verdict.AGREES and judged == inverse  # the decision and the value are unchanged
    assert "in 2 of 3 folds the search's optimum lay on the edge of the range searched (-3.93 ms to -3.83 ms)" in verdict.reason
    assert verdict.searched == (-0.42e-3, -0.42e-3, -0.3e-3)
    verdict, _ = _judged([FoldValue(Step(DELAY, -0.3e-3)), FoldValue(Step(DELAY, -0.25e-3))])
    assert "edge" not in verdict.reason and "-0.3 ms to -0.25 ms (inverse model -0.42 ms)" in verdict.reason
