"""The NumPy filters of :mod:`ilic_cli.filtering` against ``scipy.signal``, and the start-up they save.

Tolerances are relative to ``max|x|``:

* filter design (``butter``, ``cheby1``, ``bilinear``, ``zpk2sos``): 1e-14 on
  the coefficients (the same algorithms; equal to the last bit today);
* second-order sections (``sosfiltfilt``), a bilinear resonance (``lfilter``
  with ``lfilter_zi``): 1e-11 / 1e-10;
* transfer-function ``filtfilt`` of Butterworth filters: 1e-9; of the
  8th-order Chebyshev anti-alias filter of ``decimate``: 2e-8 for ``r <= 10``.
  The direct form that ``scipy.signal.lfilter`` (and MATLAB) runs amplifies
  its rounding by the denominator's small DC value (1e9 at ``r = 10``): SciPy
  itself is that far from the exact output of its coefficients, which
  :func:`test_ill_conditioned_chebyshev_is_closer_to_exact_than_scipy` shows.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ilic_cli import filter_design, filtering
from ilic_cli.filtering import bilinear_lfilter, butter_lowpass_zero_phase, decimate_matlab, filtfilt_matlab, kept_indices, lowpass_decimate
from tests.lazy import lazy_module

signal = lazy_module("scipy.signal")  # imported at first use (tests/lazy.py)

ROOT = Path(__file__).parents[2]
LENGTHS = (13, 31, 32, 33, 100, 1000, 20_003)


def _walk(n: int, seed: int = 0) -> np.ndarray:
    """A random walk: low-frequency content as in a position log, so the filters' DC behaviour matters."""
    return np.cumsum(np.random.default_rng(seed).standard_normal(n))


def _assert_close(got: np.ndarray, want: np.ndarray, x: np.ndarray, rel: float) -> None:
    assert got.shape == want.shape
    err = np.max(np.abs(got - want)) / np.max(np.abs(x))
    assert err <= rel, f"max |difference| {err:.3g} * max|x| > {rel:g}"


