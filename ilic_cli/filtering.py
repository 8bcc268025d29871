"""Data filtering for identification (paper section III; benchmark procedure).

Pure functions on arrays. The ``matlab`` helpers reproduce MATLAB's
``filtfilt`` and ``decimate`` exactly where that decides published digits
(see ``../shared/reference/emps-benchmark.md``): odd-reflection padding of
length ``3*(max(len(a), len(b)) - 1)`` and decimation that keeps the samples
aligned on the end of the record.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable

import numpy as np

PARALLEL_MIN_SIZE = 200_000
"""Arrays at least this large are filtered in threads (SciPy's filters release the GIL)."""


CHUNK_ELEMENTS = 1 << 21
"""Rows of a 2-D or larger array are filtered in blocks of about this many samples (16 MB)."""


def _in_threads(func: Callable[[np.ndarray], np.ndarray], x: np.ndarray, axis: int, keep: np.ndarray | None = None) -> np.ndarray:
    """Apply ``func`` (a filter along the last axis) to ``x`` along ``axis``.

    The rows along the filtered axis are filtered in contiguous blocks of
    about :data:`CHUNK_ELEMENTS` samples (in threads when the array is large),
    so the filter's temporaries stay bounded whatever the length of the log.
    ``keep`` (indices along the filtered axis) decimates each block as soon as
    it is filtered, so the full-rate output is never held. The result is
    identical to filtering the whole array at once.
    """
    moved = np.moveaxis(np.asarray(x, dtype=np.float64), axis, -1)

    def run(block: np.ndarray) -> np.ndarray:
        y = func(np.ascontiguousarray(block))
        return y if keep is None else np.take(y, keep, axis=-1)

    if moved.ndim < 2:
        return run(moved)
    # blocks along the first axis: views, copied one block at a time by run()
    per_row = int(np.prod(moved.shape[1:]))
    rows = max(1, CHUNK_ELEMENTS // max(per_row, 1))
    blocks = [moved[i : i + rows] for i in range(0, moved.shape[0], rows)]
    workers = min(os.cpu_count() or 1, 8, len(blocks))
    if per_row > CHUNK_ELEMENTS:
        workers = 1  # rows longer than a block: one at a time, memory over speed
    if workers < 2 or moved.size < PARALLEL_MIN_SIZE:
        parts = [run(block) for block in blocks]
    else:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers) as pool:
            parts = list(pool.map(run, blocks))
    return np.moveaxis(np.concatenate(parts, axis=0), -1, axis)


def filtfilt_matlab(b: np.ndarray, a: np.ndarray, x: np.ndarray, axis: int = 0, keep: np.ndarray | None = None) -> np.ndarray:
    """Zero-phase filtering as MATLAB ``filtfilt`` (odd padding of 3*(order) samples).

    ``keep``: indices along ``axis`` to return (decimation while filtering).
    """
    from scipy.signal import filtfilt

    padlen = 3 * (max(len(a), len(b)) - 1)
    return _in_threads(lambda c: filtfilt(b, a, c, axis=-1, padtype="odd", padlen=padlen), x, axis, keep)


def butter_lowpass_zero_phase(x: np.ndarray, cutoff_hz: float, fs_hz: float, order: int = 4, *, matlab: bool = True, axis: int = 0) -> np.ndarray:
    """Butterworth low-pass applied forward-backward (zero phase).

    Parameters
    ----------
    x : ndarray
        Signal(s), filtered along ``axis``.
    cutoff_hz, fs_hz : float
        Cut-off and sampling frequency (Hz).
    order : int
        Butterworth order (benchmark: 4).
    matlab : bool
        Transfer-function form with MATLAB's padding (default, reproduces
        published digits); otherwise second-order sections with SciPy's
        default padding (numerically safer at very low cut-offs).
    """
    from scipy import signal

    wn = cutoff_hz / (fs_hz / 2.0)
    if not 0.0 < wn < 1.0:
        raise ValueError(f"cut-off {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2} Hz")
    if matlab:
        b, a = signal.butter(order, wn)
        return filtfilt_matlab(b, a, x, axis=axis)
    sos = signal.butter(order, wn, output="sos")
    return signal.sosfiltfilt(sos, x, axis=axis)


def central_difference(x: np.ndarray, dt_s: float) -> np.ndarray:
    """Derivative by central differences, one-sided at both ends (MATLAB ``gradient``)."""
    return np.gradient(x, dt_s, axis=0)


def decimation_factor(fs_hz: float, cutoff_hz: float) -> int:
    """Decimation factor whose anti-alias cut-off ``0.8*fs/(2r)`` is ``cutoff_hz``.

    The benchmark uses ``round(0.8*500/40) = 10`` at 1 kHz.
    """
    return max(1, int(round(0.8 * (fs_hz / 2.0) / cutoff_hz)))


def kept_indices(n: int, r: int) -> np.ndarray:
    """Indices kept by end-aligned decimation of ``n`` samples by ``r`` (MATLAB ``decimate``)."""
    nout = math.ceil(n / r)
    return np.arange(r - (r * nout - n) - 1, n, r)


def decimate_matlab(x: np.ndarray, r: int, axis: int = 0) -> np.ndarray:
    """Parallel decimation as MATLAB ``decimate(x, r)`` (IIR mode).

    Chebyshev type I low-pass, order 8, 0.05 dB ripple, cut-off 0.8/r of
    Nyquist, applied forward-backward; keeps one sample in ``r`` aligned on the
    end of the record (first kept sample, 1-based: ``r - (r*nout - nd)``).
    Applied column-wise to a 2-D array, this is the parallel decimation of
    the observation matrix (paper section III).
    """
    from scipy import signal

    if r == 1:
        return np.asarray(x)
    b, a = signal.cheby1(8, 0.05, 0.8 / r)
    x = np.asarray(x)
    return filtfilt_matlab(b, a, x, axis=axis, keep=kept_indices(x.shape[axis], r))


def lowpass_decimate(x: np.ndarray, r: int, cutoff_hz: float, fs_hz: float, order: int = 4, axis: int = -1) -> np.ndarray:
    """Zero-phase Butterworth low-pass (second-order sections) then keep one sample in ``r``.

    Used for the force and the reference regressor of IDIM-ILIC windows
    (paper eq. 24: "filtering and down-sampling"); stable at the very low
    cut-offs (5 Hz at 1 kHz) where the transfer-function form is not. Kept
    samples are aligned on the end of the record, as :func:`decimate_matlab`.
    """
    from scipy import signal

    sos = _butter_sos(order, cutoff_hz / (fs_hz / 2.0)).copy()
    n = x.shape[axis]
    padlen = min(n - 1, 3 * (2 * len(sos) + 1))
    return _in_threads(lambda c: signal.sosfiltfilt(sos, c, axis=-1, padlen=padlen), x, axis, kept_indices(n, r))


@functools.lru_cache(maxsize=32)
def _butter_sos(order: int, wn: float) -> np.ndarray:
    """Butterworth low-pass in second-order sections (cached: the online loop designs it every window)."""
    from scipy import signal

    sos = signal.butter(order, wn, output="sos")
    return sos


def bilinear_lfilter(b_s: list[float], a_s: list[float], fs_hz: float, x: np.ndarray) -> np.ndarray:
    """Apply the continuous filter ``B(s)/A(s)`` to ``x`` forward only (bilinear transform, causal).

    The filter starts in the steady state of ``x[0]`` (no start-up transient).
    """
    from scipy import signal

    b, a = signal.bilinear(b_s, a_s, fs=fs_hz)
    out, _ = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
    return np.asarray(out)
