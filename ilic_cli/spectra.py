"""Spectra of residuals: Welch's power spectral density and the local maxima of a spectrum (``scipy.signal``'s, in NumPy).

Pure functions on arrays (``import scipy.signal`` alone costs about a second of start-up);
``tests/unit/test_filtering.py`` checks both against ``scipy.signal``.
"""

from __future__ import annotations

import numpy as np


def welch_psd(x: np.ndarray, fs_hz: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided power spectral density by Welch's method: ``(f_Hz, P)`` (``scipy.signal.welch`` defaults).

    Periodic Hann window of ``nperseg`` samples, half overlap, each segment's
    mean removed, density scaling, segments averaged.
    """
    x = np.asarray(x, dtype=np.float64)
    step = nperseg - nperseg // 2
    win = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)
    starts = np.arange(0, len(x) - nperseg + 1, step)
    seg = x[starts[:, None] + np.arange(nperseg)]
    seg = seg - seg.mean(axis=1, keepdims=True)
    spec = np.abs(np.fft.rfft(seg * win, axis=1)) ** 2 / (fs_hz * float(win @ win))
    spec[:, 1 : nperseg // 2 + (nperseg % 2)] *= 2.0  # one-sided: every bin but 0 and (even nperseg) Nyquist doubled
    return np.fft.rfftfreq(nperseg, 1.0 / fs_hz), spec.mean(axis=0)


def local_maxima(x: np.ndarray) -> np.ndarray:
    """Indices of the local maxima of ``x`` (``scipy.signal.find_peaks`` without conditions).

    A sample above its left neighbour whose run of equal values ends above
    the next sample; a flat top gives its middle sample (rounded down).
    """
    x = np.asarray(x)
    peaks = []
    i, n = 1, len(x)
    while i < n - 1:
        if x[i - 1] < x[i]:
            j = i + 1
            while j < n - 1 and x[j] == x[i]:
                j += 1
            if x[j] < x[i]:
                peaks.append((i + j - 1) // 2)
                i = j
        i += 1
    return np.asarray(peaks, dtype=np.intp)
