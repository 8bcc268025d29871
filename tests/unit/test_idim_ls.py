"""IDIM-LS on noise-free synthetic logs: masking, trimming, decimation, mirror symmetry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli.effects.grids import resonance_grid
from ilic_cli.idim_ls import IDIMData, IDIMLSResult, LSSettings, cross_validate, idim_ls, lsq_rows
from ilic_cli.regressor import get_model
from ilic_cli.row_spans import usable_mask, valid_rows
from tests.unit.synth import FS, asymmetric_force, motion, rigid_force


def brute_valid_rows(valid: np.ndarray, r: int) -> np.ndarray:
    """Reference for :func:`valid_rows`: a direct loop over every kept sample and every sample of its span.

    Parameters
    ----------
    valid : ndarray of bool, shape (n,)
        Usable full-rate samples.
    r : int
        Decimation factor.

    Returns
    -------
    ndarray of bool
        For each kept sample (the last one, then every ``r``-th backwards),
        whether every sample within ``r - 1`` of it is valid.
    """
    n = len(valid)
    kept = sorted(range(n - 1, -1, -r))
    out = []
    for i in kept:
        ok = True
        for j in range(n):
            if abs(j - i) <= r - 1 and not valid[j]:
                ok = False
        out.append(ok)
    return np.array(out, dtype=bool)


@pytest.mark.parametrize("r", [1, 2, 3, 4, 10])
@pytest.mark.parametrize("n", [37, 40, 41])
def test_valid_rows_one_invalid_sample_at_every_offset(n: int, r: int) -> None:
    for bad in range(n):
        valid = np.ones(n, dtype=bool)
        valid[bad] = False
        got = valid_rows(valid, r)
        want = brute_valid_rows(valid, r)
        np.testing.assert_array_equal(got, want, err_msg=f"n={n} r={r} invalid sample {bad}")
        # a row is dropped exactly when its kept sample lies within r - 1 samples of the invalid one
        assert (~got).sum() == sum(1 for i in range(n - 1, -1, -r) if abs(i - bad) <= r - 1)


def test_valid_rows_random_masks_and_stacked_windows() -> None:
    rng = np.random.default_rng(5)
    for _ in range(40):
        n, r = int(rng.integers(5, 90)), int(rng.integers(1, 12))
        valid = rng.random((3, n)) > 0.08
        got = valid_rows(valid, r)
        assert got.shape == (3, math.ceil(n / r))
        for k in range(3):
            np.testing.assert_array_equal(got[k], brute_valid_rows(valid[k], r))
    assert valid_rows(np.ones(25, dtype=bool), 10).all()
    assert not valid_rows(np.zeros(25, dtype=bool), 10).any()


def test_usable_mask() -> None:
    assert usable_mask(None, (5,)) is None
    assert usable_mask(np.ones(5), (5,)) is None  # every sample usable: no mask at all
    m = usable_mask(np.array([1, 1, 0, 1, 1]), (5,))
    assert m is not None and m.dtype == bool and list(m) == [True, True, False, True, True]
    with pytest.raises(ValueError, match=r"^valid has \(4,\) samples, the log \(5,\)$"):
        usable_mask(np.ones(4, dtype=bool), (5,))


def test_settings_are_the_benchmark_procedure() -> None:
    s = LSSettings()
    assert (s.cutoff_hz, s.order, s.decimation, s.trim, s.matlab, s.sigma) == (100.0, 4, 10, 49, True, "sample_std")
    assert s.to_dict()["decimation"] == 10


@pytest.mark.parametrize(("fs", "r", "points"), [(250.0, 6, 5), (500.0, 6, 5), (1000.0, 10, 3), (2000.0, 20, 3), (4000.0, 40, 3), (8000.0, 80, 3)])
def test_the_decimation_is_the_rate_s_rule(fs: float, r: int, points: int) -> None:
    """The rows keep 40 Hz from 1 kHz up with central differences (a factor fixed at 10 kept 80 Hz at 2 kHz, 320 Hz at
    8 kHz; 10 at 1 kHz, the benchmark); below, five-point derivatives and fs/15. IDIM-LS, and an explicit factor
    (``band_hz=None``, ``identify --decimation``) as given, with the benchmark's central differences."""
    assert resonance_grid(None, fs)[-1] == pytest.approx(min(0.1 * fs, 40.0))  # type: ignore[arg-type]  # the same modes at every rate that sees them
    t, q, qd, qdd = motion(int(10 * fs), fs)
    data = lsq_rows(t, q, rigid_force(qd, qdd), fs, get_model("rigid-offset"))
    assert (data.settings.decimation, data.settings.stencil) == (r, points) and np.diff(data.t_dec) == pytest.approx(r / fs)
    res = idim_ls(t, q, rigid_force(qd, qdd), fs, get_model("rigid-offset"))
    assert res.settings.decimation == r and len(res.y) == len(data.y)
    assert res.result.theta[:3] == pytest.approx([95.0, 200.0, 20.0], rel=1.5e-2)  # 250 Hz: Fc 1.4 % (the sign at the reversals)
    assert res.result.theta[0] == pytest.approx(95.0, rel=5e-4)  # M: central differences keeping 10 Hz at 250 Hz gave +0.13 %
    given = lsq_rows(t, q, rigid_force(qd, qdd), fs, get_model("rigid-offset"), LSSettings(decimation=7, band_hz=None))
    assert (given.settings.decimation, given.settings.stencil) == (7, 3) and np.diff(given.t_dec) == pytest.approx(7 / fs)


