"""Filter design: SciPy's algorithms in NumPy (importing ``scipy.signal`` costs about a second of start-up).

Analog prototype (Butterworth, Chebyshev type I), pre-warping, bilinear transform, pole-zero pairing into
second-order sections: the designs :mod:`ilic_cli.filtering` runs. ``tests/unit/test_filtering_scipy.py``
checks each against ``scipy.signal``.
"""

from __future__ import annotations

import functools
import math

import numpy as np


def lowpass_zpk(poles: np.ndarray, gain: float, wn: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Digital low-pass ``(z, p, k)`` from an analog prototype with no zeros, cut-off ``wn`` (fraction of Nyquist).

    Pre-warping, low-pass scaling and bilinear transform at ``fs = 2`` (``scipy.signal.iirfilter``).
    """
    if not 0.0 < wn < 1.0:
        raise ValueError(f"normalised cut-off {wn} must lie strictly between 0 and 1")
    warped = 4.0 * math.tan(math.pi * wn / 2.0)
    p = warped * poles
    k = gain * warped ** len(p)
    z_d = -np.ones(len(p))
    p_d = (4.0 + p) / (4.0 - p)
    k_d = k * float(np.real(1.0 / np.prod(4.0 - p)))
    return z_d, p_d, k_d


def butter_zpk(order: int, wn: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Butterworth low-pass of ``order`` (analog prototype ``scipy.signal.buttap``)."""
    m = np.arange(-order + 1, order, 2)
    return lowpass_zpk(-np.exp(1j * math.pi * m / (2 * order)), 1.0, wn)


def cheby1_zpk(order: int, ripple_db: float, wn: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Chebyshev type I low-pass (analog prototype ``scipy.signal.cheb1ap``)."""
    eps = math.sqrt(10 ** (0.1 * ripple_db) - 1.0)
    mu = math.asinh(1 / eps) / order
    theta = math.pi * np.arange(-order + 1, order, 2) / (2 * order)
    p = -np.sinh(mu + 1j * theta)
    k = float(np.prod(-p).real)
    if order % 2 == 0:
        k = k / math.sqrt(1 + eps * eps)
    return lowpass_zpk(p, k, wn)


def zpk2tf(z: np.ndarray, p: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Transfer-function coefficients ``(b, a)`` of ``(z, p, k)`` (conjugate pairs give real polynomials)."""
    return k * np.real(np.poly(z)), np.real(np.poly(p))


def section(z: list[complex], p: list[complex]) -> np.ndarray:
    """One second-order section ``[b0, b1, b2, 1, a1, a2]`` with unit gain (``scipy.signal`` ``_single_zpksos``)."""
    sos = np.zeros(6)
    b, a = zpk2tf(np.array(z), np.array(p), 1.0)
    sos[3 - len(b) : 3] = b
    sos[6 - len(a) : 6] = a
    return sos


def zpk2sos(z: np.ndarray, p: np.ndarray, k: float) -> np.ndarray:
    """Second-order sections of a low-pass with real zeros (``scipy.signal.zpk2sos``, pairing ``nearest``).

    Poles are taken from the closest to the unit circle, which go last, each
    paired with its nearest zeros.
    """
    if len(p) % 2:
        p, z = np.append(p, 0.0), np.append(z, 0.0)
    n_sections = len(p) // 2
    # one pole of each conjugate pair (sorted as scipy's _cplxreal), then the real poles
    p = p[np.lexsort((abs(p.imag), p.real))]
    is_real = abs(p.imag) <= 100 * np.finfo(float).eps * abs(p)
    p = np.concatenate([(p[~is_real & (p.imag > 0)] + p[~is_real & (p.imag < 0)].conj()) / 2, p[is_real].real])
    z = np.sort(z.real)
    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        i = int(np.argmin(np.abs(1 - np.abs(p))))
        p1, p = p[i], np.delete(p, i)
        reals = np.flatnonzero(np.isreal(p))
        if np.isreal(p1) and len(reals) == 0:
            j = int(np.argmin(abs(z - p1)))
            sos[si] = section([z[j], 0], [p1, 0])
            z = np.delete(z, j)
            continue
        if np.isreal(p1):
            i2 = reals[int(np.argmin(np.abs(1 - np.abs(p[reals]))))]
            p2, p = p[i2], np.delete(p, i2)
        else:
            p2 = np.conj(p1)
        pair = []
        for _ in range(2):
            j = int(np.argsort(abs(z - p1), kind="stable")[0])
            pair.append(z[j])
            z = np.delete(z, j)
        sos[si] = section(pair, [p1, p2])
    sos[0, :3] *= k
    return sos


@functools.lru_cache(maxsize=32)
def butter_ba(order: int, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """Butterworth low-pass ``(b, a)`` (``scipy.signal.butter(order, wn)``; cached)."""
    return zpk2tf(*butter_zpk(order, wn))


@functools.lru_cache(maxsize=32)
def butter_sos(order: int, wn: float) -> np.ndarray:
    """Butterworth low-pass in second-order sections (``scipy.signal.butter(order, wn, output="sos")``; cached: the online loop designs it every window)."""
    return zpk2sos(*butter_zpk(order, wn))


@functools.lru_cache(maxsize=32)
def cheby1_ba(order: int, ripple_db: float, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev type I low-pass ``(b, a)`` (``scipy.signal.cheby1(order, ripple_db, wn)``; cached)."""
    return zpk2tf(*cheby1_zpk(order, ripple_db, wn))


@functools.lru_cache(maxsize=32)
def cheby1_sos(order: int, ripple_db: float, wn: float) -> np.ndarray:
    """Chebyshev type I low-pass in second-order sections (``scipy.signal.cheby1(order, ripple_db, wn, output="sos")``; cached)."""
    return zpk2sos(*cheby1_zpk(order, ripple_db, wn))


@functools.lru_cache(maxsize=64)
def bilinear_ba(b_s: tuple[float, ...], a_s: tuple[float, ...], fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Digital ``(b, a)`` of the analog ``B(s)/A(s)`` by the bilinear transform (``scipy.signal.bilinear``; cached).

    ``sum_q c_q ((z + 1)/f)^(N - q) ((z - 1) f)^q`` with ``f = sqrt(2 fs)``, for
    the numerator and the denominator, in ascending powers of ``z``.
    """
    b, a = np.trim_zeros(np.atleast_1d(np.asarray(b_s, dtype=float)), "f"), np.trim_zeros(np.atleast_1d(np.asarray(a_s, dtype=float)), "f")
    fac = math.sqrt(fs_hz * 2)
    zp1, zm1 = np.array([1.0, 1.0]) / fac, np.array([-1.0, 1.0]) * fac
    n = max(len(a), len(b)) - 1

    def power(c: np.ndarray, k: int) -> np.ndarray:
        out = np.ones(1)
        for _ in range(k):
            out = np.convolve(out, c)
        return out

    def transformed(coef: np.ndarray) -> np.ndarray:
        total = np.zeros(n + 1)
        for q, c in enumerate(coef[::-1]):
            total += c * np.convolve(power(zp1, n - q), power(zm1, q))
        return total[::-1]

    bz, az = transformed(b), transformed(a)
    return bz / az[0], az / az[0]