@pytest.mark.parametrize("order", range(1, 11))
@pytest.mark.parametrize("wn", [0.005, 0.02, 0.1, 0.5, 0.9])
def test_butterworth_design_is_scipys(order: int, wn: float) -> None:
    b, a = filter_design.butter_ba(order, wn)
    want_b, want_a = signal.butter(order, wn)
    np.testing.assert_allclose(b, want_b, rtol=1e-14, atol=1e-14 * np.max(np.abs(want_b)))
    np.testing.assert_allclose(a, want_a, rtol=1e-14, atol=1e-14 * np.max(np.abs(want_a)))
    sos = filter_design.butter_sos(order, wn)
    np.testing.assert_allclose(sos, signal.butter(order, wn, output="sos"), rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("order", range(1, 9))
@pytest.mark.parametrize("r", [2, 3, 5, 10, 13, 20])
def test_chebyshev_design_is_scipys(order: int, r: int) -> None:
    b, a = filter_design.cheby1_ba(order, 0.05, 0.8 / r)
    want_b, want_a = signal.cheby1(order, 0.05, 0.8 / r)
    np.testing.assert_allclose(b, want_b, rtol=1e-14, atol=1e-14 * np.max(np.abs(want_b)))
    np.testing.assert_allclose(a, want_a, rtol=1e-14, atol=1e-14 * np.max(np.abs(want_a)))


def test_design_rejects_cutoffs_outside_nyquist() -> None:
    for wn in (0.0, 1.0, 1.5):
        with pytest.raises(ValueError, match="strictly between 0 and 1"):
            filter_design.butter_zpk(4, wn)


@pytest.mark.parametrize("n", LENGTHS)
@pytest.mark.parametrize("order", [1, 2, 3, 4, 6])
@pytest.mark.parametrize("wn", [0.05, 0.2, 0.6])
def test_filtfilt_matlab_is_scipys_transfer_function_filtfilt(n: int, order: int, wn: float) -> None:
    b, a = signal.butter(order, wn)
    x = _walk(n, order)
    if n <= 3 * order:
        with pytest.raises(ValueError, match="greater than padlen"):
            filtfilt_matlab(b, a, x)
        return
    _assert_close(filtfilt_matlab(b, a, x), signal.filtfilt(b, a, x, padtype="odd", padlen=3 * order), x, 1e-9)


def test_fir_filtfilt_is_scipys() -> None:
    """A denominator of 1 (moving average): no recursion, the numerator alone."""
    x = _walk(200, 3)
    b, a = np.ones(5) / 5, np.ones(1)
    _assert_close(filtfilt_matlab(b, a, x), signal.filtfilt(b, a, x, padtype="odd", padlen=12), x, 1e-14)


@pytest.mark.parametrize("n", [25, 33, 100, 1000, 20_003])
@pytest.mark.parametrize("r", [2, 5, 10])
def test_decimate_matlab_is_scipys_chebyshev_filtfilt(n: int, r: int) -> None:
    x = _walk(n, r)
    b, a = signal.cheby1(8, 0.05, 0.8 / r)
    want = signal.filtfilt(b, a, x, padtype="odd", padlen=24)[kept_indices(n, r)]
    _assert_close(decimate_matlab(x, r), want, x, 2e-8)


@pytest.mark.parametrize("r", [14, 20, 40, 80, 100, 160])
def test_decimate_matlab_beyond_13_is_the_chebyshev_design_in_sections(r: int) -> None:
    """Above MATLAB's one-stage limit the order-8 design itself (``cheby1(..., output="sos")``), MATLAB's padding.

    The transfer function's rounded coefficients are another filter there: its DC gain 0.99493 at r = 40, 0.922 at 80,
    -3.4 at 100, for the design's 0.99426 (the bottom of its 0.05 dB ripple)."""
    x = _walk(20_003, r)
    sos = signal.cheby1(8, 0.05, 0.8 / r, output="sos")
    np.testing.assert_allclose(filter_design.cheby1_sos(8, 0.05, 0.8 / r), sos, rtol=1e-14, atol=1e-14)
    want = signal.sosfiltfilt(sos, x, padtype="odd", padlen=24)[kept_indices(len(x), r)]
    _assert_close(decimate_matlab(x, r), want, x, 1e-10)
    flat = decimate_matlab(np.full(5000, 2.0), r)  # a constant: the steady-state starts, the design's DC gain each pass
    np.testing.assert_allclose(flat, 2.0 * 10 ** (-0.05 / 10), rtol=1e-9)


def _direct_form_extended(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """``lfilter`` in extended precision (``np.longdouble``), sample by sample: the reference for an ill-conditioned direct form."""
    b, a = (np.asarray(v, dtype=np.longdouble) / np.longdouble(a[0]) for v in (b, a))
    z = np.asarray(zi, dtype=np.longdouble).copy()
    y = np.empty(len(x), dtype=np.longdouble)
    for i, xi in enumerate(np.asarray(x, dtype=np.longdouble)):
        y[i] = b[0] * xi + z[0]
        z[:-1] = b[1:-1] * xi + z[1:] - a[1:-1] * y[i]
        z[-1] = b[-1] * xi - a[-1] * y[i]
    return y


def test_ill_conditioned_chebyshev_is_closer_to_exact_than_scipy() -> None:
    """At ``r = 10`` SciPy's direct form is off the exact output by ~1e-8 * max|x|; ours is closer."""
    x = _walk(400, 11)
    b, a = signal.cheby1(8, 0.05, 0.08)
    zi = signal.lfilter_zi(b, a)
    exact = _direct_form_extended(b, a, x, zi * x[0]).astype(np.float64)
    theirs = signal.lfilter(b, a, x, zi=zi * x[0])[0]
    ours = bilinear_lfilter_free(b, a, x)
    assert np.max(np.abs(theirs - exact)) > 1e-10 * np.max(np.abs(x))  # the conditioning is real
    assert np.max(np.abs(ours - exact)) < np.max(np.abs(theirs - exact))


def bilinear_lfilter_free(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])`` by :mod:`ilic_cli.filtering`'s recursion."""
    y = np.array(x[None, :])
    filtering._steady_start(filtering._tf_system(b, a), y)
    return y[0]


@pytest.mark.parametrize("n", LENGTHS)
@pytest.mark.parametrize("order", [2, 4, 8])
@pytest.mark.parametrize("cutoff", [5.0, 50.0])
def test_sosfiltfilt_at_5_hz_of_1_khz(n: int, order: int, cutoff: float) -> None:
    x = _walk(n, order)
    sos = signal.butter(order, cutoff / 500.0, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if n > padlen:  # SciPy's default padding
        _assert_close(butter_lowpass_zero_phase(x, cutoff, 1000.0, order, matlab=False), signal.sosfiltfilt(sos, x), x, 1e-11)
    want = signal.sosfiltfilt(sos, x, padlen=min(n - 1, padlen))[kept_indices(n, 80)]
    _assert_close(lowpass_decimate(x, 80, cutoff, 1000.0, order), want, x, 1e-11)


def test_odd_order_sections_pad_as_scipy() -> None:
    """An odd order has a first-order section: SciPy's default padding leaves its zero taps out."""
    x = _walk(500, 5)
    sos = signal.butter(3, 0.1, output="sos")
    assert filtering._sos_padlen(sos) == 3 * (2 * 2 + 1 - 1)
    _assert_close(butter_lowpass_zero_phase(x, 50.0, 1000.0, 3, matlab=False), signal.sosfiltfilt(sos, x), x, 1e-11)


@pytest.mark.parametrize("n", [1, 2, 31, 33, 1000, 20_003])
@pytest.mark.parametrize("f_hz", [2.0, 20.0, 200.0, 450.0])
def test_bilinear_lfilter_is_scipys(n: int, f_hz: float) -> None:
    w = 2 * np.pi * f_hz
    b_s, a_s = [0.1 * w, w * w], [1.0, 0.1 * w, w * w]
    b, a = signal.bilinear(b_s, a_s, fs=1000.0)
    np.testing.assert_allclose(filter_design.bilinear_ba(tuple(b_s), tuple(a_s), 1000.0), (b, a), rtol=1e-14, atol=1e-14)
    x = _walk(n, int(f_hz)) + 3.0
    want = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])[0]
    _assert_close(bilinear_lfilter(b_s, a_s, 1000.0, x), want, x, 1e-10)


