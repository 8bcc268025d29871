"""The instrumental-variable solve and the plant of an estimate (no simulation)."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.closed_loop_id import plant_of
from ilic_cli.lsq import solve, solve_iv


def system(seed: int = 0, n: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    W = rng.normal(size=(n, 3))
    theta = np.array([2.0, -1.0, 0.5])
    return W, W @ theta + 0.1 * rng.normal(size=n), theta


def test_iv_with_the_regressor_as_instruments_is_least_squares() -> None:
    W, y, _ = system()
    iv, ls = solve_iv(W, W, y, ("a", "b", "c")), solve(W, y, ("a", "b", "c"))
    np.testing.assert_allclose(iv.theta, ls.theta, rtol=1e-12)
    np.testing.assert_allclose(iv.std, ls.std, rtol=1e-10)  # sigma^2 (W'W)^-1 W'W (W'W)^-1 = eq. 9
    assert iv.rank == 3 and iv.error_norm == pytest.approx(ls.error_norm)


def test_iv_removes_the_bias_of_a_noisy_regressor() -> None:
    W, y, theta = system(1, 20000)
    rng = np.random.default_rng(2)
    noisy = W + 0.5 * rng.normal(size=W.shape)  # errors in variables: LS shrinks toward zero
    ls = solve(noisy, y, ("a", "b", "c"))
    iv = solve_iv(W, noisy, y, ("a", "b", "c"))  # noise-free instruments
    assert np.max(np.abs(ls.theta - theta)) > 0.2
    np.testing.assert_allclose(iv.theta, theta, atol=5 * np.max(iv.std))
    # the IV covariance: (Z'W)^-1 Z'Z (W'Z)^-1 scaled by the residual variance
    A = np.linalg.inv(W.T @ noisy)
    sig2 = np.sum((y - noisy @ iv.theta) ** 2) / (len(y) - 3)
    np.testing.assert_allclose(iv.std, np.sqrt(np.diag(sig2 * A @ (W.T @ W) @ A.T)), rtol=1e-10)


def test_iv_uncorrelated_instrument_is_not_identifiable() -> None:
    W, y, _ = system()
    Z = W.copy()
    Z[:, 2] = 0.0
    res = solve_iv(Z, W, y, ("a", "b", "c"))
    assert res.rank == 2 and np.all(np.isinf(res.std)) and not res.full_rank


def test_plant_of_rigid_and_asymmetric() -> None:
    rigid, eff = plant_of(("M", "Fv", "Fc", "offset"), np.array([95.0, 200.0, 20.0, -3.0]))
    assert rigid == {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0} and eff == {}
    rigid, eff = plant_of(("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"), np.array([95.0, 160.0, 20.0, 240.0, 21.0]))
    assert rigid["Fv_neg"] == 240.0 and eff == {}
