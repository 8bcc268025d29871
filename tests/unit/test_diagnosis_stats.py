"""Statistics of the diagnosis on cases with a hand-derived or textbook answer."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from ilic_cli.diagnosis.stats import (
    ar_fit,
    batched_rss,
    blocked_folds,
    chi2_sf,
    diebold_mariano,
    effective_size,
    f_sf,
    folds_either_side,
    gls_covariance,
    heldout_errors,
    heldout_fall_p,
    lag1_autocorrelation,
    nested_f_test,
    normal_isf,
    normal_sf,
    shifted_rss,
    whiten,
)
from ilic_cli.lsq import lstsq, relative_error_pct

X = np.array([0.0, 1.0, 2.0, 3.0])
W_LINE = np.c_[np.ones(4), X]
Y_LINE = np.array([0.0, 1.0, 1.0, 3.0])  # intercept -0.1, slope 0.9, RSS 0.7


def test_lstsq_and_relative_error_by_hand() -> None:
    theta, rss = lstsq(W_LINE, Y_LINE)
    assert theta == pytest.approx([-0.1, 0.9])
    assert rss == pytest.approx(0.7)
    assert relative_error_pct(Y_LINE, W_LINE @ theta) == pytest.approx(100 * math.sqrt(0.7 / 11))
    theta, rss = lstsq(np.c_[X, X], 2 * X)  # rank-deficient: minimum norm
    assert theta == pytest.approx([1.0, 1.0]) and rss == pytest.approx(0.0, abs=1e-20)


def test_lag1_autocorrelation_by_hand() -> None:
    assert lag1_autocorrelation(np.array([1.0, -1.0, 1.0, -1.0])) == pytest.approx(-0.75)
    assert lag1_autocorrelation(np.array([3.0, 4.0, 5.0, 6.0])) == pytest.approx((0.75 - 0.25 + 0.75) / 5.0)  # mean 4.5 removed
    assert lag1_autocorrelation(np.full(5, 2.0)) == 0.0


def test_effective_size() -> None:
    assert effective_size(100, 0.5) == pytest.approx(100 / 3)
    assert effective_size(100, -0.5) == pytest.approx(300.0)
    assert effective_size(100, 0.0) == 100.0
    assert effective_size(100, 0.999) == 2.0  # rho clipped at 0.99: 0.5, then at least 2
    assert effective_size(100, -5.0) == pytest.approx(100 * 1.99 / 0.01)
    assert effective_size(1000, 0.995) == pytest.approx(1000 * 0.01 / 1.99)


def test_whiten_by_hand() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(whiten(x, np.array([0.5])), [1.5, 2.0, 2.5])
    np.testing.assert_allclose(whiten(x, np.array([0.5, 0.25])), [3 - 1 - 0.25, 4 - 1.5 - 0.5])
    np.testing.assert_array_equal(whiten(x, np.zeros(0)), x)
    X2 = np.c_[x, 2 * x]
    np.testing.assert_allclose(whiten(X2, np.array([0.5])), np.c_[[1.5, 2.0, 2.5], [3.0, 4.0, 5.0]])


def test_ar_fit_orders() -> None:
    rng = np.random.default_rng(0)
    w = rng.standard_normal(4000)
    assert len(ar_fit(w)) == 0  # white noise: BIC keeps no lag
    e = np.zeros(4000)
    for i in range(2, 4000):
        e[i] = 0.5 * e[i - 1] - 0.3 * e[i - 2] + w[i]
    a = ar_fit(e)
    assert len(a) == 2 and a == pytest.approx([0.5, -0.3], abs=0.05)
    assert len(ar_fit(e, max_order=1)) == 1
    assert len(ar_fit(e[:4])) == 0  # too short for one lag on a quarter of the rows
    assert len(ar_fit(e[:9], max_order=10)) <= 2


def test_f_test_without_whitening_is_the_textbook_f_test() -> None:
    """max_order 0: no whitening; F = ((RSS0 - RSS1)/q) / (RSS1/(n - k0 - q))."""
    rng = np.random.default_rng(1)
    n = 60
    t = np.linspace(0, 1, n)
    W0 = np.c_[np.ones(n), t]
    W1 = np.c_[W0, np.sin(6 * t), np.cos(6 * t)]
    y = W0 @ [1.0, 2.0] + 0.3 * np.sin(6 * t) + 0.5 * rng.standard_normal(n)
    _, rss0 = lstsq(W0, y)
    _, rss1 = lstsq(W1, y)
    F = ((rss0 - rss1) / 2) / (rss1 / (n - 2 - 2))
    p = stats.f.sf(F, 2, n - 4)
    res = nested_f_test(W0, y, W1, y, q=2, trials=7, max_order=0)
    assert (res.df1, res.df2, res.ar_order) == (2, n - 4, 0)
    assert res.F == pytest.approx(F, rel=1e-9)
    assert res.p_value == pytest.approx(p, rel=1e-9)
    assert res.trials == 7 and res.p_adjusted == pytest.approx(min(1.0, 7 * p), rel=1e-9)
    assert res.delta_bic == pytest.approx(n * math.log(rss1 / rss0) + 2 * math.log(n), rel=1e-9)
    e1 = y - W1 @ lstsq(W1, y)[0]
    assert res.rho == pytest.approx(lag1_autocorrelation(e1))
    d = res.to_dict()
    assert d["bonferroni_trials"] == 7 and d["p_adjusted"] == res.p_adjusted and d["F"] == res.F
    # Bonferroni: the adjusted p-value is capped at 1
    big = nested_f_test(W0, y, W1, y, q=2, trials=10**9, max_order=0)
    assert big.p_adjusted == 1.0 and big.p_value == pytest.approx(p, rel=1e-9)
    # a candidate that explains nothing: F = 0, p = 1
    same = nested_f_test(W0, y, np.c_[W0, W0[:, 1]], y, q=1, max_order=0)
    assert same.F == pytest.approx(0.0, abs=1e-9) and same.p_value == pytest.approx(1.0)


def test_f_test_whitens_both_models_with_the_larger_models_filter() -> None:
    rng = np.random.default_rng(2)
    n = 400
    t = np.linspace(0, 1, n)
    W0 = np.c_[np.ones(n), t]
    W1 = np.c_[W0, np.sin(9 * t)]
    e = np.zeros(n)
    w = rng.standard_normal(n)
    for i in range(1, n):
        e[i] = 0.8 * e[i - 1] + w[i]
    y = W0 @ [1.0, 2.0] + 2.0 * np.sin(9 * t) + e
    res = nested_f_test(W0, y, W1, y, q=1)
    a = ar_fit(y - W1 @ lstsq(W1, y)[0])
    assert res.ar_order == len(a) >= 1
    _, r0 = lstsq(whiten(W0, a), whiten(y, a))
    _, r1 = lstsq(whiten(W1, a), whiten(y, a))
    m = n - len(a)
    assert res.df2 == m - 2 - 1
    assert res.F == pytest.approx((r0 - r1) / (r1 / (m - 3)), rel=1e-9)


def test_gls_covariance_without_whitening_is_ols() -> None:
    rng = np.random.default_rng(3)
    W = np.c_[np.ones(50), rng.standard_normal(50)]
    y = W @ [1.0, 2.0] + rng.standard_normal(50)
    theta, rss = lstsq(W, y)
    cov = gls_covariance(W, y, theta, max_order=0)
    np.testing.assert_allclose(cov, rss / 48 * np.linalg.inv(W.T @ W), rtol=1e-9)


def test_blocked_folds_partition_time_with_guards() -> None:
    folds = blocked_folds(103, 4, 5)
    assert len(folds) == 4
    tests = [te for _, te in folds]
    np.testing.assert_array_equal(np.concatenate(tests), np.arange(103))
    for train, test in folds:
        a, b = test[0], test[-1] + 1
        assert np.all(np.diff(test) == 1)
        # training: every row at least `guard` away from the block, and nothing else
        want = [i for i in range(103) if i < a - 5 or i >= b + 5]
        np.testing.assert_array_equal(train, want)
    assert [len(te) for te in tests] == [25, 26, 26, 26]  # edges 0, 25, 51, 77, 103


def test_folds_either_side_of_a_change_train_on_both_sides() -> None:
    """Each fold holds out one block of each side of the change, trains on both, with the guard around each held-out block."""
    t = np.arange(103) * 0.1
    folds = folds_either_side(t, 8.0, 4, 3)  # the change at row 80: sides of 80 and 23 rows
    tests = [te for _, te in folds]
    np.testing.assert_array_equal(np.sort(np.concatenate(tests)), np.arange(103))
    assert [te[te >= 80][[0, -1]].tolist() for te in tests] == [[80, 84], [85, 90], [91, 96], [97, 102]]  # blocked_folds(23, 4)
    for train, test in folds:
        before, after = test[test < 80], test[test >= 80]
        assert len(before) == 20 and np.all(np.diff(before) == 1) and np.all(np.diff(after) == 1)
        assert np.sum(train >= 80) >= 23 - len(after) - 6 > 0 and np.sum(train < 80) > 0
        want = [i for i in range(103) if all(i < r[0] - 3 or i > r[-1] + 3 for r in (before, after))]
        np.testing.assert_array_equal(train, want)
    # blocked over the whole log, the last fold would train on no row after the change
    assert not np.any(blocked_folds(103, 4, 3)[-1][0] >= 80)
    for change in (None, 0.2, 10.1):  # no change, or fewer than k rows on a side: the plain blocks
        assert all(
            np.array_equal(a[1], b[1]) and np.array_equal(a[0], b[0]) for a, b in zip(folds_either_side(t, change, 4, 3), blocked_folds(103, 4, 3), strict=True)
        )


def test_batched_and_shifted_rss_match_single_fits() -> None:
    rng = np.random.default_rng(4)
    W0 = rng.standard_normal((80, 3))
    Y = rng.standard_normal((80, 6))
    np.testing.assert_allclose(shifted_rss(W0, Y), [lstsq(W0, Y[:, g])[1] for g in range(6)], rtol=1e-9)
    y = rng.standard_normal(80)
    X = rng.standard_normal((80, 4, 1))
    np.testing.assert_allclose(batched_rss(W0, y, X), [lstsq(np.hstack([W0, X[:, g]]), y)[1] for g in range(4)], rtol=1e-6)


def test_heldout_errors_of_an_exact_model_vanish_and_a_wrong_one_do_not() -> None:
    t = np.linspace(0, 1, 100)
    W = np.c_[np.ones(100), t]
    folds = blocked_folds(100, 5, 3)
    np.testing.assert_allclose(heldout_errors(W, W @ [1.0, 2.0], folds), 0.0, atol=1e-9)
    y = np.where(t < 0.2, 5.0, 0.0)  # a step in the first block only: training never sees it
    e = heldout_errors(W, y, folds)
    assert e[:20] == pytest.approx(5.0, abs=1e-9)
    assert not np.isnan(e).any()


def newey_west_p(e_before: np.ndarray, e_after: np.ndarray) -> float:
    """One-sided p-value by the Diebold-Mariano docstring's formula (Bartlett weights, floor(4 (n/100)^(2/9)) lags).

    Parameters
    ----------
    e_before, e_after : ndarray
        Errors of the two models.
    """
    d = e_before**2 - e_after**2
    n = len(d)
    dc = d - d.mean()
    L = int(4 * (n / 100) ** (2 / 9))
    lrv = dc @ dc / n + sum(2 * (1 - k / (L + 1)) * (dc[k:] @ dc[:-k]) / n for k in range(1, L + 1))
    return float(stats.norm.sf(d.mean() / math.sqrt(lrv / n)))


def test_diebold_mariano() -> None:
    assert diebold_mariano(np.ones(2), np.zeros(2)) == 1.0  # too short
    assert diebold_mariano(np.ones(10), np.zeros(10)) == 0.0  # always better, no variance
    assert diebold_mariano(np.zeros(10), np.ones(10)) == 1.0
    assert diebold_mariano(np.ones(10), np.ones(10)) == 1.0  # identical errors: not better
    three = (np.array([1.0, 2.0, 3.0]), np.zeros(3))  # n = 3 is enough: one lag
    assert diebold_mariano(*three) == pytest.approx(newey_west_p(*three), rel=1e-9)
    assert 0.001 < diebold_mariano(*three) < 0.05
    rng = np.random.default_rng(5)
    e = rng.standard_normal(500)
    assert int(4 * (500 / 100) ** (2 / 9)) == 5
    for c in (0.98, 0.99):  # p about 2e-4 and 0.17
        after = e * c + 0.1 * rng.standard_normal(500)
        p = newey_west_p(e, after)
        assert 1e-5 < p < 0.5
        assert diebold_mariano(e, after) == pytest.approx(p, rel=1e-9)
        assert diebold_mariano(0.01 * e, 0.01 * after) == pytest.approx(p, rel=1e-9)  # scale-free
    with_nan = np.r_[np.nan, e]
    assert diebold_mariano(with_nan, np.r_[0.0, after]) == pytest.approx(diebold_mariano(e, after))


def test_the_absolute_loss_sees_a_fall_that_a_few_large_errors_hide_from_the_squared_one() -> None:
    """A threefold fall in all but 10 of 500 samples, whose errors 20 times the others the candidate moves either way (corpus
    s440: the held-out error falls in every block, and a few large ones set the squared differential's long-run variance)."""
    rng = np.random.default_rng(11)
    n = 500
    before = rng.standard_normal(n)
    after = before / 3 + 0.05 * rng.standard_normal(n)
    k = rng.choice(n, 10, replace=False)
    before[k] = 20.0
    after[k] = 20.0 * rng.uniform(0.6, 1.25, 10)
    p_sq, p_abs = diebold_mariano(before, after), diebold_mariano(before, after, "absolute")
    assert p_sq > 0.01 and p_abs < 1e-6
    assert p_abs <= heldout_fall_p(before, after) <= 2 * p_abs  # the larger statistic against its own null: between one p and twice it
    assert heldout_fall_p(after, before) > 0.9  # a rise: no fall by either loss
    # either loss alone decides: the squared one where the fall is in a few large errors (a breakaway's)
    spikes = 0.1 * rng.standard_normal(n)
    spikes[::50] = 5.0
    fixed = spikes.copy()
    fixed[::50] = 0.0
    least = min(diebold_mariano(spikes, fixed), diebold_mariano(spikes, fixed, "absolute"))
    assert least <= heldout_fall_p(spikes, fixed) <= 2 * least < 0.01


def test_the_held_out_test_at_its_edges() -> None:
    """Too few samples: no evidence (p = 1); three are enough (one lag). A differential without variance: each loss's own rule."""
    assert heldout_fall_p(np.ones(2), np.zeros(2)) == 1.0
    three = (np.array([1.0, 2.0, 3.0]), np.array([0.5, 0.9, 1.6]))
    assert heldout_fall_p(*three) < 1.0
    assert heldout_fall_p(np.ones(10), np.zeros(10)) == 0.0  # always better by the same amount: certain
    assert heldout_fall_p(np.ones(10), np.ones(10)) == 1.0  # identical errors: no fall
    flat_sq = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])  # squared differential constant (1 - 0.25), absolute one too
    assert heldout_fall_p(flat_sq, 0.5 * flat_sq) == 0.0
    after = np.tile([0.0, 0.75, -0.75, 0.0, 0.75], 10)
    before = np.where(after == 0.0, 1.0, 1.25)  # 1.25^2 - 0.75^2 = 1 exactly: the squared differential constant, the absolute one not
    assert heldout_fall_p(before, after) == 0.0


