"""``benchmarks/identify_information_limit.py``: the oracle's spread of an estimate under a known coloured error."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

import benchmarks.identify_information_limit as bench


def test_the_autocovariance_is_the_simulators_disturbances() -> None:
    """The oracle's covariance is that of the force ``plant.sensors.draw_disturbance`` draws: its variance and its
    autocorrelation at 10 and 40 ms (a first-order filter or another corner would not match)."""
    from plant.sensors import draw_disturbance

    fs, std, bw = 1000.0, 0.4, 10.0
    acov = bench.disturbance_autocovariance(std, bw, fs, 60)
    assert acov[0] == pytest.approx(std**2, rel=1e-9)
    d = draw_disturbance(400_000, 7, {"disturbance": {"std": std, "bandwidth_hz": bw}}, fs)
    for lag in (0, 10, 40):
        empirical = float(np.mean(d[: len(d) - lag] * d[lag:]))
        assert empirical == pytest.approx(acov[lag], abs=0.03 * std**2), lag


def test_white_error_gives_the_least_squares_spread_and_a_coloured_one_a_smaller_blue() -> None:
    """A white error: OLS and BLUE are both sigma sqrt(diag (W'W)^-1). A slowly correlated error on a slow column: the BLUE's
    spread is below the OLS sandwich's, which is above the white formula's."""
    rng = np.random.Generator(np.random.PCG64(3))
    t = np.arange(400) / 100.0
    W = np.c_[np.ones_like(t), np.sin(2 * np.pi * 0.3 * t), np.sign(np.sin(2 * np.pi * 0.5 * t)), rng.standard_normal(len(t))]

    def std(cov: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        return np.sqrt(np.diag(cov[0])), np.sqrt(np.diag(cov[1]))

    white = std(bench.oracle_cov(W, t, 100.0, np.array([0.25])))
    formula = 0.5 * np.sqrt(np.diag(np.linalg.inv(W.T @ W)))
    np.testing.assert_allclose(white[0], formula, rtol=1e-9)
    np.testing.assert_allclose(white[1], formula, rtol=1e-9)
    coloured = std(bench.oracle_cov(W, t, 100.0, bench.disturbance_autocovariance(0.5, 5.0, 100.0, 200)))
    assert np.all(coloured[1] <= coloured[0] * (1 + 1e-9)) and np.any(coloured[1] < 0.95 * coloured[0])
    assert coloured[0][0] > 1.5 * formula[0]


def test_the_chance_of_all_within_the_bound() -> None:
    """Independent errors: the product of the normal chances; errors that lean together: more than that product."""
    truth = np.array([1.0, 2.0])
    sd = np.array([0.01, 0.02])
    exact = float(np.prod(2 * norm.cdf(bench.WITHIN / (sd / truth)) - 1))
    assert bench.within_chance(np.diag(sd**2), truth) == pytest.approx(exact, abs=0.004)
    lean = np.diag(sd) @ np.array([[1.0, 0.95], [0.95, 1.0]]) @ np.diag(sd)
    assert exact + 0.02 < bench.within_chance(lean, truth) < 2 * norm.cdf(2.0) - 1
