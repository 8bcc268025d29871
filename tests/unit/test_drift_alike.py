"""A drift whose coefficient the rows cannot tell (:mod:`ilic_cli.diagnosis.drift_alike`): on moves at one cruise speed a
trend of ``Fv`` and one of ``Fc`` explain the rows alike; at two speeds they do not."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.drift_alike import ALIKE_RULE, alike

N = 600
T = np.linspace(0.0, 10.0, N)
WARM = np.exp(-T / 2.5)


def _moves(speeds: tuple[float, ...], seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Back-and-forth moves (60 rows each, 4 of them on the ramps) at ``speeds`` in turn, and a warm-up of Fv on their force."""
    v = np.zeros(N)
    for k, start in enumerate(range(0, N, 60)):
        level = speeds[k % len(speeds)] * (1 if k % 2 == 0 else -1)
        v[start : start + 60] = level
        v[start : start + 2] = v[start + 58 : start + 60] = level / 2  # the ramps
    W = np.c_[v, np.sign(v)]
    y = W @ np.array([2.0, 6.0]) - 0.5 * v * WARM + np.random.default_rng(seed).normal(0.0, 0.2, N)
    return W, y, v


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_one_cruise_speed_cannot_tell_a_trend_of_fv_from_one_of_fc(seed: int) -> None:
    W, y, v = _moves((1.0,), seed)
    same = alike(W, y, (v * WARM, 1), [("Fc", np.sign(v) * WARM, 1)], 1, 1e-3)
    assert same is not None and same.parameter == "Fc"
    assert same.p_given_it >= 1e-3 and same.p_given_finding >= 1e-3
    assert "cannot tell which of Fv and Fc drifts" in same.words("Fv") and same.to_dict()["rule"] == ALIKE_RULE


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_two_cruise_speeds_tell_them(seed: int) -> None:
    W, y, v = _moves((1.0, 0.3), seed)
    assert alike(W, y, (v * WARM, 1), [("Fc", np.sign(v) * WARM, 1)], 1, 1e-3) is None
