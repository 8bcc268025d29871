"""``lsq.solve_tall`` (a QR of ``[W y]``, then the SVD of ``R``) against ``lsq.solve`` (the SVD of ``W``)."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.lsq import solve, solve_tall


@pytest.mark.parametrize("sigma", ["sample_std", "eq8"])
def test_solve_tall_is_lsq_solve(sigma: str) -> None:
    """The same estimate, deviations, covariance and figures to the rounding of a system of condition 1e4."""
    rng = np.random.default_rng(3)
    rows, b = 20_000, 12
    W = rng.standard_normal((rows, b)) @ np.diag(np.logspace(0, -4, b)) @ np.linalg.qr(rng.standard_normal((b, b)))[0]
    y = W @ rng.standard_normal(b) + 0.01 * rng.standard_normal(rows) + 0.3
    names = tuple(f"p{i}" for i in range(b))
    want, got = solve(W, y, names, sigma=sigma), solve_tall(W, y, names, sigma=sigma)  # type: ignore[arg-type]
    assert got.names == want.names and got.rows == want.rows and got.rank == want.rank == b
    np.testing.assert_allclose(got.theta, want.theta, rtol=1e-9)
    np.testing.assert_allclose(got.std, want.std, rtol=1e-9)
    assert want.cov is not None and got.cov is not None
    np.testing.assert_allclose(got.cov, want.cov, rtol=1e-9, atol=1e-12 * np.abs(want.cov).max())
    for field in ("sigma_rho", "error_norm", "relative_error_pct", "condition_number"):
        assert getattr(got, field) == pytest.approx(getattr(want, field), rel=1e-9), field
    np.testing.assert_allclose(got.rel_std_pct, want.rel_std_pct, rtol=1e-9)


def test_solve_tall_leaves_rank_deficient_and_short_systems_to_lsq_solve() -> None:
    """An unexcited direction (infinite deviations) and a system hardly taller than wide: ``lsq.solve``'s bits."""
    rng = np.random.default_rng(4)
    W = rng.standard_normal((5000, 4))
    W[:, 3] = W[:, 0] + W[:, 1]
    y = rng.standard_normal(5000)
    names = ("a", "b", "c", "d")
    got, want = solve_tall(W, y, names), solve(W, y, names)
    assert got.rank == 3 and np.array_equal(got.theta, want.theta) and np.array_equal(got.std, want.std)
    short = rng.standard_normal((7, 4))
    assert np.array_equal(solve_tall(short, y[:7], names).theta, solve(short, y[:7], names).theta)
