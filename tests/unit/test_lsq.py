"""Least squares with standard deviations (paper eqs. 5-10) on systems small enough to solve by hand.

The reference case is the straight-line fit of ``y = [0, 1, 1, 3]`` at
``x = [0, 1, 2, 3]``: intercept -0.1, slope 0.9, residuals
``[0.1, 0.2, -0.7, 0.4]`` (RSS 0.7, mean 0). With ``r = 4`` rows and ``b = 2``
parameters, eq. 8 gives sigma^2 = 0.7/2 and the sample std 0.7/3;
``(W'W)^-1 = [[0.7, -0.3], [-0.3, 0.2]]``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli.lsq import bartlett_sum, column_basis, evaluate, lstsq, newey_west_lags, norm_pct, relative_error_pct, solve, solve_batch

X = np.array([0.0, 1.0, 2.0, 3.0])
W_LINE = np.c_[np.ones(4), X]
Y_LINE = np.array([0.0, 1.0, 1.0, 3.0])
NAMES = ("c", "s")


def test_line_fit_by_hand_eq8() -> None:
    r = solve(W_LINE, Y_LINE, NAMES, sigma="eq8")
    assert r.theta == pytest.approx([-0.1, 0.9], abs=1e-12)
    sig = math.sqrt(0.7 / 2)
    assert r.sigma_rho == pytest.approx(sig, rel=1e-12)
    assert r.std == pytest.approx([sig * math.sqrt(0.7), sig * math.sqrt(0.2)], rel=1e-12)
    assert r.rel_std_pct == pytest.approx([100 * sig * math.sqrt(0.7) / 0.1, 100 * sig * math.sqrt(0.2) / 0.9], rel=1e-12)
    assert r.error_norm == pytest.approx(math.sqrt(0.7), rel=1e-12)
    assert r.relative_error_pct == pytest.approx(100 * math.sqrt(0.7) / math.sqrt(11.0), rel=1e-12)
    # W'W = [[4, 6], [6, 14]]: eigenvalues (18 +- sqrt(244)) / 2, cond(W) = sqrt(lmax / lmin)
    lmax, lmin = (18 + math.sqrt(244)) / 2, (18 - math.sqrt(244)) / 2
    assert r.condition_number == pytest.approx(math.sqrt(lmax / lmin), rel=1e-12)
    assert r.rows == 4 and r.rank == 2 and r.full_rank
    assert r.names == NAMES


def test_line_fit_by_hand_sample_std() -> None:
    r = solve(W_LINE, Y_LINE, NAMES, sigma="sample_std")
    sig = math.sqrt(0.7 / 3)  # residual mean is 0: ddof = 1
    assert r.sigma_rho == pytest.approx(sig, rel=1e-12)
    assert r.std == pytest.approx([sig * math.sqrt(0.7), sig * math.sqrt(0.2)], rel=1e-12)
    # the default is eq. 8
    assert solve(W_LINE, Y_LINE, NAMES).sigma_rho == pytest.approx(math.sqrt(0.7 / 2), rel=1e-12)


def test_one_degree_of_freedom_eq8() -> None:
    """r - b = 1: sigma is the residual norm itself."""
    W = W_LINE[:3]
    y = Y_LINE[:3]  # fit of (0,0),(1,1),(2,1): slope 0.5, intercept 1/6, residuals -1/6, 1/3, -1/6
    r = solve(W, y, NAMES)
    assert r.theta == pytest.approx([1 / 6, 0.5], abs=1e-12)
    assert r.sigma_rho == pytest.approx(math.sqrt(1 / 36 + 1 / 9 + 1 / 36), rel=1e-12)


def test_square_system_is_exact_and_zero_error() -> None:
    W = np.array([[2.0, 1.0], [1.0, 3.0]])
    theta = np.array([1.5, -2.0])
    r = solve(W, W @ theta, NAMES)
    assert r.theta == pytest.approx(theta, abs=1e-12)
    assert r.error_norm == pytest.approx(0.0, abs=1e-12)
    assert np.all(r.std < 1e-10)


def test_exact_system_recovers_known_parameters() -> None:
    rng = np.random.default_rng(0)
    W = rng.standard_normal((60, 4))
    theta = np.array([95.0, 200.0, 20.0, -3.0])
    r = solve(W, W @ theta, ("M", "Fv", "Fc", "offset"))
    assert r.theta == pytest.approx(theta, rel=1e-12)
    assert r.relative_error_pct < 1e-10
    assert np.all(r.rel_std_pct < 1e-8)


def test_matches_normal_equations_on_noisy_data() -> None:
    """eq. 9: std_j = sigma * sqrt(((W'W)^-1)_jj), against the textbook formula."""
    rng = np.random.default_rng(1)
    W = rng.standard_normal((200, 3)) * [1.0, 10.0, 0.1]
    y = W @ [1.0, -2.0, 3.0] + 0.5 * rng.standard_normal(200)
    r = solve(W, y, ("a", "b", "c"))
    theta = np.linalg.solve(W.T @ W, W.T @ y)
    e = y - W @ theta
    sig = math.sqrt(e @ e / (200 - 3))
    assert r.theta == pytest.approx(theta, rel=1e-10)
    assert r.std == pytest.approx(sig * np.sqrt(np.diag(np.linalg.inv(W.T @ W))), rel=1e-10)
    assert r.condition_number == pytest.approx(np.linalg.cond(W), rel=1e-10)


def test_rank_deficient_gives_infinite_std_only_where_unidentifiable() -> None:
    x = np.linspace(-1.0, 1.0, 50)
    W = np.c_[x, x, np.cos(3 * x)]  # the first two columns are the same
    y = 2.0 * x + 0.5 * np.cos(3 * x)
    r = solve(W, y, ("a", "b", "c"))
    assert r.rank == 2 and not r.full_rank
    assert np.isinf(r.std[0]) and np.isinf(r.std[1]) and np.isfinite(r.std[2])
    assert np.isinf(r.rel_std_pct[0]) and np.isinf(r.rel_std_pct[1])
    assert math.isinf(r.condition_number)
    assert r.theta[0] == pytest.approx(1.0) and r.theta[1] == pytest.approx(1.0)  # minimum norm
    assert r.theta[2] == pytest.approx(0.5)
    p = r.parameters()
    assert p["a"]["std"] is None and p["a"]["rel_std_pct"] is None and p["c"]["std"] is not None
    d = r.to_dict()
    assert d["condition_number"] is None and d["rank"] == 2 and d["rows"] == 50


def test_zero_parameter_has_infinite_relative_std_and_zero_force_infinite_error() -> None:
    z = solve(W_LINE, np.zeros(4), NAMES)
    assert np.all(z.theta == 0) and np.all(np.isinf(z.rel_std_pct))
    assert math.isinf(z.relative_error_pct)
    assert z.to_dict()["relative_error_pct"] is None


def test_to_dict_reports_the_estimates() -> None:
    r = solve(W_LINE, Y_LINE, NAMES, sigma="eq8")
    d = r.to_dict()
    assert set(d) == {"parameters", "relative_error_pct", "error_norm", "error_std", "condition_number", "rows", "rank"}
    assert d["parameters"]["s"]["value"] == pytest.approx(0.9)
    assert d["parameters"]["s"]["std"] == pytest.approx(math.sqrt(0.35 * 0.2))
    assert d["parameters"]["s"]["rel_std_pct"] == pytest.approx(100 * math.sqrt(0.35 * 0.2) / 0.9)
    assert d["error_std"] == pytest.approx(math.sqrt(0.35))
    assert d["error_norm"] == pytest.approx(math.sqrt(0.7))
    assert d["relative_error_pct"] == pytest.approx(100 * math.sqrt(0.7 / 11))
    assert d["rows"] == 4 and d["rank"] == 2


def test_batch_solves_each_system_independently() -> None:
    rng = np.random.default_rng(2)
    W = rng.standard_normal((3, 30, 2))
    y = rng.standard_normal((3, 30))
    W[1, :, 1] = W[1, :, 0]  # one rank-deficient window among full ones
    batch = solve_batch(W, y, NAMES)
    for k in range(3):
        one = solve(W[k], y[k], NAMES)
        assert batch[k].theta == pytest.approx(one.theta, rel=1e-10, abs=1e-12)
        assert batch[k].rank == one.rank
        np.testing.assert_allclose(batch[k].std, one.std, rtol=1e-10)
    assert batch[0].full_rank and not batch[1].full_rank and batch[2].full_rank


def test_evaluate_fixed_parameters() -> None:
    """Cross-test validation: fixed theta, sample-std convention."""
    r = evaluate(W_LINE, Y_LINE, np.array([0.0, 2.0]), NAMES)  # residuals [0, -1, -3, -3], mean -1.75
    assert list(r.theta) == [0.0, 2.0]
    assert r.error_norm == pytest.approx(math.sqrt(19.0))
    assert r.sigma_rho == pytest.approx(1.5)  # deviations 1.75, .75, -1.25, -1.25: 6.75 / 3 = 2.25
    assert r.relative_error_pct == pytest.approx(100 * math.sqrt(19.0 / 11.0))
    assert r.std == pytest.approx([1.5 * math.sqrt(0.7), 1.5 * math.sqrt(0.2)])
    assert np.isinf(r.rel_std_pct[0]) and r.rel_std_pct[1] == pytest.approx(100 * 1.5 * math.sqrt(0.2) / 2.0)
    lmax, lmin = (18 + math.sqrt(244)) / 2, (18 - math.sqrt(244)) / 2
    assert r.condition_number == pytest.approx(math.sqrt(lmax / lmin))
    assert r.rows == 4 and r.rank == 2 and r.names == NAMES
    assert evaluate(np.c_[X, X], Y_LINE, np.array([0.5, 0.5]), NAMES).rank == 1
    one = evaluate(W_LINE, Y_LINE, np.array([0.0, 1.0]), NAMES)  # residuals [0, 0, -1, 0]: sample std 0.5
    assert one.rel_std_pct[1] == pytest.approx(100 * 0.5 * math.sqrt(0.2))
    W3 = np.random.default_rng(4).standard_normal((20, 3))
    assert evaluate(W3, W3 @ [1.0, 2.0, 3.0] + 1.0, np.ones(3), ("a", "b", "c")).condition_number == pytest.approx(np.linalg.cond(W3))


def test_results_are_immutable() -> None:
    import dataclasses

    r = solve(W_LINE, Y_LINE, NAMES)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.rank = 3  # type: ignore[misc]


def test_small_forces_have_a_finite_relative_error() -> None:
    r = solve(W_LINE, 0.01 * Y_LINE, NAMES)  # ||y|| = 0.033
    assert r.relative_error_pct == pytest.approx(100 * math.sqrt(0.7 / 11), rel=1e-9)


def test_rank_deficient_noisy_system_is_the_minimum_norm_solution() -> None:
    rng = np.random.default_rng(6)
    x = np.linspace(-1.0, 1.0, 50)
    W = np.c_[x, x, np.cos(3 * x)]
    y = 2.0 * x + 0.5 * np.cos(3 * x) + 0.1 * rng.standard_normal(50)
    r = solve(W, y, ("a", "b", "c"))
    want = np.linalg.lstsq(W, y, rcond=None)[0]
    assert r.theta == pytest.approx(want, rel=1e-9)
    # the identifiable parameter's std is that of the reduced system [x, cos 3x]
    reduced = solve(np.c_[x, np.cos(3 * x)], y, ("ab", "c"))
    sig_ratio = math.sqrt((50 - 2) / (50 - 3))  # eq. 8 divides by r - b with b = 3 columns
    assert r.std[2] == pytest.approx(reduced.std[1] * sig_ratio, rel=1e-9)


def test_column_basis_spans_the_columns_under_the_rank_rule() -> None:
    rng = np.random.default_rng(11)
    w = rng.standard_normal((50, 3))
    W = np.hstack([w, w[:, :1] + w[:, 1:2], 1e-18 * rng.standard_normal((50, 1))])  # rank 3: a sum, and a column below the rule
    U = column_basis(W)
    assert U.shape == (50, 3)
    np.testing.assert_allclose(U.T @ U, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(U @ (U.T @ w), w, atol=1e-12)  # the span of the columns, nothing lost
    assert column_basis(np.zeros((4, 2))).shape == (4, 0)
    assert column_basis(np.zeros((4, 0))).shape[1] == 0


def test_lstsq_gives_the_estimate_and_its_residual_sum_of_squares() -> None:
    rng = np.random.default_rng(12)
    W = rng.standard_normal((40, 3))
    y = W @ np.array([1.0, -2.0, 0.5]) + 0.1 * rng.standard_normal(40)
    theta, rss = lstsq(W, y)
    np.testing.assert_allclose(theta, np.linalg.lstsq(W, y, rcond=None)[0], rtol=1e-12)
    assert rss == pytest.approx(float(np.sum((y - W @ theta) ** 2)), rel=1e-12) and 0 < rss < 1.0
    # rank-deficient: the minimum-norm estimate under the rank rule (a duplicated column shares its weight)
    theta2, rss2 = lstsq(np.hstack([W[:, :1], W[:, :1]]), 2.0 * W[:, 0])
    np.testing.assert_allclose(theta2, [1.0, 1.0], rtol=1e-10)
    assert rss2 == pytest.approx(0.0, abs=1e-20)


def test_the_newey_west_sum_is_the_bartlett_weighted_autocovariance() -> None:
    """``bartlett_sum``: sum over |l| <= L of (1 - |l|/(L+1)) sum_t g_t g_(t-l)', term by term; the lags floor(4 (n/100)^(2/9)), below n."""
    g = np.random.default_rng(7).standard_normal((50, 2))
    L = 3
    want = np.zeros((2, 2))
    for lag in range(-L, L + 1):
        w = 1.0 - abs(lag) / (L + 1.0)
        for t in range(50):
            if 0 <= t - lag < 50:
                want += w * np.outer(g[t], g[t - lag])
    np.testing.assert_allclose(bartlett_sum(g, L), want, rtol=1e-12)
    assert [newey_west_lags(n) for n in (1, 2, 3, 100, 1000)] == [0, 1, 1, 4, 6]


def test_the_most_correlated_estimates_by_hand() -> None:
    """The pair of largest |r|, with its sign; an estimate without variance (or a NaN) takes no part; fewer than two: none."""
    from ilic_cli.lsq import most_correlated

    s = np.array([1.0, 2.0, 0.5, 3.0])
    r = np.eye(4)
    r[1, 2] = r[2, 1] = -0.962  # the robot corpus's Fv and Fc on one cruise speed
    r[0, 3] = r[3, 0] = 0.899  # smaller, positive
    names = ("M", "Fv", "Fc", "offset")
    assert most_correlated(names, r * np.outer(s, s)) == ("Fv", "Fc", pytest.approx(-0.962))
    r[0, 3] = r[3, 0] = 0.97
    assert most_correlated(names, r * np.outer(s, s)) == ("M", "offset", pytest.approx(0.97))
    cov = r * np.outer(s, s)
    cov[0, :] = cov[:, 0] = 0.0  # M without variance: the next pair
    assert most_correlated(names, cov) == ("Fv", "Fc", pytest.approx(-0.962))
    cov[1, 2] = cov[2, 1] = np.nan
    assert most_correlated(names, cov)[:2] in {("Fv", "offset"), ("Fc", "offset")}
    cov[3, 3] = np.inf  # an unidentifiable estimate (rank-deficient rows): no correlation either
    assert most_correlated(names, cov) is None
    assert most_correlated(("M",), np.eye(1)) is None


def test_noise_corrected_least_squares_undoes_the_attenuation_of_a_noisy_column() -> None:
    """Errors in the variables: a column measured with noise as large as its signal halves plain least squares'
    coefficient; corrected for the noise's covariance (its realisations given), the coefficient is the truth's."""
    from ilic_cli.lsq import lstsq, noise_corrected_lstsq

    rng = np.random.default_rng(3)
    n = 20000
    x = rng.standard_normal(n)
    noise = rng.standard_normal((8, n, 1))  # realisations of the column's noise, independent of the one it carries
    W = np.c_[x + rng.standard_normal(n)]
    y = 2.0 * x + 0.1 * rng.standard_normal(n)
    plain, _ = lstsq(W, y)
    corrected, rss = noise_corrected_lstsq(W, y, noise)
    assert abs(plain[0] - 1.0) < 0.05 and abs(corrected[0] - 2.0) < 0.06
    assert rss == pytest.approx(float(np.sum((y - W @ corrected) ** 2)))
    too_much = noise_corrected_lstsq(W, y, 3.0 * noise)  # more noise than the column holds: not resolved, plain least squares
    assert np.allclose(too_much[0], plain)


def test_one_relative_error_from_arrays_or_from_norms() -> None:
    """The output-error fits keep the force's norm and take each residual's: the same figure, to the bit."""
    y, y_hat = np.array([3.0, -4.0, 12.0]), np.array([2.5, -4.0, 11.0])
    assert relative_error_pct(y, y_hat) == norm_pct(float(np.linalg.norm(y - y_hat)), 13.0) == 100.0 * math.sqrt(1.25) / 13.0
    assert norm_pct(1.0, 0.0) == math.inf and relative_error_pct(np.zeros(3), np.ones(3)) == math.inf
