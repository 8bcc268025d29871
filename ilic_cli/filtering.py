"""Data filtering for identification (paper section III; benchmark procedure).

Pure functions on arrays. The ``matlab`` helpers reproduce MATLAB's ``filtfilt`` and ``decimate`` exactly where that
decides published digits (see ``../shared/reference/emps-benchmark.md``): odd-reflection padding of length
``3*(max(len(a), len(b)) - 1)`` and decimation that keeps the samples aligned on the end of the record.

Everything here is NumPy (``import scipy.signal`` alone costs about a second of start-up): the filters are designed by
SciPy's algorithms (analog prototype, pre-warping, bilinear transform, pole-zero pairing into second-order sections; the
designs: :mod:`ilic_cli.filter_design`) and the linear recursion runs blockwise (:func:`_run`).
``tests/unit/test_filtering_scipy.py`` checks every function against ``scipy.signal``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ilic_cli.filter_design import bilinear_ba, butter_ba, butter_sos, cheby1_ba, cheby1_sos
from ilic_cli.parallel import ordered_map

# ---------------------------------------------------------------------------
# linear recursion, blockwise (exact linear algebra, vectorised over blocks)
# ---------------------------------------------------------------------------
BLOCK = 32
"""Samples per block of the blockwise recursion (:func:`_run`): the zero-state response of a block is a BLOCK x BLOCK matmul."""


@dataclass(frozen=True)
class _StateSpace:
    """``z' = A z + B u``, ``y = C z + D u`` and its block matrices for blocks of ``L`` samples.

    ``TT`` (L x L): zero-state response of a block, transposed (upper-triangular Toeplitz matrix of the impulse response);
    ``G`` (L x m): each sample's input to the state after the block; ``Obs`` (m x L): each sample's response to the state at
    the block's start; ``P = A^L``.
    """

    A: np.ndarray
    D: float
    L: int
    TT: np.ndarray
    G: np.ndarray
    Obs: np.ndarray
    P: np.ndarray


@functools.lru_cache(maxsize=64)
def _blocks(A_key: bytes, B_key: bytes, C_key: bytes, D: float, m: int, L: int) -> _StateSpace:
    """The block matrices of a state-space system (cached: filters are designed from a few settings)."""
    A = np.frombuffer(A_key).reshape(m, m)
    B = np.frombuffer(B_key)
    C = np.frombuffer(C_key)
    Obs = np.empty((m, L))  # Obs[:, j] = (C A^j)^T
    G = np.empty((L, m))  # G[L-1-j] = A^j B
    row, col = C.copy(), B.copy()
    for j in range(L):
        Obs[:, j] = row
        G[L - 1 - j] = col
        row, col = row @ A, A @ col
    h = np.concatenate([[D], C @ G[::-1].T])[:L]  # impulse response: D, C B, C A B, ...
    idx = np.arange(L)
    diff = idx[:, None] - idx[None, :]
    TT = np.where(diff <= 0, h[np.clip(-diff, 0, None)], 0.0)
    return _StateSpace(A=A, D=D, L=L, TT=TT, G=G, Obs=Obs, P=np.linalg.matrix_power(A, L))


NEGLIGIBLE = 2.0**-100
"""The prefix scan stops once ``A^(dL)`` is below this (relative to 1): farther blocks' states no longer reach the result's rounding."""


@functools.lru_cache(maxsize=256)
def _doublings(A_key: bytes, B_key: bytes, C_key: bytes, D: float, m: int, L: int, count: int) -> tuple[np.ndarray, ...]:
    """The prefix scan's steps ``(P^T)^(2^k)``, ``k < count``, up to the first below :data:`NEGLIGIBLE`: the same for every
    call of :func:`_run` on that many blocks, which formed them anew each time (9-10 products and maxima, 10 s at 1 kHz)."""
    out: list[np.ndarray] = []
    step = _blocks(A_key, B_key, C_key, D, m, L).P.T.copy()
    while len(out) < count and np.max(np.abs(step)) > NEGLIGIBLE:
        out.append(step)
        step = step @ step
    return tuple(out)


BLAS_ONE_THREAD = 1 << 18
"""Products of ``m x k`` by ``k x n`` are cut into row chunks with ``m k n`` below this: OpenBLAS then uses one thread
(its threads cost several times the CPU time on these skinny products and compete with :func:`_in_threads`)."""


def _product(a: np.ndarray, b: np.ndarray, out: np.ndarray, *, add: bool = False) -> None:
    """``out = a @ b`` (or ``out += a @ b``) in chunks along ``a``'s second-last axis (:data:`BLAS_ONE_THREAD`), from the last.

    ``out`` may be ``a`` itself: each chunk's product is formed before it is stored. The chunks do not depend on ``a``'s
    leading axes, so a row's result does not depend on the rows filtered with it.
    """
    step = max(1, BLAS_ONE_THREAD // (b.shape[0] * b.shape[1]))
    for i in range(((a.shape[-2] - 1) // step) * step, -1, -step):
        if add:
            out[..., i : i + step, :] += a[..., i : i + step, :] @ b
        else:
            out[..., i : i + step, :] = a[..., i : i + step, :] @ b


CHUNK = 1 << 16
"""Samples a row handled at once by the in-place FIR and reversal (bounded temporaries)."""


def _fir_in_place(x: np.ndarray, fir: np.ndarray) -> None:
    """Rows ``x`` (R, n) replaced by their convolution with ``fir`` from a zero history, chunk by chunk from the end."""
    n, k = x.shape[1], len(fir) - 1
    for row in x:
        for s in range(((n - 1) // CHUNK) * CHUNK, -1, -CHUNK):
            e = min(s + CHUNK, n)
            # outputs s..e-1 need inputs s-k..e-1, none of them overwritten yet
            row[s:e] = np.convolve(row[s - k : e], fir, mode="valid") if s >= k else np.convolve(row[:e], fir)[s:e]


def _reverse_in_place(x: np.ndarray) -> None:
    """Reverse rows ``x`` (R, n) in place, swapping chunks from both ends (bounded temporaries)."""
    n = x.shape[1]
    for i in range(0, n // 2, CHUNK):
        c = min(CHUNK, n // 2 - i)
        head = x[:, i : i + c].copy()
        x[:, i : i + c] = x[:, n - i - c : n - i][:, ::-1]
        x[:, n - i - c : n - i] = head[:, ::-1]


def _run(system: System, x: np.ndarray) -> None:
    """Zero-state output of ``system`` for rows ``x`` (R, n, contiguous), written over ``x``: the FIR numerator, then
    ``z' = A z + B u``, ``y = C z + D u``.

    Blocks of :data:`BLOCK` samples: within a block the zero-state response is ``T`` times the block and the state after it
    ``G^T u``; the state at every block's start is the prefix sum ``sum_j P^(k-1-j) G^T u_j``, computed by doubling (``log2``
    of the blocks' count matrix products, all blocks at once); each block's output adds ``Obs^T`` times its start state.
    """
    fir, A, B, C, D, _ = system
    rows, n = x.shape
    if fir is not None:
        _fir_in_place(x, fir)
    m = len(B)
    if m == 0:  # no recursion: a pure FIR (or gain)
        x *= D
        return
    L = min(BLOCK, n)
    key = (A.tobytes(), B.tobytes(), C.tobytes(), float(D), m, L)
    s = _blocks(*key)
    nb, tail = divmod(n, L)
    full = x[:, : nb * L].reshape(rows, nb, L)
    # states at the blocks' starts, (row, block, state); block 0 starts at rest
    start = np.zeros((rows, nb + 1, m))
    _product(full, s.G, start[:, 1:])
    for k, step in enumerate(_doublings(*key, max(nb - 1, 0).bit_length())):  # the d = 2^k below nb
        # start[k] += P^d start[k - d]; chunks from the last, so every source chunk is read before it is updated
        d = 1 << k
        _product(start[:, 1 : nb + 1 - d], step, start[:, d + 1 :], add=True)
    if tail:
        # (rows, 1, tail): one product per row, as for the full blocks
        x[:, None, nb * L :] = x[:, None, nb * L :] @ s.TT[:tail, :tail] + start[:, nb : nb + 1] @ s.Obs[:, :tail]
    # each block's output over its input
    _product(full, s.TT, full)
    _product(start[:, :nb], s.Obs, full, add=True)


PARALLEL_MIN_SIZE = 200_000
"""Arrays at least this large are filtered in threads (NumPy's matrix products release the GIL)."""


CHUNK_ELEMENTS = 1 << 21
"""Rows of a 2-D or larger array are filtered in blocks of about this many samples (16 MB)."""


def _in_threads(func: Callable[[np.ndarray], np.ndarray], x: np.ndarray, axis: int, keep: np.ndarray | None = None) -> np.ndarray:
    """Apply ``func`` (a filter along the last axis) to ``x`` along ``axis``.

    The rows along the filtered axis are filtered in contiguous blocks of about :data:`CHUNK_ELEMENTS` samples (in threads
    when the array is large), so the filter's temporaries stay bounded whatever the length of the log. ``keep`` (indices
    along the filtered axis) decimates each block as soon as it is filtered, so the full-rate output is never held. The
    result is identical to filtering the whole array at once.
    """
    moved = np.moveaxis(np.asarray(x, dtype=np.float64), axis, -1)

    def run(block: np.ndarray) -> np.ndarray:
        y = func(block)
        return y if keep is None else np.take(y, keep, axis=-1)

    if moved.ndim < 2:
        return run(moved)
    # blocks along the first axis: views, copied one block at a time by func
    per_row = int(np.prod(moved.shape[1:]))
    rows = max(1, CHUNK_ELEMENTS // max(per_row, 1))
    blocks = [moved[i : i + rows] for i in range(0, moved.shape[0], rows)]
    # at most 8 threads; rows longer than a block: one at a time, memory over speed (in a worker of ordered_map: in that thread)
    workers = 1 if per_row > CHUNK_ELEMENTS or moved.size < PARALLEL_MIN_SIZE else 8
    parts = ordered_map(run, blocks, most=workers)
    return np.moveaxis(np.concatenate(parts, axis=0), -1, axis)


def _df2t(b: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """State-space ``(A, B, C, D)`` of ``b/a`` in direct form II transposed (the state ``zi`` of ``scipy.signal.lfilter``)."""
    b, a = np.asarray(b, dtype=np.float64), np.asarray(a, dtype=np.float64)
    b, a = b / a[0], a / a[0]
    n = max(len(a), len(b))
    b, a = np.pad(b, (0, n - len(b))), np.pad(a, (0, n - len(a)))
    A = np.eye(n - 1, k=1)
    A[:, 0] = -a[1:]
    C = np.zeros(n - 1)
    C[:1] = 1.0
    return A, b[1:] - a[1:] * b[0], C, float(b[0])


System = tuple[np.ndarray | None, np.ndarray, np.ndarray, np.ndarray, float, float]
"""``(fir, A, B, C, D, gain)``: an FIR numerator (or ``None``), then a state-space filter; the DC gain of the whole."""


def _cascade(sections: list[tuple[np.ndarray, np.ndarray]]) -> System:
    """State-space of the filters ``b_i/a_i`` in series (each in direct form II transposed) and its DC gain."""
    parts = [_df2t(b, a) for b, a in sections]
    m = sum(len(p[1]) for p in parts)
    A, B, C = np.zeros((m, m)), np.zeros(m), np.zeros(m)
    D, gain, start = 1.0, 1.0, 0
    for (Ai, Bi, Ci, Di), (b, a) in zip(parts, sections, strict=True):
        k = slice(start, start + len(Bi))
        # each filter is fed by the output of those before it, C z + D u
        A[k, :start] = np.outer(Bi, C[:start])
        A[k, k] = Ai
        B[k] = Bi * D
        C[:start] *= Di
        C[k] = Ci
        D *= Di
        gain *= math.fsum(b) / math.fsum(a)  # exactly rounded sums: a low-pass's a(1) is a small difference of large terms
        start = k.stop
    return None, A, B, C, D, gain


def _polished_roots(a: np.ndarray, steps: int = 3) -> np.ndarray:
    """Roots of ``a`` refined by Newton steps in extended precision (their conjugate pairs exact, real ones real).

    ``np.roots`` is backward stable only: a low-pass's clustered poles come out about 1e-9 off, which moves the output by 1e-7.
    """
    roots = np.roots(a)
    roots = np.where(abs(roots.imag) <= 1e-12 * abs(roots), roots.real, roots).astype(np.clongdouble)
    coef = np.asarray(a, dtype=np.longdouble)
    for _ in range(steps):
        value, slope = np.zeros_like(roots), np.zeros_like(roots)
        for c in coef:  # Horner: the polynomial and its derivative
            slope = slope * roots + value
            value = value * roots + c
        roots = roots - np.where(slope != 0, value / np.where(slope != 0, slope, 1), 0)
    return roots


def _tf_system(b: np.ndarray, a: np.ndarray) -> System:
    """``b/a`` as :func:`_tf_sections` (cached by the coefficients' bytes: diagnosis filters with the same few designs hundreds of times)."""
    b, a = np.asarray(b, dtype=np.float64), np.asarray(a, dtype=np.float64)
    return _tf_sections(b.tobytes(), a.tobytes())


@functools.lru_cache(maxsize=64)
def _tf_sections(b_key: bytes, a_key: bytes) -> System:
    """``b/a`` as the FIR ``b`` followed by first- and second-order all-pole sections of the roots of ``a``.

    The same transfer function as the direct form, without its ill-conditioned recursion (an 8th-order low-pass's
    denominator amplifies rounding by 1e9).
    """
    b, a = np.frombuffer(b_key), np.frombuffer(a_key)
    b, a = b / a[0], a / a[0]
    if 1 < len(a) <= 3:  # one section already: no roots needed
        _, A, B, C, D, _ = _cascade([(np.ones(1), a)])
        return b, A, B, C, D, math.fsum(b) / math.fsum(a)
    poles = _polished_roots(a)
    pairs = poles[poles.imag > 0]
    real = np.sort(poles[poles.imag == 0].real)
    sections = [(np.ones(1), np.array([1.0, -2.0 * p.real, p.real**2 + p.imag**2], dtype=np.float64)) for p in pairs]
    sections += [(np.ones(1), np.poly(real[i : i + 2]).astype(np.float64)) for i in range(0, len(real), 2)]
    _, A, B, C, D, _ = _cascade(sections)
    return b, A, B, C, D, math.fsum(b) / math.fsum(a)


def _odd_extension(x: np.ndarray, n: int) -> np.ndarray:
    """Rows ``x`` extended by ``n`` samples at both ends by odd reflection (``scipy.signal`` ``odd_ext``); always a new array."""
    if n == 0:
        return np.array(x, dtype=np.float64, order="C")
    return np.concatenate([2 * x[:, :1] - x[:, n:0:-1], x, 2 * x[:, -1:] - x[:, -2 : -(n + 2) : -1]], axis=1)


def _steady_start(system: System, x: np.ndarray) -> None:
    """Rows ``x`` filtered in place from the steady state of their first sample: ``gain x0`` plus the zero-state response to ``x - x0``."""
    x0 = x[:, :1].copy()
    x -= x0
    _run(system, x)
    x += system[-1] * x0


def _forward_backward(system: System, x: np.ndarray, padlen: int) -> np.ndarray:
    """Rows ``x`` (R, n) filtered forward then backward, odd-padded, each pass from the steady state of its first sample.

    ``scipy.signal.filtfilt`` (``method="pad"``) and ``scipy.signal.sosfiltfilt``.
    One padded copy of ``x`` is filtered in place (a view of it is returned).
    """
    if x.shape[-1] <= padlen:
        raise ValueError(f"The length of the input vector x must be greater than padlen, which is {padlen}.")
    y = _odd_extension(x, padlen)
    _steady_start(system, y)
    _reverse_in_place(y)
    _steady_start(system, y)
    _reverse_in_place(y)
    return y[:, padlen : y.shape[1] - padlen]


def _rows(x: np.ndarray) -> np.ndarray:
    """``x`` (any shape, filtered along the last axis) as float rows (R, n)."""
    return np.asarray(x, dtype=np.float64).reshape(-1, x.shape[-1])


def _filtfilt_rows(system: System, padlen: int) -> Callable[[np.ndarray], np.ndarray]:
    """Forward-backward filtering of ``system`` along the last axis of a block, padded by ``padlen``."""
    return lambda c: _forward_backward(system, _rows(c), padlen).reshape(c.shape[:-1] + (-1,))


def _sos_padlen(sos: np.ndarray) -> int:
    """SciPy's default padding of ``sosfiltfilt``: ``3 * (2 * sections + 1)``, less the trivial taps."""
    return 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))


def filtfilt_matlab(b: np.ndarray, a: np.ndarray, x: np.ndarray, axis: int = 0, keep: np.ndarray | None = None) -> np.ndarray:
    """Zero-phase filtering as MATLAB ``filtfilt`` (odd padding of 3*(order) samples).

    ``keep``: indices along ``axis`` to return (decimation while filtering).
    """
    padlen = 3 * (max(len(a), len(b)) - 1)
    return _in_threads(_filtfilt_rows(_tf_system(b, a), padlen), x, axis, keep)


def _sos_system(sos: np.ndarray) -> System:
    """Second-order sections in series as one state-space filter (cached by the sections' bytes)."""
    return _sos_sections(np.asarray(sos, dtype=np.float64).tobytes())


@functools.lru_cache(maxsize=64)
def _sos_sections(key: bytes) -> System:
    """:func:`_sos_system` of the sections stored in ``key``."""
    return _cascade([(row[:3], row[3:]) for row in np.frombuffer(key).reshape(-1, 6)])


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
    wn = cutoff_hz / (fs_hz / 2.0)
    if not 0.0 < wn < 1.0:
        raise ValueError(f"cut-off {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2} Hz")
    if matlab:
        return filtfilt_matlab(*butter_ba(order, wn), x, axis=axis)
    sos = butter_sos(order, wn)
    return _in_threads(_filtfilt_rows(_sos_system(sos), _sos_padlen(sos)), x, axis)


def decimation_factor(fs_hz: float, cutoff_hz: float) -> int:
    """Decimation factor whose anti-alias cut-off ``0.8*fs/(2r)`` is ``cutoff_hz``.

    The benchmark uses ``round(0.8*500/40) = 10`` at 1 kHz.
    """
    return max(1, int(round(0.8 * (fs_hz / 2.0) / cutoff_hz)))


ROWS_BAND_HZ = 40.0
"""The widest band IDIM-LS's decimated rows keep (Hz): the benchmark's, ``round(0.8·500/40) = 10`` at 1 kHz (twice the
20 Hz loop bandwidth). Above 1 kHz the rows keep it (a factor fixed at 10 kept 80 Hz at 2 kHz, 320 Hz at 8 kHz: more of the
regressor's noise, and the robot corpus's identify at 8 kHz was 2.1-2.9 % off in Fc, now within 1.3 %)."""

ROWS_BAND_OF_FS = 0.04
"""... and with the benchmark's central differences never more than this share of the rate (its 40 Hz of 1 kHz), where
their gain at the band's edge is 0.99 (velocity) and 0.979 (acceleration) at every rate: 1 kHz and up."""

FIVE_POINT_BAND_OF_FS = 1.0 / 15.0
"""Below 1 kHz, where 40 Hz is more than :data:`ROWS_BAND_OF_FS` of the rate, the derivatives are five-point stencils
(:func:`ilic_cli.derivatives.derivative`; gains at this share 0.9990 and 0.9980) and the rows keep ``min(40 Hz, fs/15)``:
a decimation by 6 below 600 Hz, whose divisors let the search at the log's rate run on every second or third sample.
Measured with ``identify --method ls`` on fresh draws of the robot corpus's clean dwell-and-move logs (four axes, S-curves
and trapezoids), within 2 % of M, Fv and Fc, central differences keeping 0.04·fs against this, on the same seeds: 250 Hz
with sensor noise 24-28/40 against 31/32, with a 700 Hz current loop 26/32 against 21/32 (its lag), with a 10 Hz force
disturbance 12/32 against 18/32; 500 Hz 39/40, 36/40, 10/40 against 40/40, 36/40, 14/40. At 250 Hz the 10 Hz rows cut
through the breakaways (the S-curves' 80-150 ms ramps): Fv and Fc spread ±1.5 % with no noise at all. Five points keeping
0.04·fs lean Fv +2.8 %; keeping 0.08·fs widens the current loop's lag into Fv −1.5 % at 250 Hz (20/32 within). On chirps
and multisines at 250 Hz, which reverse often and never dwell, neither rule is within 2 % on more than 56 of 96 logs (this
one 47; M's median error halved, Fv's 1.9 % against 1.4 %: docs/methods.md)."""


def rows_stencil(fs_hz: float, band_hz: float = ROWS_BAND_HZ) -> int:
    """The derivative's stencil for rows keeping ``band_hz`` at ``fs_hz``: 3 (central differences, the benchmark's) where
    ``band_hz`` is at most :data:`ROWS_BAND_OF_FS` of the rate, else 5 (:data:`FIVE_POINT_BAND_OF_FS`)."""
    return 3 if band_hz <= ROWS_BAND_OF_FS * fs_hz * (1.0 + 1e-12) else 5


def rows_decimation(fs_hz: float, band_hz: float = ROWS_BAND_HZ) -> int:
    """IDIM-LS's decimation at ``fs_hz``: its anti-alias cut-off at ``band_hz`` where the rate allows, else at
    :data:`FIVE_POINT_BAND_OF_FS` of the rate (:func:`rows_stencil`; :data:`ROWS_BAND_HZ`).

    10 at 1 kHz (the benchmark's), 20 at 2 kHz, 40 at 4 kHz, 80 at 8 kHz; 6 below 600 Hz.
    """
    share = ROWS_BAND_OF_FS if rows_stencil(fs_hz, band_hz) == 3 else FIVE_POINT_BAND_OF_FS
    return decimation_factor(fs_hz, min(band_hz, share * fs_hz))


def decimated_band_hz(fs_hz: float, r: int) -> float:
    """The band a decimation by ``r`` keeps at ``fs_hz`` (Hz): its anti-alias cut-off ``0.8·(fs/2)/r`` (the inverse of :func:`decimation_factor`)."""
    return 0.8 * fs_hz / 2.0 / r


def rows_band_hz(fs_hz: float) -> float:
    """The band IDIM-LS's decimated rows keep at ``fs_hz`` (Hz): :func:`decimated_band_hz` of :func:`rows_decimation`."""
    return decimated_band_hz(fs_hz, rows_decimation(fs_hz))


DECIMATION_RULE = (
    f"rows decimated by round(0.8·(fs/2)/band): they keep {ROWS_BAND_HZ:g} Hz from 1 kHz up (the benchmark's 10 at 1 kHz, "
    f"central differences); below, where {ROWS_BAND_HZ:g} Hz is more than {ROWS_BAND_OF_FS:g}·fs, the derivatives are five-point "
    f"stencils and the rows keep min({ROWS_BAND_HZ:g} Hz, fs/{1.0 / FIVE_POINT_BAND_OF_FS:g})"
)
"""The decimation rule, in words (the reports state it)."""


def kept_indices(n: int, r: int) -> np.ndarray:
    """Indices kept by end-aligned decimation of ``n`` samples by ``r`` (MATLAB ``decimate``)."""
    nout = math.ceil(n / r)
    return np.arange(r - (r * nout - n) - 1, n, r)


MATLAB_DECIMATE_MAX = 13
"""The largest factor MATLAB's ``decimate`` is documented for in one stage; beyond it :func:`decimate_matlab` realises its
filter from the poles and zeros.

The transfer function's coefficients of an order-8 Chebyshev low-pass at ``0.8/r`` of Nyquist lose the design as ``r``
grows: its poles cluster at ``z = 1`` and rounding the expanded polynomial moves them. The DC gain of the rounded filter,
0.99426 by design, is 0.99426 up to r = 20, 0.99493 at r = 40, 0.922 at r = 80 (an 8 kHz log's rows) and -3.4 at r = 100.
MATLAB's ``decimate`` then lowers the order until the response at the cut-off is within 1e-6 dB of the design (with these
coefficients, order 6 at r = 80, 4 at r = 100) and recommends decimating in stages. Here the order-8 design is kept and realised in second-order
sections, as SciPy's ``cheby1(..., output="sos")``, with MATLAB's padding. Measured on the robot corpus's 8 kHz log
s3931 (sensor noise only, the controller's answer to it 2.5 N·m RMS in the force): the rows' force came out 0.29 N·m
high on average (the rounded filter passed part of that answer), the rigid replay's held-out force error was 10.3 %
and a concealed asymmetric friction, fitted within 1 %, was rejected by the replay. At r <= 13 the transfer function's
rounding is below 1e-7 dB at the cut-off and MATLAB's form is kept (the published digits).
"""


def decimate_matlab(x: np.ndarray, r: int, axis: int = 0) -> np.ndarray:
    """Parallel decimation as MATLAB ``decimate(x, r)`` (IIR mode).

    Chebyshev type I low-pass, order 8, 0.05 dB ripple, cut-off 0.8/r of
    Nyquist, applied forward-backward; keeps one sample in ``r`` aligned on the
    end of the record (first kept sample, 1-based: ``r - (r*nout - nd)``).
    Applied column-wise to a 2-D array, this is the parallel decimation of
    the observation matrix (paper section III). Above :data:`MATLAB_DECIMATE_MAX`
    the same filter in second-order sections.
    """
    if r == 1:
        return np.asarray(x)
    x = np.asarray(x)
    if r > MATLAB_DECIMATE_MAX:
        sos = cheby1_sos(8, 0.05, 0.8 / r)
        return _in_threads(_filtfilt_rows(_sos_system(sos), 3 * 8), x, axis, kept_indices(x.shape[axis], r))
    b, a = cheby1_ba(8, 0.05, 0.8 / r)
    return filtfilt_matlab(b, a, x, axis=axis, keep=kept_indices(x.shape[axis], r))


def lowpass_decimate(x: np.ndarray, r: int, cutoff_hz: float, fs_hz: float, order: int = 4, axis: int = -1) -> np.ndarray:
    """Zero-phase Butterworth low-pass (second-order sections) then keep one sample in ``r``.

    Used for the force and the reference regressor of IDIM-ILIC windows
    (paper eq. 24: "filtering and down-sampling"); stable at the very low
    cut-offs (5 Hz at 1 kHz) where the transfer-function form is not. Kept
    samples are aligned on the end of the record, as :func:`decimate_matlab`.
    """
    sos = butter_sos(order, cutoff_hz / (fs_hz / 2.0))
    n = x.shape[axis]
    return _in_threads(_filtfilt_rows(_sos_system(sos), min(n - 1, 3 * (2 * len(sos) + 1))), x, axis, kept_indices(n, r))


def bilinear_lfilter(b_s: list[float], a_s: list[float], fs_hz: float, x: np.ndarray) -> np.ndarray:
    """Apply the continuous filter ``B(s)/A(s)`` to ``x`` forward only (bilinear transform, causal).

    The filter starts in the steady state of ``x[0]`` (no start-up transient).
    ``s`` is replaced by ``2 fs (z - 1)/(z + 1)`` (``scipy.signal.bilinear``).
    """
    y = np.array(x, dtype=np.float64).reshape(1, -1)
    _steady_start(_tf_system(*bilinear_ba(tuple(b_s), tuple(a_s), float(fs_hz))), y)
    return y.reshape(np.shape(x))
