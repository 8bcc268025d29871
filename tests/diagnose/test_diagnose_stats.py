"""Statistics of the diagnosis: prewhitened F-test calibration, batched RSS, held-out test, localisation."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.locate import force_lag, velocity_bins
from ilic_cli.diagnosis.stats import ar_fit, batched_rss, blocked_folds, diebold_mariano, nested_f_test, variance_inflation
from ilic_cli.effects import EFFECTS, catalogue_ids
from ilic_cli.lsq import lstsq
from tests.lazy import lazy_module

signal = lazy_module("scipy.signal")  # imported at first use (tests/lazy.py)


def test_catalogue_ids_and_fields() -> None:
    assert set(catalogue_ids()) >= {"asymmetric_friction", "stribeck", "position_ripple", "spring", "payload_change", "offset", "delay", "flexibility"}
    for e in (EFFECTS[i] for i in catalogue_ids()):
        assert e.explanation.endswith(".") and e.form and e.signature
        d = e.to_dict()
        assert d["id"] == e.id


def test_prewhitened_f_test_is_calibrated_under_autocorrelated_noise() -> None:
    """Under the null with AR(1) noise (rho 0.7, like the decimated IDIM residual) the
    prewhitened test rejects at about its level; the ordinary one would reject far more often."""
    rng = np.random.default_rng(0)
    n, hits, hits_naive, trials = 600, 0, 0, 300
    t = np.linspace(0, 1, n)
    W0 = np.c_[np.ones(n), np.sin(2 * np.pi * 3 * t)]
    x = np.cos(2 * np.pi * 2 * t)  # a smooth candidate column, absent from the data
    W1 = np.c_[W0, x]
    for _ in range(trials):
        e = signal.lfilter([1.0], [1.0, -0.7], rng.standard_normal(n))
        y = W0 @ np.array([1.0, 2.0]) + e
        hits += nested_f_test(W0, y, W1, y, 1).p_value < 0.05
        _, r0 = lstsq(W0, y)
        _, r1 = lstsq(W1, y)
        from scipy import stats

        hits_naive += stats.f.sf((r0 - r1) / (r1 / (n - 3)), 1, n - 3) < 0.05
    assert hits / trials < 0.1
    assert hits_naive / trials > 0.2


def test_ar_fit_recovers_ar1() -> None:
    rng = np.random.default_rng(1)
    e = signal.lfilter([1.0], [1.0, -0.6], rng.standard_normal(5000))
    a = ar_fit(e)
    assert abs(a[0] - 0.6) < 0.05


def test_batched_rss_matches_loop() -> None:
    rng = np.random.default_rng(2)
    W0 = rng.standard_normal((200, 3))
    y = rng.standard_normal(200)
    X = rng.standard_normal((200, 5, 2))
    got = batched_rss(W0, y, X)
    want = [lstsq(np.hstack([W0, X[:, g]]), y)[1] for g in range(5)]
    assert np.allclose(got, want)


def test_diebold_mariano_and_folds() -> None:
    rng = np.random.default_rng(3)
    e = rng.standard_normal(1000)
    assert diebold_mariano(e, e * 0.5) < 1e-6
    assert diebold_mariano(e, e + 0.01 * rng.standard_normal(1000)) > 0.01
    folds = blocked_folds(100, 5, 3)
    assert len(folds) == 5 and all(len(te) == 20 for _, te in folds)
    train, test = folds[1]
    assert not set(train) & set(range(17, 43))


def test_locate_velocity_bins_and_lag() -> None:
    rng = np.random.default_rng(4)
    qd = np.sin(np.linspace(0, 20, 2000))
    e = rng.standard_normal(2000) + np.where(qd < 0, 1.0, 0.0)
    regs = velocity_bins(e, qd)
    neg = [r for r in regs if r.bounds[1] <= 0]
    pos = [r for r in regs if r.bounds[0] >= 0]
    assert all(r.significant for r in neg) and not any(r.significant for r in pos)
    y = np.sin(np.linspace(0, 60, 6000)) + 0.01 * rng.standard_normal(6000)
    lag = force_lag(np.roll(y, 3), y, 1000.0)
    assert abs(lag.bounds[0] - 0.003) < 2e-4


def test_variance_inflation_is_the_ar1_factor_of_a_mean_and_credits_no_negative_autocorrelation() -> None:
    """The one factor both the inverse model's and the closed loop's profile standard deviations inflate by: the variance of
    the mean of an AR(1) series of lag-1 autocorrelation rho is about (1 + rho)/(1 - rho) times white noise's."""
    rng = np.random.default_rng(3)
    rho, n, trials = 0.6, 400, 2000
    w = rng.standard_normal((trials, n))
    e = np.empty_like(w)
    e[:, 0] = w[:, 0] / np.sqrt(1 - rho**2)
    for i in range(1, n):
        e[:, i] = rho * e[:, i - 1] + w[:, i]
    measured = np.var(e.mean(axis=1)) / (1 / (1 - rho**2) / n)
    assert abs(measured / variance_inflation(rho) - 1) < 0.12
    assert variance_inflation(-0.5) == 1.0 and variance_inflation(0.0) == 1.0
    assert variance_inflation(0.999) == variance_inflation(0.99) == pytest.approx(199.0)
