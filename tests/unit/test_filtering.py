"""Filtering and decimation with known answers (no recording needed).

MATLAB's ``decimate`` keeps the samples aligned on the *end* of the record:
the last sample is always kept, then every ``r``-th one backwards. Its
anti-alias filter is ``cheby1(8, 0.05, 0.8/r)`` applied by ``filtfilt``, whose
MATLAB padding is an odd reflection of ``3*(max(len(a), len(b)) - 1)``
samples (``../shared/reference/emps-benchmark.md``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli import filtering, spectra
from ilic_cli.derivatives import central_difference, derivative
from ilic_cli.filter_design import cheby1_ba
from ilic_cli.filtering import (
    butter_lowpass_zero_phase,
    decimate_matlab,
    decimation_factor,
    filtfilt_matlab,
    kept_indices,
    lowpass_decimate,
)
from tests.lazy import lazy_module

signal = lazy_module("scipy.signal")  # imported at first use (tests/lazy.py)


@pytest.mark.parametrize("r", [1, 2, 3, 7, 10, 80])
def test_kept_indices_are_end_aligned(r: int) -> None:
    for n in range(1, 4 * r + 3):
        idx = kept_indices(n, r)
        # brute force: walk back from the last sample in steps of r
        want = sorted(range(n - 1, -1, -r))
        assert list(idx) == want, (n, r)
        assert len(idx) == math.ceil(n / r)


def test_decimation_factor() -> None:
    assert decimation_factor(1000.0, 40.0) == 10  # the benchmark: round(0.8*500/40)
    assert decimation_factor(1000.0, 5.0) == 80  # IDIM-ILIC at 1 kHz
    assert decimation_factor(2000.0, 5.0) == 160
    assert decimation_factor(1000.0, 450.0) == 1  # never below 1
    assert decimation_factor(1000.0, 1000.0) == 1


def test_filtfilt_matlab_pads_three_times_the_order() -> None:
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.standard_normal(300))
    b, a = signal.butter(4, 0.1)
    want = signal.filtfilt(b, a, x, padtype="odd", padlen=3 * 4)
    got = filtfilt_matlab(b, a, x)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # SciPy's default padding (3*max(len(a), len(b))) is measurably different
    assert np.max(np.abs(signal.filtfilt(b, a, x) - want)) > 1e-6


def test_filtfilt_matlab_along_an_axis_and_keep() -> None:
    rng = np.random.default_rng(1)
    x = rng.standard_normal((250, 3))
    b, a = signal.butter(2, 0.2)
    got = filtfilt_matlab(b, a, x, axis=0)
    for j in range(3):
        np.testing.assert_allclose(got[:, j], signal.filtfilt(b, a, x[:, j], padtype="odd", padlen=6), atol=1e-12)
    keep = np.array([0, 5, 249])
    np.testing.assert_allclose(filtfilt_matlab(b, a, x, axis=0, keep=keep), got[keep], atol=1e-12)


def test_large_and_chunked_arrays_filter_as_a_whole() -> None:
    """Threads and blocks (arrays above PARALLEL_MIN_SIZE, rows over CHUNK_ELEMENTS) do not change the result."""
    rng = np.random.default_rng(2)
    x = rng.standard_normal((5, 60_000))
    b, a = signal.butter(2, 0.05)
    got = filtfilt_matlab(b, a, x, axis=1)
    assert got.shape == x.shape
    for i in (0, 4):
        np.testing.assert_allclose(got[i], signal.filtfilt(b, a, x[i], padtype="odd", padlen=6), atol=1e-10)
    old = filtering.CHUNK_ELEMENTS
    try:
        filtering.CHUNK_ELEMENTS = 1000  # rows longer than a block, one block per row
        np.testing.assert_allclose(filtfilt_matlab(b, a, x, axis=1), got, atol=1e-12)
    finally:
        filtering.CHUNK_ELEMENTS = old


def test_butterworth_gain_at_and_above_the_cutoff() -> None:
    """Forward-backward digital Butterworth of order N: |H|^2 = 1/(1 + w^(2N)), w = tan(pi f/fs)/tan(pi fc/fs)
    (bilinear transform): 1/2 at fc, 1 at DC."""
    fs, fc = 1000.0, 50.0
    w2 = math.tan(math.pi * 2 * fc / fs) / math.tan(math.pi * fc / fs)
    t = np.arange(20_000) / fs
    mid = slice(5000, 15000)
    for matlab in (True, False):
        for f, gain in ((fc, 0.5), (2 * fc, 1 / (1 + w2**8)), (0.0, 1.0)):
            x = np.cos(2 * np.pi * f * t)
            y = butter_lowpass_zero_phase(x, fc, fs, 4, matlab=matlab)
            assert np.max(np.abs(y[mid])) == pytest.approx(gain, rel=2e-3), (matlab, f)
            # zero phase: the output is the input scaled, no lag
            np.testing.assert_allclose(y[mid], gain * x[mid], atol=2e-3 * gain + 1e-9)


def test_butterworth_order_and_axis() -> None:
    fs, fc = 1000.0, 50.0
    x = np.cos(2 * np.pi * 2 * fc * np.arange(20_000) / fs)
    y2 = butter_lowpass_zero_phase(x, fc, fs, 2)
    w2 = math.tan(math.pi * 2 * fc / fs) / math.tan(math.pi * fc / fs)
    assert np.max(np.abs(y2[5000:15000])) == pytest.approx(1 / (1 + w2**4), rel=2e-3)
    X = np.c_[x, 2 * x]
    Y = butter_lowpass_zero_phase(X, fc, fs, 2, axis=0)
    np.testing.assert_allclose(Y[:, 1], 2 * y2, atol=1e-12)
    np.testing.assert_allclose(butter_lowpass_zero_phase(X.T, fc, fs, 2, axis=1), Y.T, atol=1e-12)


@pytest.mark.parametrize("cutoff", [0.0, -5.0, 500.0, 600.0])
def test_butterworth_cutoff_must_lie_below_nyquist(cutoff: float) -> None:
    with pytest.raises(ValueError, match="Nyquist"):
        butter_lowpass_zero_phase(np.zeros(100), cutoff, 1000.0)


def test_central_difference_is_matlab_gradient() -> None:
    dt = 0.5
    x = np.array([0.0, 1.0, 4.0, 9.0, 16.0])
    d = central_difference(x, dt)
    # interior (x[k+1] - x[k-1]) / (2 dt), ends one-sided (x[1] - x[0]) / dt
    assert list(d) == [2.0, 4.0, 8.0, 12.0, 14.0]
    X = np.c_[x, -x]
    np.testing.assert_array_equal(central_difference(X, dt)[:, 1], -d)


def test_the_five_point_derivative_is_exact_on_quartics_and_flat_in_the_band() -> None:
    """Five points: exact on a polynomial of degree 4 inside, central differences next to the ends, one-sided at them;
    its gain at 0.06 of the rate within 0.07 % where central differences lose 2.4 %; columns alike; 3 is central_difference."""
    dt = 0.01
    t = np.arange(12) * dt
    x = 1.0 + 2.0 * t - 3.0 * t**2 + 0.5 * t**3 + 7.0 * t**4
    d = derivative(x, dt, 5)
    np.testing.assert_allclose(d[2:-2], (2.0 - 6.0 * t + 1.5 * t**2 + 28.0 * t**3)[2:-2], rtol=0, atol=1e-12)
    c = central_difference(x, dt)
    np.testing.assert_array_equal(d[[0, 1, -2, -1]], c[[0, 1, -2, -1]])
    np.testing.assert_array_equal(derivative(x, dt, 3), c)
    np.testing.assert_array_equal(derivative(np.c_[x, -x], dt, 5)[:, 1], -d)
    w = 2 * np.pi * 0.06  # radians per sample at 0.06 fs
    k = np.arange(400)
    s = np.sin(w * k)
    gain5 = np.max(np.abs(derivative(s, 1.0, 5)[5:-5])) / w
    gain3 = np.max(np.abs(central_difference(s, 1.0)[5:-5])) / w
    assert abs(gain5 - 1.0) < 1e-3 and 0.97 < gain3 < 0.98
    with pytest.raises(ValueError, match="3 or 5"):
        derivative(x, dt, 4)


@pytest.mark.parametrize("n", [997, 1000, 1003])
def test_decimate_matlab_is_chebyshev_filtfilt_then_end_aligned_samples(n: int) -> None:
    rng = np.random.default_rng(n)
    x = np.cumsum(rng.standard_normal(n))
    r = 10
    b, a = signal.cheby1(8, 0.05, 0.8 / r)
    full = signal.filtfilt(b, a, x, padtype="odd", padlen=3 * 8)
    got = decimate_matlab(x, r)
    assert len(got) == math.ceil(n / r)
    np.testing.assert_allclose(got, full[n - 1 :: -r][::-1], atol=1e-9)
    # the same along an axis of a 2-D array (parallel decimation of the observation matrix)
    got2 = decimate_matlab(np.c_[x, 2 * x], r, axis=0)
    np.testing.assert_allclose(got2[:, 1], 2 * got, atol=1e-9)
    np.testing.assert_array_equal(decimate_matlab(x, 1), x)


@pytest.mark.parametrize("which", ["chebyshev", "butterworth"])
def test_decimation_keeps_the_sample_times_of_a_ramp(which: str) -> None:
    """A ramp through the origin, decimated, is proportional to the kept indices (rows away from the edges)."""
    if which == "chebyshev":
        n, r, edge = 1003, 10, 20
        y = decimate_matlab(np.arange(n, dtype=float), r)
    else:
        n, r, edge = 20_003, 80, 12
        y = lowpass_decimate(np.arange(n, dtype=float), r, 5.0, 1000.0)
    idx = kept_indices(n, r)
    ratio = y[edge:-edge] / idx[edge:-edge]
    # one sample off would spread the ratio by 1/idx[edge] - 1/idx[-edge], over 1e-3
    assert np.ptp(ratio) < 2e-4 * np.mean(ratio)
    assert np.mean(ratio) == pytest.approx(1.0, abs=0.02)


def test_lowpass_decimate_butterworth_sos_end_aligned() -> None:
    rng = np.random.default_rng(3)
    n, r, fc, fs = 1234, 80, 5.0, 1000.0
    x = np.cumsum(rng.standard_normal((2, n)), axis=1)
    sos = signal.butter(4, fc / (fs / 2), output="sos")
    full = signal.sosfiltfilt(sos, x, axis=1, padlen=3 * (2 * len(sos) + 1))
    got = lowpass_decimate(x, r, fc, fs, 4, axis=1)
    assert got.shape == (2, math.ceil(n / r))
    np.testing.assert_allclose(got, full[:, n - 1 :: -r][:, ::-1], atol=1e-9)
    # order 2 is a different filter
    assert not np.allclose(lowpass_decimate(x, r, fc, fs, 2, axis=1), got, atol=1e-6)
    # along axis 0
    np.testing.assert_allclose(lowpass_decimate(x.T, r, fc, fs, 4, axis=0), got.T, atol=1e-9)


def test_lowpass_decimate_short_record_pads_what_it_can() -> None:
    x = np.ones(10)
    y = lowpass_decimate(x, 3, 5.0, 1000.0)
    assert y.shape == (4,)
    np.testing.assert_allclose(y, 1.0, atol=1e-9)


def test_threaded_blocks_give_the_serial_result() -> None:
    """Several blocks of rows filtered in threads: the same numbers as one row at a time."""
    rng = np.random.default_rng(7)
    x = rng.standard_normal((5, 60_000))
    b, a = signal.butter(2, 0.05)
    old = filtering.CHUNK_ELEMENTS
    try:
        filtering.CHUNK_ELEMENTS = 2 * 60_000  # two rows per block: three blocks, two workers on 2 cores
        got = filtfilt_matlab(b, a, x, axis=1)
    finally:
        filtering.CHUNK_ELEMENTS = old
    for i in range(5):
        np.testing.assert_allclose(got[i], signal.filtfilt(b, a, x[i], padtype="odd", padlen=6), atol=1e-10)


def test_stacked_observation_matrices_decimate_along_time() -> None:
    """(K windows, n samples, b columns) decimated along axis 1, as IDIM-ILIC does with its regressor."""
    rng = np.random.default_rng(8)
    W = np.cumsum(rng.standard_normal((2, 700, 3)), axis=1)
    got = lowpass_decimate(W, 80, 5.0, 1000.0, 4, axis=1)
    assert got.shape == (2, 9, 3)
    for k in range(2):
        for j in range(3):
            np.testing.assert_allclose(got[k, :, j], lowpass_decimate(W[k, :, j], 80, 5.0, 1000.0, 4), atol=1e-9)
    got0 = decimate_matlab(W, 10, axis=1)
    assert got0.shape == (2, 70, 3)
    np.testing.assert_allclose(got0[1, :, 2], decimate_matlab(W[1, :, 2], 10), atol=1e-9)


def test_defaults_are_the_benchmarks() -> None:
    """Order 4 and MATLAB's transfer-function filtfilt by default (benchmark: 4th-order Butterworth)."""
    rng = np.random.default_rng(9)
    x = np.cumsum(rng.standard_normal(2000))
    b, a = signal.butter(4, 100.0 / 500.0)
    np.testing.assert_allclose(butter_lowpass_zero_phase(x, 100.0, 1000.0), signal.filtfilt(b, a, x, padtype="odd", padlen=12), atol=1e-9)
    sos = signal.butter(4, 5.0 / 500.0, output="sos")
    full = signal.sosfiltfilt(sos, x, padlen=3 * (2 * len(sos) + 1))
    np.testing.assert_allclose(lowpass_decimate(x, 80, 5.0, 1000.0), full[1999::-80][::-1], atol=1e-9)