@pytest.mark.parametrize("block", [1, 3, 32, 50])
def test_block_length_does_not_change_the_result(block: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Many short blocks (a deep prefix scan) or one block per record: the same output."""
    x = _walk(2_000, 4)
    b, a = signal.butter(4, 0.05)
    want = signal.filtfilt(b, a, x, padtype="odd", padlen=12)
    monkeypatch.setattr(filtering, "BLOCK", block)
    _assert_close(filtfilt_matlab(b, a, x), want, x, 1e-9)
    monkeypatch.setattr(filtering, "NEGLIGIBLE", 0.0)  # scan to the end: nothing beyond the cut-off mattered
    _assert_close(filtfilt_matlab(b, a, x), want, x, 1e-9)


def test_small_blas_chunks_give_one_product(monkeypatch: pytest.MonkeyPatch) -> None:
    """Products cut into chunks of one row (the scan's in-place update runs last chunk first): the same numbers."""
    x = np.stack([_walk(3_001, 1), _walk(3_001, 2)])
    sos = signal.butter(4, 0.01, output="sos")
    want = signal.sosfiltfilt(sos, x, axis=1)
    monkeypatch.setattr(filtering, "BLAS_ONE_THREAD", 1)
    _assert_close(butter_lowpass_zero_phase(x, 5.0, 1000.0, matlab=False, axis=1), want, x, 1e-11)


@pytest.mark.parametrize(
    ("args", "heavy"),
    [
        (["identify", "--method", "ls"], ("scipy.signal", "scipy.stats", "matplotlib", "pandas", "numba")),
        (["diagnose"], ("scipy.signal", "scipy.stats", "matplotlib", "pandas")),
    ],
)
def test_a_mat_file_command_does_not_import_scipy_signal(tmp_path: Path, args: list[str], heavy: tuple[str, ...]) -> None:
    """``ilic identify LOG.mat --method ls`` and ``ilic diagnose LOG.mat``: no ``scipy.signal`` nor ``scipy.stats``, which cost ~1 s of start-up."""
    from ilic_cli.io import write_log
    from tests.conftest import make_synthetic_log

    path = write_log(make_synthetic_log(samples=3_000), tmp_path / "log.mat")
    code = (
        "import sys\n"
        "from ilic_cli.cli import main\n"
        "try:\n"
        f"    main([{args[0]!r}, {str(path)!r}, *{args[1:]!r}, '--format', 'json'])\n"
        "except SystemExit as exc:\n"
        "    assert not exc.code, exc.code\n"
        f"print('HEAVY', [m for m in {heavy!r} if m in sys.modules])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    assert '"relative_error_pct"' in out.stdout  # the command did its work
    assert out.stdout.strip().splitlines()[-1] == "HEAVY []"


def test_a_rows_result_does_not_depend_on_the_rows_beside_it() -> None:
    """Columns filtered together or one at a time: the same bits (IDIM-LS decimates its matrix column by column)."""
    x = np.cumsum(np.random.default_rng(12).standard_normal((5, 2_503)), axis=1)
    together = decimate_matlab(x, 10, axis=1)
    for i in (0, 4):
        np.testing.assert_array_equal(decimate_matlab(x[i], 10), together[i])
    windows = lowpass_decimate(x, 80, 5.0, 1000.0)
    np.testing.assert_array_equal(lowpass_decimate(x[2:3], 80, 5.0, 1000.0), windows[2:3])