def test_the_held_out_tests_null_is_the_larger_of_two_correlated_normals() -> None:
    """``P(max(Z1, Z2) > a)`` for ``Z1, Z2`` standard normal with correlation ``rho``: Owen's ``T`` form against numerical integration
    of ``1 - P(Z1 <= a, Z2 <= a)``; ``rho`` from the long-run covariance of the two differentials."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal(800)
    before, after = x + 0.3 * rng.standard_normal(800), x + 0.3 * rng.standard_normal(800)
    after[:400] *= 0.9  # a small fall: both statistics near 2
    d = np.c_[before**2 - after**2, np.abs(before) - np.abs(after)]
    n, dc = len(d), d - d.mean(axis=0)
    lags = int(4 * (n / 100) ** (2 / 9))
    S = dc.T @ dc / n + sum((1 - k / (lags + 1)) * (dc[k:].T @ dc[:-k] + dc[:-k].T @ dc[k:]) / n for k in range(1, lags + 1))
    z = d.mean(axis=0) / np.sqrt(np.diag(S) / n)
    rho, a = S[0, 1] / math.sqrt(S[0, 0] * S[1, 1]), z.max()
    assert 0.3 < rho < 0.99 and 1.0 < a < 4.0
    inside = stats.multivariate_normal([0.0, 0.0], [[1.0, rho], [rho, 1.0]]).cdf([a, a])
    assert heldout_fall_p(before, after) == pytest.approx(1.0 - inside, rel=1e-4)


def test_the_held_out_test_keeps_its_level_on_equal_models() -> None:
    """Two equally good predictions (independent AR(1) errors of one variance): p <= 0.05 in at most about 5 % of 400 draws."""
    rng = np.random.default_rng(2)
    hits = 0
    for _ in range(400):
        w = rng.standard_normal((2, 600))
        e = np.empty_like(w)
        e[:, 0] = w[:, 0]
        for t in range(1, 600):
            e[:, t] = 0.6 * e[:, t - 1] + w[:, t]
        hits += heldout_fall_p(e[0], e[1]) <= 0.05
    assert hits <= 30  # 20 expected at most (Bonferroni), 30 leaves sampling room


def test_small_scale_inputs_give_the_same_statistics() -> None:
    """Scale invariance: the autocorrelation, the AR order and the F statistic do not depend on the unit of the force."""
    alt = 0.01 * np.array([1.0, -1.0, 1.0, -1.0])
    assert lag1_autocorrelation(alt) == pytest.approx(-0.75)
    rng = np.random.default_rng(6)
    w = rng.standard_normal(4000)
    for scale in (0.01, 1.2, 1.5, 100.0):
        assert len(ar_fit(scale * w)) == 0, scale  # white noise at any scale: no lag
    e = np.zeros(4000)
    for i in range(1, 4000):
        e[i] = 0.6 * e[i - 1] + w[i]
    a = ar_fit(e)
    for scale in (0.01, 100.0):
        np.testing.assert_allclose(ar_fit(scale * e), a, rtol=1e-9)
    np.testing.assert_allclose(ar_fit(e + 100.0), a, rtol=1e-6)  # the mean is removed
    n = 60
    t = np.linspace(0, 1, n)
    W0 = np.c_[np.ones(n), t]
    W1 = np.c_[W0, np.sin(6 * t)]
    y = W0 @ [1.0, 2.0] + 0.3 * np.sin(6 * t) + 0.5 * rng.standard_normal(n)
    big = nested_f_test(W0, y, W1, y, q=1, max_order=0)
    small = nested_f_test(W0, 0.001 * y, W1, 0.001 * y, q=1, max_order=0)
    assert small.F == pytest.approx(big.F, rel=1e-9) and small.delta_bic == pytest.approx(big.delta_bic, rel=1e-9)


def test_ar_order_is_at_most_a_quarter_of_the_series() -> None:
    """An alternating series is AR(1) with a = -1: found as soon as one lag fits in (n - 1)/4 rows."""
    alt = np.array([1.0, -1.0] * 10)
    assert len(ar_fit(alt[:4])) == 0
    assert len(ar_fit(alt[:5])) == 1 and ar_fit(alt[:5])[0] < -0.9
    assert len(ar_fit(alt[:8])) == 1
    assert 1 <= len(ar_fit(alt[:9])) <= 2


def test_f_test_edge_cases() -> None:
    W0 = np.c_[np.ones(4), X]
    W1 = np.c_[W0, X**2]
    y = Y_LINE
    res = nested_f_test(W0, y, W1, y, q=1, max_order=0)  # 4 rows, 2 + 1 parameters: df2 = 1
    assert (res.df1, res.df2) == (1, 1)
    assert res.trials == 1 and res.p_adjusted == res.p_value  # one comparison by default
    eye = np.eye(4)
    y3 = np.array([1.0, 2.0, 3.0, 0.0])
    assert lstsq(eye[:, :3], y3)[1] == 0.0
    exact = nested_f_test(eye[:, :2], y3, eye[:, :3], y3, q=1, max_order=0)  # the larger model fits exactly
    assert math.isinf(exact.F) and exact.p_value == 0.0 and exact.delta_bic == float("-inf")
    d = res.to_dict()
    assert set(d) == {
        "test",
        "F",
        "df1",
        "df2",
        "p_value",
        "bonferroni_trials",
        "p_adjusted",
        "whitening_ar_order",
        "residual_lag1_autocorrelation",
        "delta_bic",
    }
    assert d["test"] == "nested-model F-test on AR-prewhitened decimated IDIM data, Bonferroni-corrected"
    assert (d["df1"], d["df2"], d["p_value"], d["whitening_ar_order"], d["residual_lag1_autocorrelation"], d["delta_bic"]) == (
        1,
        1,
        res.p_value,
        0,
        res.rho,
        res.delta_bic,
    )
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        res.F = 0.0  # type: ignore[misc]


def test_gls_covariance_one_degree_of_freedom_and_default_folds() -> None:
    W = W_LINE[:3]
    theta, rss = lstsq(W, Y_LINE[:3])
    np.testing.assert_allclose(gls_covariance(W, Y_LINE[:3], theta, max_order=0), rss / 1 * np.linalg.inv(W.T @ W), rtol=1e-9)
    folds = blocked_folds(200)  # docs/diagnosis.md: blocked 5-fold cross-validation
    assert len(folds) == 5
    train, test = folds[2]
    assert (test[0], test[-1]) == (80, 119) and 69 in train and 70 not in train and 129 not in train and 130 in train  # 10 rows guard


def test_batched_rss_with_rank_deficient_base() -> None:
    # a repeated column: the base's span is what counts, under the one rank rule of ilic_cli.lsq
    rng = np.random.default_rng(5)
    w = rng.standard_normal((120, 2))
    W0 = np.hstack([w, w[:, :1]])
    y = rng.standard_normal(120)
    X = rng.standard_normal((120, 3, 2))
    np.testing.assert_allclose(batched_rss(W0, y, X), [lstsq(np.hstack([W0, X[:, g]]), y)[1] for g in range(3)], rtol=1e-9)


def test_tail_probabilities_match_scipy_stats() -> None:
    x = np.array([0.0, 0.3, 1.7, 4.2, 11.0, 40.0])
    np.testing.assert_array_equal(normal_sf(x), stats.norm.sf(x))
    np.testing.assert_array_equal(f_sf(x, 3, 250), stats.f.sf(x, 3, 250))
    np.testing.assert_array_equal(chi2_sf(x, 8), stats.chi2.sf(x, 8))
    p = np.array([1e-12, 0.01, 0.5, 0.9])
    np.testing.assert_allclose(normal_isf(p), stats.norm.isf(p), rtol=1e-15)