def test_short_record_pads_all_it_has() -> None:
    x = np.random.default_rng(10).standard_normal(10)
    sos = signal.butter(4, 5.0 / 500.0, output="sos")
    full = signal.sosfiltfilt(sos, x, padlen=9)  # the padding cannot exceed n - 1 samples
    np.testing.assert_allclose(lowpass_decimate(x, 3, 5.0, 1000.0), full[9::-3][::-1], atol=1e-12)


def test_cutoff_error_names_the_nyquist_frequency() -> None:
    with pytest.raises(ValueError, match=r"^cut-off 600.0 Hz must lie between 0 and the Nyquist frequency 500.0 Hz$"):
        butter_lowpass_zero_phase(np.zeros(100), 600.0, 1000.0)


@pytest.mark.parametrize(("n", "nperseg"), [(64, 64), (777, 777), (1000, 255), (2456, 2048), (5000, 256)])
def test_welch_is_scipys(n: int, nperseg: int) -> None:
    x = np.cumsum(np.random.default_rng(n).standard_normal(n)) + np.random.default_rng(n + 1).standard_normal(n)
    f, P = spectra.welch_psd(x - x.mean(), 200.0, nperseg)
    want_f, want_P = signal.welch(x - x.mean(), fs=200.0, nperseg=nperseg)
    np.testing.assert_array_equal(f, want_f)
    assert np.max(np.abs(P - want_P)) <= 1e-13 * np.max(want_P)