def assert_truth(theta: np.ndarray) -> None:
    """The rigid-offset truth of :func:`rigid_force` within 0.2 % (M, Fv, Fc) and 0.05 N (offset)."""
    assert theta[:3] == pytest.approx([95.0, 200.0, 20.0], rel=2e-3)
    assert theta[3] == pytest.approx(-3.0, abs=0.05)


@pytest.fixture(scope="module")
def log() -> tuple[np.ndarray, ...]:
    t, q, qd, qdd = motion(10_000)
    return t, q, rigid_force(qd, qdd)


def test_noise_free_log_gives_the_truth(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    res = idim_ls(t, q, tau, FS, get_model("rigid-offset"))
    assert res.result.names == ("M", "Fv", "Fc", "offset")
    assert_truth(res.result.theta)
    assert res.result.relative_error_pct < 0.2
    d = res.to_dict()
    assert d["method"] == "IDIM-LS" and d["model"] == "rigid-offset" and d["settings"]["trim"] == 49
    assert list(res.to_frame()["parameter"]) == ["M", "Fv", "Fc", "offset"]
    assert res.y_hat == pytest.approx(res.result.theta @ lsq_rows(t, q, tau, FS, get_model("rigid-offset")).W.T)
    # SciPy filtering instead of MATLAB's: the same answer within the same tolerance
    sci = idim_ls(t, q, tau, FS, get_model("rigid-offset"), LSSettings(matlab=False))
    assert_truth(sci.result.theta)


def test_trim_and_end_aligned_rows(log: tuple[np.ndarray, ...]) -> None:
    """The first ``trim`` samples are dropped, then the rows are the samples aligned on the end of the record."""
    t, q, tau = log
    n = len(t)
    for trim in (49, 50):
        data = lsq_rows(t, q, tau, FS, get_model("rigid"), LSSettings(trim=trim))
        assert data.kin.t[0] == t[trim] and len(data.kin.t) == n - trim
        np.testing.assert_array_equal(data.tau, tau[trim:])
        rows = len(range(n - 1, trim - 1, -10))
        assert data.W.shape == (rows, 3) and data.y.shape == (rows,)
        np.testing.assert_array_equal(data.t_dec, t[n - 1 : trim - 1 : -10][::-1])
    assert lsq_rows(t, q, tau, FS, get_model("rigid")).W.shape[0] == 996  # ceil(9951 / 10)


def test_decimate_matches_the_system_columns(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    valid = np.ones(len(t), dtype=bool)
    valid[3000:3005] = False
    for v in (None, valid):
        data = lsq_rows(t, q, tau, FS, get_model("rigid"), valid=v)
        np.testing.assert_allclose(data.decimate(data.kin.qd), data.W[:, 1], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(data.decimate(data.tau), data.y, rtol=1e-12, atol=1e-12)
        assert len(data.t_dec) == len(data.y)


def test_masked_rows_are_exactly_those_touching_a_saturated_sample(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    n, trim, r = len(t), 49, 10
    valid = np.ones(n, dtype=bool)
    valid[4321:4330] = False  # a saturated plateau
    valid[7000] = False
    data = lsq_rows(t, q, tau, FS, get_model("rigid-offset"), valid=valid)
    keep = brute_valid_rows(valid[trim:], r)
    assert data.rows is not None
    np.testing.assert_array_equal(data.rows, keep)
    # rows every 10 trimmed samples from 0: 4270, 4280 are within 9 of the plateau (4272..4280), 6950, 6960 of 6951
    assert len(data.y) == keep.sum() == 996 - 2 - 2
    np.testing.assert_array_equal(data.t_dec, t[n - 1 : trim - 1 : -r][::-1][keep])
    res = idim_ls(t, q, tau, FS, get_model("rigid-offset"), valid=valid)
    assert_truth(res.result.theta)
    assert res.result.rows == keep.sum()


def test_a_part_that_ends_at_a_gap_loses_its_filters_edge(log: tuple[np.ndarray, ...]) -> None:
    """A 0.3 s gap cut at the fastest sample: each part is filtered on its own, and the first part's last ``trim`` samples, the
    filters' edge, are left out as every part's first are (``part_valid``): the truth within 0.2 % (measured Fv +0.025 %).
    The parts' rows stacked with that edge kept: Fv -1.08 %, Fc +0.93 %. The report counts the rows the fit uses."""
    from ilic_cli.lsq import lstsq
    from ilic_cli.usable import rows_left_out

    t, q, tau = log
    n = len(t)
    cut = int(np.argmax(np.abs(np.gradient(q[1000:9000])))) + 1000
    keep = np.r_[0:cut, cut + 300 : n]
    tg, qg, taug = t[keep], q[keep], tau[keep]
    segments = ((0, cut), (cut, len(tg)))
    res = idim_ls(tg, qg, taug, FS, get_model("rigid-offset"), segments=segments)
    assert_truth(res.result.theta)
    parts = [lsq_rows(tg[a:b], qg[a:b], taug[a:b], FS, get_model("rigid-offset")) for a, b in segments]
    edge, _ = lstsq(np.vstack([d.W for d in parts]), np.concatenate([d.y for d in parts]))
    assert abs(edge[1] / 200.0 - 1.0) > 5e-3, edge  # the edge kept: what the rule removes
    total, left = rows_left_out(np.zeros(len(tg), dtype=bool), LSSettings().at_rate(FS), segments, gap_edges=True)
    assert total - left == res.result.rows and left > 0
    assert rows_left_out(np.zeros(len(tg), dtype=bool), LSSettings().at_rate(FS), segments) == (total, 0)


def test_a_part_with_few_rows_of_its_own_adds_them_to_the_others(log: tuple[np.ndarray, ...]) -> None:
    """Too few rows is judged on the parts together: a part after a gap that is almost all at rest (a long last dwell) gives its
    few rows beside the other part's, where alone it is refused (the 200 kg axis at 8 kHz: the drive lag's 20 Hz rows, none
    left in the part after the gap, refused the whole log)."""
    from ilic_cli.idim_ls import decimated_systems, part_valid

    t, q, tau = log
    model = get_model("rigid-offset")
    valid = np.ones(len(t), dtype=bool)
    valid[5000:9950] = False  # the second part's rows all touch a sample left out but its last 4
    W, y, _, kept = decimated_systems(t, q, tau, FS, model, LSSettings(), valid, ((0, 5000), (5000, len(t))))
    first = decimated_systems(
        t[:5000], q[:5000], tau[:5000], FS, model, LSSettings(), part_valid(valid[:5000], 5000, False, True, LSSettings().at_rate(FS)), None
    )
    assert kept is not None and 0 < len(y) - len(first[1]) <= len(model.columns) + 1  # the few rows of the second part
    with pytest.raises(ValueError, match="too few for 4 parameters"):
        lsq_rows(t[5000:], q[5000:], tau[5000:], FS, model, valid=valid[5000:])
    theta = idim_ls(t, q, tau, FS, model, valid=valid, segments=((0, 5000), (5000, len(t)))).result.theta
    assert theta[:3] == pytest.approx([95.0, 200.0, 20.0], rel=5e-3)  # fitted, not refused (Fc -0.25 %: the 4 rows at the log's end)


def test_no_invalid_sample_is_bit_identical(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    a = idim_ls(t, q, tau, FS, get_model("rigid-offset"))
    b = idim_ls(t, q, tau, FS, get_model("rigid-offset"), valid=np.ones(len(t), dtype=bool))
    np.testing.assert_array_equal(a.result.theta, b.result.theta)
    np.testing.assert_array_equal(a.result.std, b.result.std)


def test_everything_masked_is_refused(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    valid = np.zeros(len(t), dtype=bool)
    valid[:80] = True  # 31 valid trimmed samples: rows 0, 10, 20 only, too few for 3 parameters
    with pytest.raises(ValueError, match=r"^only 3 decimated rows are left .* too few for 3 parameters$"):
        lsq_rows(t, q, tau, FS, get_model("rigid"), valid=valid)
    valid[:90] = True  # rows 0, 10, 20, 30: one more than the parameters is still too few
    with pytest.raises(
        ValueError,
        match=r"^only 4 decimated rows are left once the samples left out \(a saturated drive, the axis at rest, a gap's edges\) are masked; "
        r"too few for 3 parameters$",
    ):
        lsq_rows(t, q, tau, FS, get_model("rigid"), valid=valid)
    valid[:100] = True  # rows 0..40: five
    assert len(lsq_rows(t, q, tau, FS, get_model("rigid"), valid=valid).y) == 5
    with pytest.raises(ValueError, match=r"^too few samples \(319\) for IDIM-LS with trim 49 and decimation 10$"):
        lsq_rows(t[:319], q[:319], tau[:319], FS, get_model("rigid"))
    assert len(lsq_rows(t[:320], q[:320], tau[:320], FS, get_model("rigid")).y) == 28  # the shortest log accepted


def test_results_and_settings_are_immutable(log: tuple[np.ndarray, ...]) -> None:
    """LSSettings() is a shared default argument: neither it nor the results may change after the fact."""
    import dataclasses

    t, q, tau = log
    res = idim_ls(t, q, tau, FS, get_model("rigid"))
    data = lsq_rows(t, q, tau, FS, get_model("rigid"))
    for obj, attr in ((LSSettings(), "trim"), (res, "model"), (data, "fs_hz")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, attr, 0)
    bare = IDIMLSResult(model="rigid", result=res.result, settings=LSSettings())
    assert bare.t is None and bare.y is None and bare.y_hat is None
    assert IDIMData(kin=data.kin, tau=data.tau, W=data.W, y=data.y, fs_hz=FS, settings=LSSettings()).rows is None
    frame = res.to_frame()
    assert list(frame.columns) == ["parameter", "value", "std", "rel_std_pct"]
    np.testing.assert_array_equal(frame["value"], res.result.theta)
    np.testing.assert_array_equal(frame["std"], res.result.std)
    np.testing.assert_array_equal(frame["rel_std_pct"], res.result.rel_std_pct)


def test_scipy_anti_alias_filter_keeps_the_band_and_stops_aliases() -> None:
    """matlab=False: Butterworth anti-alias at MATLAB decimate's cut-off, 0.8 of the decimated Nyquist (40 Hz
    for 1 kHz / 10): a 30 Hz tone passes (within 2 %), a 60 Hz one (above the new 50 Hz Nyquist) is stopped."""
    t, q, qd, qdd = motion(10_000)
    data = lsq_rows(t, q, rigid_force(qd, qdd), FS, get_model("rigid"), LSSettings(matlab=False))
    tt, td = data.kin.t, data.t_dec
    for f, lo, hi in ((30.0, 0.98, 1.0), (60.0, 0.0, 0.01)):
        d = data.decimate(np.sin(2 * np.pi * f * tt))[50:-50]
        basis = np.c_[np.sin(2 * np.pi * f * td), np.cos(2 * np.pi * f * td)][50:-50]
        amp = float(np.hypot(*np.linalg.lstsq(basis, d, rcond=None)[0]))  # amplitude of the tone in the decimated rows
        assert lo <= amp <= hi + 1e-9, (f, amp)


def test_sigma_conventions(log: tuple[np.ndarray, ...]) -> None:
    """With an offset column the residual has zero mean: eq. 8 and the sample std differ by sqrt((r-1)/(r-b))."""
    t, q, tau = log
    rng = np.random.default_rng(0)
    tau = tau + rng.normal(0, 2.0, len(t))
    a = idim_ls(t, q, tau, FS, get_model("rigid-offset"), LSSettings(sigma="eq8")).result
    b = idim_ls(t, q, tau, FS, get_model("rigid-offset")).result
    assert a.sigma_rho / b.sigma_rho == pytest.approx(math.sqrt((a.rows - 1) / (a.rows - 4)), rel=1e-9)


def test_asymmetric_mirror_swaps_the_sides() -> None:
    """q -> -q and tau -> -tau swap (Fv_pos, Fc_pos) with (Fv_neg, Fc_neg), exactly; the truth is recovered on each side."""
    t, q, qd, qdd = motion(10_000)
    truth = {"M": 95.0, "Fv_pos": 215.0, "Fc_pos": 22.0, "Fv_neg": 185.0, "Fc_neg": 17.0}
    tau = asymmetric_force(qd, qdd, **truth)
    model = get_model("asymmetric")
    a = dict(zip(model.names, idim_ls(t, q, tau, FS, model).result.theta, strict=True))
    m = dict(zip(model.names, idim_ls(t, -q, -tau, FS, model).result.theta, strict=True))
    for name, value in truth.items():
        assert a[name] == pytest.approx(value, rel=1e-2), name
    swap = {"M": "M", "Fv_pos": "Fv_neg", "Fv_neg": "Fv_pos", "Fc_pos": "Fc_neg", "Fc_neg": "Fc_pos"}
    for name, other in swap.items():
        assert m[name] == pytest.approx(a[other], rel=1e-9, abs=1e-9), name


def test_cross_validation_applies_fixed_parameters(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    model = get_model("rigid-offset")
    own = idim_ls(t, q, tau, FS, model).result
    cv = cross_validate(own.theta, t, q, tau, FS, model)
    assert cv.relative_error_pct == pytest.approx(own.relative_error_pct, rel=1e-9)
    wrong = cross_validate(own.theta * [1.1, 1.0, 1.0, 1.0], t, q, tau, FS, model)
    assert wrong.relative_error_pct > 5 * own.relative_error_pct
    valid = np.ones(len(t), dtype=bool)
    valid[5000:5100] = False
    # trimmed samples 4951..5050 are invalid: the rows 4950, 4960, ..., 5050 (11) touch them
    assert cross_validate(own.theta, t, q, tau, FS, model, valid=valid).rows == own.rows - 11


def _noisy_fits(correlated: bool, seeds: int = 24) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fc of ``seeds`` noisy copies of one log, with eq. 9's and the robust standard deviations (a 2 N force noise, white or smoothed over ~50 ms)."""
    t, q, qd, qdd = motion(10_000)
    tau0 = rigid_force(qd, qdd)
    est, eq9, rob = [], [], []
    for seed in range(seeds):
        w = np.random.default_rng(seed).normal(0.0, 1.0, len(t))
        noise = np.convolve(w, np.ones(50) / np.sqrt(50), mode="same") if correlated else w
        res = idim_ls(t, q, tau0 + 2.0 * noise, FS, get_model("rigid-offset"))
        assert res.robust is not None
        est.append(res.result.theta[2])
        eq9.append(res.result.std[2])
        rob.append(res.robust.std[2])
    return np.array(est), np.array(eq9), np.array(rob)


def test_the_robust_std_is_the_spread_of_a_correlated_residual() -> None:
    """Eq. 9 assumes a white residual: with a force noise correlated over ~5 rows it understates the seeds' spread of Fc; the
    Newey-West std beside it follows the spread, and on a white residual the two agree. Eq. 9's own figures are untouched."""
    est, eq9, rob = _noisy_fits(correlated=True)
    spread = est.std(ddof=1)
    assert eq9.mean() < 0.6 * spread and 0.7 * spread < rob.mean() < 1.4 * spread, (spread, eq9.mean(), rob.mean())
    est_w, eq9_w, rob_w = _noisy_fits(correlated=False, seeds=4)
    assert rob_w == pytest.approx(eq9_w, rel=0.25)
    t, q, qd, qdd = motion(10_000)
    res = idim_ls(t, q, rigid_force(qd, qdd) + 2.0 * np.random.default_rng(0).normal(0.0, 1.0, len(t)), FS, get_model("rigid-offset"))
    d = res.to_dict()["robust_std"]
    assert set(d["std"]) == {"M", "Fv", "Fc", "offset"} and d["residual_white"] and d["lags"] == int(4 * (len(res.y) / 100) ** (2 / 9))
