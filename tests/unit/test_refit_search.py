"""The refit's closed-loop search of the kept effects' nonlinear values (``ilic_cli/diagnosis/refit_search.py``): pure parts."""

from __future__ import annotations

import math
import re

import numpy as np

from ilic_cli.diagnosis.fits import Point
from ilic_cli.diagnosis.refit_search import MAX_ROUNDS, search_all
from ilic_cli.diagnosis.system import Step
from ilic_cli.effects import EFFECTS

DELAY, STRIBECK = EFFECTS["delay"], EFFECTS["stribeck"]
LAG, VS = -0.000227, 0.008  # the optimum of the profile below


def _profile(coupling: float):  # type: ignore[no-untyped-def]
    """An output error (%) whose least is at (LAG, VS), the two values coupled (the valley oblique to both)."""

    def profile(steps: list[Step], theta: np.ndarray) -> Point:
        lag, vs = float(steps[0].value), float(steps[1].value)
        a, b = (lag - LAG) / 0.0001, math.log(vs / VS)
        error = 0.7 + (a + coupling * b) ** 2 + b**2
        return Point(error, theta, error, 0.0, theta)

    return profile


def _searched(coupling: float, restart: bool = True):  # type: ignore[no-untyped-def]
    grids = {"delay": np.arange(-0.002, 0.002, 0.00005), "stribeck": np.geomspace(0.001, 0.04, 32)}
    steps = [Step(DELAY, -0.00015), Step(STRIBECK, 0.0055)]
    profile = _profile(coupling)
    theta = np.zeros(3)
    return search_all([], steps, grids, profile(steps, theta), profile, [0], 1000, restart=restart)


def _rounds(reason: str) -> tuple[int, int]:
    """``(rounds, rounds that moved the value)`` of a search's reason."""
    m = re.search(r"(\d+) rounds of the coordinate search, moved in (\d+)", reason)
    assert m is not None, reason
    return int(m[1]), int(m[2])


def test_coupled_values_are_searched_in_rounds_until_a_round_stops_lowering_the_error() -> None:
    """The lag and vs coupled (as a current loop's lag and Stribeck friction are in the replay): one round of one search
    each leaves the lag 0.03 ms and vs 14 % off; rounds of the coordinate search, each moving both, end near the least."""
    (lag1, vs1), _, point1 = _searched(0.8, restart=False)
    (lag, vs), steps, point = _searched(0.8)
    assert abs(float(steps[0].value) - LAG) < 0.01e-3 and abs(float(steps[1].value) / VS - 1) < 0.03
    assert point.error < point1.error and abs(lag1.value - LAG) > 0.02e-3 and abs(vs1.value / VS - 1) > 0.1
    assert all(s.accepted and _rounds(s.reason)[0] == _rounds(s.reason)[1] >= 3 for s in (lag, vs)), (lag.reason, vs.reason)


def test_uncoupled_values_stop_at_the_round_that_moves_neither() -> None:
    """The values apart: the first round finds both, and the second, which moves neither, is the last."""
    (lag, vs), steps, _ = _searched(0.0)
    assert abs(float(steps[0].value) - LAG) < 0.01e-3 and abs(float(steps[1].value) / VS - 1) < 0.03
    assert all(_rounds(s.reason) == (2, 1) for s in (lag, vs)) and MAX_ROUNDS > 2