def test_local_maxima_are_find_peaks() -> None:
    rng = np.random.default_rng(7)
    for _ in range(500):  # small integers: many flat tops and ties at the ends
        x = rng.integers(0, 4, size=int(rng.integers(0, 30))).astype(float)
        np.testing.assert_array_equal(spectra.local_maxima(x), signal.find_peaks(x)[0])


def _scan_formed_anew(system: filtering.System, x: np.ndarray) -> None:
    """:func:`ilic_cli.filtering._run` as it was before its scan's steps were cached: each step formed and tested in the loop."""
    fir, A, B, C, D, _ = system
    rows, n = x.shape
    if fir is not None:
        filtering._fir_in_place(x, fir)
    m, L = len(B), min(filtering.BLOCK, n)
    s = filtering._blocks(A.tobytes(), B.tobytes(), C.tobytes(), float(D), m, L)
    nb, tail = divmod(n, L)
    full = x[:, : nb * L].reshape(rows, nb, L)
    start = np.zeros((rows, nb + 1, m))
    filtering._product(full, s.G, start[:, 1:])
    step, d = s.P.T.copy(), 1
    while d < nb and np.max(np.abs(step)) > filtering.NEGLIGIBLE:
        filtering._product(start[:, 1 : nb + 1 - d], step, start[:, d + 1 :], add=True)
        step, d = step @ step, 2 * d
    if tail:
        x[:, None, nb * L :] = x[:, None, nb * L :] @ s.TT[:tail, :tail] + start[:, nb : nb + 1] @ s.Obs[:, :tail]
    filtering._product(full, s.TT, full)
    filtering._product(start[:, :nb], s.Obs, full, add=True)


@pytest.mark.parametrize("r", [2, 10, 40])
def test_the_cached_scan_is_the_scan_formed_anew_bit_for_bit(r: int) -> None:
    """The prefix scan's cached steps (``filtering._doublings``) give the bits of forming them in the loop, at every block count
    around the powers of two (where the count of doublings changes) and on a long record (up to 12 doublings)."""
    system = filtering._tf_system(*cheby1_ba(8, 0.05, 0.8 / r))
    rng = np.random.default_rng(r)
    L = filtering.BLOCK
    for nb in (*range(1, 10), 15, 16, 17, 31, 32, 33, 64, 65, 3000):
        for n in (nb * L, nb * L + 7):
            x = rng.standard_normal((2, n))
            ours, anew = x.copy(), x.copy()
            filtering._run(system, ours)
            _scan_formed_anew(system, anew)
            assert np.array_equal(ours, anew), (nb, n)
