"""The IIR filters of identification equal SciPy's bit for bit, and so do the cached designs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from ilic_cli import iir


@pytest.fixture(scope="module")
def x() -> np.ndarray:
    rng = np.random.default_rng(11)
    return np.cumsum(rng.normal(size=(3, 5000)), axis=1)


@pytest.mark.parametrize("design", [signal.butter(4, 0.2), signal.cheby1(8, 0.05, 0.08), signal.butter(2, 0.013), (np.array([0.3, 0.1]), np.array([2.0, -0.5]))])
def test_lfilter_and_filtfilt_are_scipys(x: np.ndarray, design: tuple[np.ndarray, np.ndarray]) -> None:
    b, a = design
    zi = signal.lfilter_zi(b, a)
    np.testing.assert_array_equal(iir.lfilter_zi(b, a), zi)
    want = signal.lfilter(b, a, x, axis=-1, zi=np.outer(x[:, 0], zi))[0]
    np.testing.assert_array_equal(iir.lfilter(b, a, x, np.outer(x[:, 0], zi)), want)
    padlen = 3 * (max(len(a), len(b)) - 1)
    np.testing.assert_array_equal(iir.filtfilt(b, a, x, padlen), signal.filtfilt(b, a, x, axis=-1, padtype="odd", padlen=padlen))


@pytest.mark.parametrize("padlen", [None, 27, 0])
def test_sosfiltfilt_is_scipys(x: np.ndarray, padlen: int | None) -> None:
    sos = signal.butter(4, 0.01, output="sos")
    np.testing.assert_array_equal(iir.sosfilt_zi(sos), signal.sosfilt_zi(sos))
    np.testing.assert_array_equal(iir.sosfiltfilt(sos, x, padlen), signal.sosfiltfilt(sos, x, axis=-1, padlen=padlen))
    np.testing.assert_array_equal(iir.sosfiltfilt(sos, x[0], padlen), signal.sosfiltfilt(sos, x[0], padlen=padlen))


def test_cached_designs_are_scipys() -> None:
    for key in iir.DESIGNS:
        if key[0] == "butter":
            _, order, wn, output = key
            got = iir.butter(order, wn, output)  # type: ignore[arg-type]
            want = (signal.butter(order, wn, output="sos"),) if output == "sos" else signal.butter(order, wn)
        else:
            _, order, ripple, wn, _ = key
            got, want = iir.cheby1(order, ripple, wn), signal.cheby1(order, ripple, wn)  # type: ignore[arg-type]
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
    # a design outside the table comes from SciPy
    for g, w in zip(iir.butter(3, 0.37), signal.butter(3, 0.37), strict=True):
        np.testing.assert_array_equal(g, w)


def test_odd_extension_refuses_too_long_a_padding() -> None:
    with pytest.raises(ValueError, match="padding"):
        iir.odd_ext(np.arange(5.0)[None, :], 5)
