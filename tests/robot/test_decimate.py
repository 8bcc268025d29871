"""The robot path's compiled decimation against the 1-DOF chain's MATLAB ``decimate`` (``ilic_cli.filtering.decimate_matlab``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.filtering import decimate_matlab  # noqa: E402
from ilic_cli.robot.idim import chebyshev_sections, decimate_columns  # noqa: E402


@pytest.mark.parametrize(("n", "r"), [(30, 2), (1001, 10), (20_000, 20), (20_001, 40), (6_007, 7), (16_000, 80)])
def test_decimate_columns_is_decimate_matlab_to_3e_11(n: int, r: int) -> None:
    """Same filter, padding and end-aligned kept samples; only the order of operations differs (measured: 1.2e-12 of a
    column's largest at most up to r = 40, 1.6e-11 at r = 80, whose poles lie within 0.004 of z = 1)."""
    rng = np.random.default_rng(n + r)
    # random walks, steps, a constant and a sine: the columns of a regressor and a torque
    x = np.column_stack(
        [np.cumsum(rng.standard_normal((n, 5)), axis=0), np.sign(np.sin(np.arange(n) / 50.0)), np.full(n, 3.0), 1e3 * np.sin(np.arange(n) / 90.0)]
    )
    want = decimate_matlab(x, r, axis=0)
    got = decimate_columns(x.copy(), r)
    assert got.shape == want.shape
    error = np.abs(got - want).max(axis=0) / np.abs(want).max(axis=0)
    assert np.all(error < 3e-11), error
    gain = chebyshev_sections(r)[2]
    np.testing.assert_allclose(got[:, 6], 3.0 * gain**2, rtol=1e-13)  # a constant: the steady-state starts, the DC gain of each pass


def test_decimate_columns_does_not_depend_on_the_other_columns() -> None:
    """Each column is filtered on its own: the parts (a thread each) and the columns beside it change no bit."""
    rng = np.random.default_rng(1)
    x = rng.standard_normal((5000, 9))
    whole = decimate_columns(x.copy(), 20)
    for c in range(9):
        assert np.array_equal(decimate_columns(x[:, c : c + 1].copy(), 20)[:, 0], whole[:, c])
    parts = np.zeros((2, 5000, 5))
    parts[0], parts[1, :, :4] = x[:, :5], x[:, 5:]
    assert np.array_equal(decimate_columns(parts, 20)[:, :9], whole)


def test_chebyshev_sections_are_the_transfer_function() -> None:
    """The sections' product is MATLAB's ``b/a`` (order 8, 0.05 dB, 0.8/r) and the gain its DC gain.

    Multiplied out, the sections of the polished roots give ``a`` back to 3e-13 (r = 10), 5e-12 (20), 1e-9 (40) of its
    largest coefficient: the ill-conditioning of ``a`` itself; the filters' outputs agree far closer (the test above).
    Beyond r = 13 the rounded ``a`` is another filter (its DC gain 0.922 at r = 80), and the sections are the design's poles.
    """
    from ilic_cli.filter_design import cheby1_ba, cheby1_zpk  # the designs decimate_matlab uses

    for r, tolerance in ((10, 1e-12), (13, 1e-12)):
        sections, k, gain = chebyshev_sections(r)
        b, a = cheby1_ba(8, 0.05, 0.8 / r)
        poly = np.array([1.0])
        for a1, a2 in sections:
            poly = np.convolve(poly, [1.0, a1, a2])
        np.testing.assert_allclose(poly, a / a[0], rtol=0, atol=tolerance * np.abs(a / a[0]).max())
        np.testing.assert_allclose(k * np.array([1, 8, 28, 56, 70, 56, 28, 8, 1]), b / a[0], rtol=1e-14)
        assert gain == math.fsum(b) / math.fsum(a)  # as filtfilt_matlab's steady-state starts
        assert gain == pytest.approx(10 ** (-0.05 / 20), rel=1e-7)  # even order: at the ripple's bottom
    for r in (20, 40, 80, 100):  # beyond MATLAB's one stage: the design's own poles, as decimate_matlab's sections
        sections, k, gain = chebyshev_sections(r)
        _, poles, _ = cheby1_zpk(8, 0.05, 0.8 / r)
        upper = poles[poles.imag > 0]
        want = np.array(sorted(zip(-2.0 * upper.real, np.abs(upper) ** 2, strict=True)))
        np.testing.assert_allclose(np.array(sorted(map(tuple, sections))), want, rtol=1e-13)
        assert gain == pytest.approx(10 ** (-0.05 / 20), rel=1e-9)
    with pytest.raises(ValueError, match="greater than padlen"):
        decimate_columns(np.zeros((24, 2)), 10)


def _filtfilt_kept_numpy(x: np.ndarray, r: int) -> np.ndarray:
    """:func:`ilic_cli.robot.kernel.filtfilt_kept`'s arithmetic in the same order, one sample at a time in NumPy."""
    from ilic_cli.filtering import kept_indices  # the end-aligned samples decimate_matlab keeps

    sections, k, gain = chebyshev_sections(r)
    n, pad = len(x), 24
    keep = kept_indices(n, r)

    def run(signal: np.ndarray, x0: np.ndarray) -> np.ndarray:
        w1, w2, y = np.zeros((4, x.shape[1])), np.zeros((4, x.shape[1])), np.empty_like(signal)
        for i, value in enumerate(signal):
            u = value - x0
            for s, (a1, a2) in enumerate(sections):
                w = u - a1 * w1[s] - a2 * w2[s]
                u = w + 2.0 * w1[s] + w2[s]
                w2[s], w1[s] = w1[s], w
            y[i] = k * u + gain * x0
        return y

    ext = np.concatenate([2.0 * x[:1] - x[pad:0:-1], x, 2.0 * x[-1:] - x[-2 : -pad - 2 : -1]])
    forward = run(ext, ext[0].copy())
    backward = run(forward[::-1], forward[-1].copy())[::-1]
    return backward[pad : pad + n][keep]


def test_decimate_columns_bits_are_its_recursion_in_numpy() -> None:
    """The compiled loops (vectorised across a sample's columns, two threads) give the plain recursion's bits."""
    x = np.cumsum(np.random.default_rng(7).standard_normal((1500, 11)), axis=0)
    assert np.array_equal(decimate_columns(x.copy(), 20), _filtfilt_kept_numpy(x, 20))
