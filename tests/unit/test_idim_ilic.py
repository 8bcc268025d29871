"""IDIM-ILIC on noise-free synthetic windows: the essential-parameter rule, window bookkeeping, reference lag.

With the force computed from the very reference derivatives the regressor is
built from, ``W_r theta = tau`` holds sample by sample, and the per-window
filtering and decimation are linear: every window returns the truth to
rounding. A reference that leads the measured motion by ``L`` samples is
found by :func:`reference_lag` as ``+L``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli.idim_ilic import (
    ILICResult,
    ILICSettings,
    WindowEstimate,
    delay_samples,
    essential_mask,
    estimate_window,
    estimate_windows,
    identify_ilic,
    reference_derivatives,
    reference_lag,
    tracking_error_ratio,
    update_parameters,
)
from ilic_cli.lsq import solve
from ilic_cli.regressor import get_model
from tests.unit.synth import FS, motion, rigid_force

X = np.array([0.0, 1.0, 2.0, 3.0])
W_LINE = np.c_[np.ones(4), X]
Y_LINE = np.array([0.0, 1.0, 1.0, 3.0])
# straight-line fit (see tests/unit/test_lsq.py): slope 0.9 with std sqrt(0.35 * 0.2) = 0.2646, %std 29.4;
# intercept -0.1 with std sqrt(0.35 * 0.7) = 0.495, %std 495
SLOPE_STD = math.sqrt(0.35 * 0.2)


def test_finite_relative_std_above_the_limit_is_not_essential() -> None:
    r = solve(W_LINE, Y_LINE, ("c", "s"))
    assert np.all(np.isfinite(r.rel_std_pct)) and r.full_rank
    assert r.rel_std_pct[1] == pytest.approx(100 * SLOPE_STD / 0.9)  # 29.4 %: above 15 %
    assert list(essential_mask(r, 15.0)) == [False, False]
    assert list(essential_mask(r, 30.0)) == [False, True]
    assert list(essential_mask(r, 500.0)) == [True, True]


def test_the_rule_is_on_the_relative_not_the_absolute_std() -> None:
    """std < 15 with %std > 15 is not essential; std > 15 with %std < 15 is."""
    small = solve(W_LINE, Y_LINE, ("c", "s"))  # slope: std 0.26, %std 29.4
    assert small.std[1] < 15 < small.rel_std_pct[1]
    assert not essential_mask(small, 15.0)[1]
    big = solve(W_LINE, 100 * (Y_LINE + 1000 * X), ("c", "s"))  # slope 100090: std 26.5, %std 0.026
    assert big.std[1] > 15 > big.rel_std_pct[1]
    assert essential_mask(big, 15.0)[1]
    # intercept -10: std 49.5 and %std 495, both above: not essential either way
    assert not essential_mask(big, 15.0)[0]


def test_the_limit_itself_is_essential() -> None:
    r = solve(W_LINE, Y_LINE, ("c", "s"))
    limit = float(r.rel_std_pct[1])
    assert essential_mask(r, limit)[1]
    assert not essential_mask(r, limit * (1 - 1e-9))[1]


def test_infinite_std_is_never_essential() -> None:
    r = solve(np.c_[X, X], Y_LINE, ("a", "b"))
    assert not r.full_rank
    assert not essential_mask(r, 1e300).any()
    assert not essential_mask(r, math.inf).any()  # even with no limit at all (--sigma-max inf)


def test_update_replaces_only_essential_parameters() -> None:
    t, q, qd, qdd = motion(2000)
    model = get_model("rigid")
    tau = rigid_force(qd, qdd, offset=0.0)
    w = estimate_window(model, qd, qdd, tau, FS, ILICSettings())
    assert w.essential.all()
    chi = np.array([1.0, 2.0, 3.0])
    assert update_parameters(chi, w) == pytest.approx([95.0, 200.0, 20.0], rel=1e-9)
    w0 = estimate_window(model, np.zeros(2000), np.zeros(2000), np.zeros(2000), FS, ILICSettings())  # no motion
    assert not w0.essential.any()
    np.testing.assert_array_equal(update_parameters(chi, w0), chi)


def windows(n_windows: int = 5, seconds: float = 2.0) -> tuple[np.ndarray, ...]:
    """Stacked windows ``(K, n)`` of :func:`motion` and the exact rigid force."""
    t, q, qd, qdd = motion(int(n_windows * seconds * FS))
    tau = rigid_force(qd, qdd, offset=0.0)
    shape = (n_windows, -1)
    return tuple(a.reshape(shape) for a in (t, q, qd, qdd, tau))


def test_every_window_returns_the_truth_and_its_bounds() -> None:
    t, q, qd, qdd, tau = windows()
    out = estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), q_ref=q, q=q, t=t, k0=3)
    assert [w.k for w in out] == [3, 4, 5, 6, 7]
    for i, w in enumerate(out):
        assert w.result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-9)
        assert w.essential.all() and w.note == ""
        assert w.t_start == t[i, 0] and w.t_end == t[i, -1]
        assert w.tracking_error_ratio == 0.0
        assert w.result.rows == math.ceil(2000 / 80)
    d = out[0].to_dict()
    assert d["k"] == 3 and d["essential"] == {"M": True, "Fv": True, "Fc": True} and d["note"] == ""
    assert d["parameters"]["Fv"]["value"] == pytest.approx(200.0)


def test_settings_factor() -> None:
    assert ILICSettings().factor(1000.0) == 80  # round(0.8*500/5)
    assert ILICSettings(cutoff_hz=10.0).factor(1000.0) == 40
    assert ILICSettings(decimation=25).factor(1000.0) == 25
    s = ILICSettings()
    assert (s.window_s, s.cutoff_hz, s.sigma_max_pct, s.filter_order) == (6.2, 5.0, 15.0, 4)  # paper section V


def test_unexcited_parameter_is_reported_and_not_essential() -> None:
    t, q, qd, qdd, tau = windows(2)
    qd[1] = 0.5  # constant velocity: no acceleration, a constant sign: M is not excited, Fv and Fc are confounded
    qdd[1] = 0.0
    tau[1] = rigid_force(qd[1], qdd[1], offset=0.0)
    out = estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), t=t)
    assert out[0].essential.all()
    assert not out[1].result.full_rank and not out[1].essential.any()
    assert out[1].note.startswith("rank-deficient: ") and "M" in out[1].note and "not excited" in out[1].note


def test_large_relative_std_is_noted_not_essential() -> None:
    t, q, qd, qdd, tau = windows(1)
    rng = np.random.default_rng(0)
    noisy = tau + rng.normal(0, 200.0, tau.shape)  # Coulomb and viscous drown: finite but large %std
    w = estimate_windows(get_model("rigid-offset"), qd, qdd, noisy, FS, ILICSettings(), t=t)[0]
    assert w.result.full_rank
    rel = dict(zip(w.result.names, w.result.rel_std_pct, strict=True))
    bad = [n for n, r in rel.items() if r > 15.0]
    assert bad and all(np.isfinite(list(rel.values())))
    assert w.note == "not essential: " + ", ".join(bad)
    assert [n for n, e in zip(w.result.names, w.essential, strict=True) if not e] == bad


def test_masked_window_drops_rows_and_a_fully_masked_one_is_null() -> None:
    t, q, qd, qdd, tau = windows(3)
    valid = np.ones(t.shape, dtype=bool)
    valid[1, 1000:1010] = False
    valid[2, :] = False
    out = estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), t=t, valid=valid)
    assert out[0].note == "" and out[0].result.rows == 25
    # kept samples every 80 ending at 1999: 39, 119, ..., 999, 1079, ...; within 79 of 1000..1009: 999, 1079
    assert out[1].result.rows == 23
    assert out[1].note.startswith("8 % of the rows masked (saturated drive)")
    assert out[1].result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-9)
    assert out[2].result.rank == 0 and not out[2].essential.any()
    assert out[2].note.startswith("100 % of the rows masked") and "rank-deficient" in out[2].note
    same = estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), t=t, valid=np.ones(t.shape, dtype=bool))
    for a, b in zip(same, estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), t=t), strict=True):
        np.testing.assert_array_equal(a.result.theta, b.result.theta)


def test_estimate_window_is_one_window_of_the_batch() -> None:
    t, q, qd, qdd, tau = windows(2)
    one = estimate_window(get_model("rigid"), qd[1], qdd[1], tau[1], FS, ILICSettings(), q_ref=q[1], q=q[1] + 1e-3, t=t[1], k=9)
    assert one.k == 9 and one.t_start == t[1, 0] and one.t_end == t[1, -1]
    assert one.result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-9)
    assert one.tracking_error_ratio == pytest.approx(tracking_error_ratio(q[1], q[1] + 1e-3))


def test_tracking_error_ratio_by_hand() -> None:
    q = np.array([0.0, 1.0, 2.0, 3.0])  # spread about the mean: sqrt(2.25 + .25 + .25 + 2.25) = sqrt(5)
    q_ref = q + np.array([0.0, 0.0, 0.0, 1.0])
    assert tracking_error_ratio(q_ref, q) == pytest.approx(1 / math.sqrt(5))
    assert math.isinf(tracking_error_ratio(np.ones(4), np.zeros(4)))
    stacked = tracking_error_ratio(np.stack([q_ref, q]), np.stack([q, q]))
    assert stacked == pytest.approx([1 / math.sqrt(5), 0.0])


def test_delay_samples_by_hand() -> None:
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert list(delay_samples(x, 2)) == [1.0, 1.0, 1.0, 2.0, 3.0]
    assert list(delay_samples(x, 0)) == list(x)
    assert list(delay_samples(x, -3)) == list(x)


@pytest.mark.parametrize("lag", [0, 1, 7, 23])
def test_reference_lag_recovers_a_known_delay_with_its_sign(lag: int) -> None:
    t, q_ref, _, _ = motion(6000)
    q = delay_samples(q_ref, lag)  # the axis trails its reference by `lag` samples
    assert reference_lag(q_ref, q, 50) == lag
    # a reference that trails the motion is not a positive lag: the search stops at 0
    if lag:
        assert reference_lag(q, q_ref, 50) == 0


def test_reference_lag_search_bounds() -> None:
    t, q_ref, _, _ = motion(6000)
    q = delay_samples(q_ref, 30)
    assert reference_lag(q_ref, q, 10) == 10  # the largest lag searched
    assert reference_lag(q_ref[:100], q[:100], 50) == 25  # at most a quarter of the record
    # only the first max_samples are used: a different tail does not matter
    q_tail = q.copy()
    q_tail[3000:] = 0.0
    assert reference_lag(q_ref, q_tail, 50, max_samples=3000) == 30


def test_identify_ilic_delays_the_reference_by_the_lag_of_the_motion() -> None:
    """The axis trails the reference by 7 samples; the force is the rigid model on the actual motion."""
    lag, n = 7, 10_500  # five 2-s windows and 0.5 s left over
    t, q_ref, _, _ = motion(n)
    qd_r, qdd_r = reference_derivatives(q_ref, 1 / FS)
    q = delay_samples(q_ref, lag)
    tau = rigid_force(delay_samples(qd_r, lag), delay_samples(qdd_r, lag), offset=0.0)
    model = get_model("rigid")
    res = identify_ilic(t, q_ref, tau, FS, model, ILICSettings(window_s=2.0), q=q)
    assert res.ref_lag == lag and len(res.windows) == 5
    assert res.dropped_s == pytest.approx(0.5)
    for w in res.windows:
        assert w.result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-6)
    # the tracking error is the controller's: against the reference as recorded, not the delayed one
    cut = slice(2000, 4000)
    assert res.windows[1].tracking_error_ratio == pytest.approx(float(tracking_error_ratio(q_ref[cut], q[cut])))
    assert res.windows[1].tracking_error_ratio > 0.01
    # without the delay the estimate is off
    biased = identify_ilic(t, q_ref, tau, FS, model, ILICSettings(window_s=2.0, ref_lag=0), q=q)
    assert biased.ref_lag == 0
    assert abs(biased.windows[1].result.theta[1] - 200.0) > 1.0
    # given the lag, the same answer; no measured position: no lag
    given = identify_ilic(t, q_ref, tau, FS, model, ILICSettings(window_s=2.0, ref_lag=lag))
    np.testing.assert_allclose(given.windows[1].result.theta, res.windows[1].result.theta, rtol=1e-12)
    assert identify_ilic(t, q_ref, tau, FS, model, ILICSettings(window_s=2.0)).ref_lag == 0
    d = res.to_dict()
    assert d["ref_lag_samples"] == lag and d["window_s"] == 2.0 and len(d["windows"]) == 5 and d["method"] == "IDIM-ILIC"
    frame = res.to_frame()
    assert list(frame["k"]) == [1, 2, 3, 4, 5] and frame["Fv"].iloc[0] == pytest.approx(200.0, rel=1e-6)


def test_identify_ilic_given_derivatives_and_mask() -> None:
    n = 4000
    t, q, qd, qdd = motion(n)
    tau = rigid_force(qd, qdd, offset=0.0)
    model = get_model("rigid")
    valid = np.ones(n, dtype=bool)
    valid[2500:2505] = False
    res = identify_ilic(t, q, tau, FS, model, ILICSettings(window_s=2.0, ref_lag=0), qd_ref=qd, qdd_ref=qdd, valid=valid)
    assert res.windows[0].note == "" and "masked" in res.windows[1].note
    for w in res.windows:
        assert w.result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-9)
    with pytest.raises(ValueError, match="shorter than one window"):
        identify_ilic(t[:1999], q[:1999], tau[:1999], FS, model, ILICSettings(window_s=2.0))


def test_window_and_result_records() -> None:
    """The JSON and table layouts of the windows (``ilic identify --format json|csv``)."""
    import dataclasses

    t, q, qd, qdd, tau = windows(2)
    res = identify_ilic(
        t.ravel(),
        q.ravel(),
        tau.ravel(),
        FS,
        get_model("rigid"),
        ILICSettings(window_s=2.0, ref_lag=0),
        qd_ref=qd.ravel(),
        qdd_ref=qdd.ravel(),
        q=q.ravel() + 1e-4,
    )
    w = res.windows[1]
    d = w.to_dict()
    assert set(d) == {"k", "t_start", "t_end", "parameters", "essential", "relative_error_pct", "condition_number", "tracking_error_ratio", "note"}
    assert (d["k"], d["t_start"], d["t_end"]) == (2, 2.0, 3.999)
    assert d["relative_error_pct"] == pytest.approx(w.result.relative_error_pct)
    assert d["condition_number"] == pytest.approx(w.result.condition_number)
    assert d["tracking_error_ratio"] == pytest.approx(w.tracking_error_ratio) and d["tracking_error_ratio"] > 0
    top = res.to_dict()
    assert set(top) == {"method", "model", "window_s", "cutoff_hz", "sigma_max_pct", "ref_lag_samples", "windows", "dropped_tail_s"}
    assert (top["model"], top["cutoff_hz"], top["sigma_max_pct"], top["dropped_tail_s"], top["ref_lag_samples"]) == ("rigid", 5.0, 15.0, 0.0, 0)
    frame = res.to_frame()
    assert list(frame.columns) == [
        "k",
        "t_start",
        "t_end",
        "M",
        "M_std",
        "M_rel_std_pct",
        "M_essential",
        "Fv",
        "Fv_std",
        "Fv_rel_std_pct",
        "Fv_essential",
        "Fc",
        "Fc_std",
        "Fc_rel_std_pct",
        "Fc_essential",
        "relative_error_pct",
        "tracking_error_ratio",
    ]
    row = frame.iloc[1]
    assert (row["t_start"], row["t_end"]) == (2.0, 3.999)
    assert row["Fv_std"] == w.result.std[1] and row["Fv_rel_std_pct"] == w.result.rel_std_pct[1]
    assert bool(row["Fv_essential"]) is True and bool(row["M_essential"]) is True
    assert row["relative_error_pct"] == w.result.relative_error_pct and row["tracking_error_ratio"] == w.tracking_error_ratio
    bare = WindowEstimate(k=1, t_start=0.0, t_end=1.0, result=w.result, essential=w.essential)
    assert bare.tracking_error_ratio is None and bare.note == "" and bare.to_dict()["tracking_error_ratio"] is None
    empty = ILICResult(model="rigid", names=("M",), settings=ILICSettings())
    assert empty.windows == [] and empty.dropped_s == 0.0 and empty.ref_lag == 0
    for obj, attr in ((ILICSettings(), "window_s"), (w, "k"), (res, "model")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, attr, 1)
    assert estimate_window(get_model("rigid"), qd[0], qdd[0], tau[0], FS, ILICSettings()).k == 1


def test_position_and_time_columns_see_the_reference_and_the_clock() -> None:
    from ilic_cli.regressor import Column

    t, q, qd, qdd, tau = windows(2)
    model = get_model("rigid").extend(Column("k", "N/m", lambda k: k.q), Column("c", "N/s", lambda k: k.t))
    out = estimate_windows(model, qd, qdd, tau + 300.0 * q + 2.0 * t, FS, ILICSettings(), q_ref=q, t=t)
    for w in out:
        assert w.result.theta == pytest.approx([95.0, 200.0, 20.0, 300.0, 2.0], rel=1e-6)


def test_exactly_as_many_rows_as_parameters_is_not_solved() -> None:
    """Rows every 80 samples end on 1999: 79, 159, 239, 319, ...; a row needs 79 valid samples either side."""
    t, q, qd, qdd, tau = windows(1)
    for last_valid, rows, rank in ((318, 3, 0), (398, 4, 3)):
        valid = np.zeros(t.shape, dtype=bool)
        valid[0, : last_valid + 1] = True
        w = estimate_windows(get_model("rigid"), qd, qdd, tau, FS, ILICSettings(), t=t, valid=valid)[0]
        assert w.result.rank == rank, last_valid
        assert w.note.startswith(f"{100 * (1 - rows / 25):.3g} % of the rows masked")


def test_exact_notes() -> None:
    t, q, qd, qdd, tau = windows(1)
    qd[0], qdd[0] = 0.5, 0.0
    w = estimate_windows(get_model("rigid"), qd, qdd, rigid_force(qd, qdd, offset=0.0), FS, ILICSettings())[0]
    assert w.note == "rank-deficient: M, Fv, Fc not excited in this window"


def test_lag_search_edges_and_window_length_errors() -> None:
    t, q_ref, _, _ = motion(6000)
    q = delay_samples(q_ref, 5)
    assert reference_lag(q_ref, q, 0) == 0  # no search: no lag
    # the default search reaches 50 ms: a 60-sample lag is capped there
    tau = np.zeros(6000)
    res = identify_ilic(t, q_ref, tau + 1.0, FS, get_model("rigid"), ILICSettings(window_s=2.0), q=delay_samples(q_ref, 60))
    assert res.ref_lag == 50
    with pytest.raises(ValueError, match=r"^the log \(2 s\) is shorter than one window \(2 s\); choose a shorter window$"):
        identify_ilic(t[:1999], q_ref[:1999], tau[:1999], FS, get_model("rigid"), ILICSettings(window_s=2.0))
    with pytest.raises(ValueError, match="shorter than one window"):
        identify_ilic(t, q_ref, tau, FS, get_model("rigid"), ILICSettings(window_s=1e-4))  # zero samples per window


def test_missing_acceleration_is_computed_from_the_reference() -> None:
    t, q, qd, qdd = motion(4000)
    tau = rigid_force(qd, qdd, offset=0.0)
    s = ILICSettings(window_s=2.0, ref_lag=0)
    both = identify_ilic(t, q, tau, FS, get_model("rigid"), s)
    only_qd = identify_ilic(t, q, tau, FS, get_model("rigid"), s, qd_ref=qd)
    for a, b in zip(both.windows, only_qd.windows, strict=True):
        np.testing.assert_array_equal(a.result.theta, b.result.theta)
    assert both.windows[0].result.theta == pytest.approx([95.0, 200.0, 20.0], rel=1e-2)  # central differences of q_ref


def test_tracking_error_ratio_small_spread_and_standstill() -> None:
    q = 0.1 * np.array([0.0, 1.0, 2.0, 3.0])  # spread sqrt(0.05) < 1
    assert tracking_error_ratio(q + [0.0, 0.0, 0.0, 0.1], q) == pytest.approx(0.1 / math.sqrt(0.05))
    assert math.isinf(tracking_error_ratio(np.ones(4), np.ones(4)))  # no motion at all: no ratio
