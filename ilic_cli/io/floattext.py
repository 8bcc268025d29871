"""The shortest text of float64 values, compiled (numba): byte for byte Python's ``repr(float(x))``.

Digits: Schubfach (R. Giulietti, "The Schubfach way to render doubles", 2020),
implemented from the paper's description. A finite ``v = c 2^q`` (``c`` the
significand with its hidden bit) reads back from every decimal in its
rounding interval ``R = [v - 2^(q-1), v + 2^(q-1)]`` (the lower half-width
``2^(q-2)`` at a power of two; the ends belong to ``R`` when ``c`` is even,
as a reader rounding half to even gives). With ``k = floor(log10(width of R))``
the interval holds at most one multiple of ``10^(k+1)`` and at least one of
``10^k``:

* a multiple of ``10^(k+1)`` in ``R`` is the shortest decimal;
* else ``s = floor(v / 10^k)`` or ``s + 1`` (times ``10^k``), the one in
  ``R``, or the nearer to ``v`` when both are (a tie: the even one).

Every comparison is of ``4 v / 10^k``, ``4 vl / 10^k``, ``4 vr / 10^k`` with
even integers; each is ``c' 2^q 10^-k`` rounded to odd (``floor | sticky``),
which compares with even integers exactly as the exact value does. It is the
top of the 64 x 126-bit product of ``c' 2^h`` and ``g = floor(10^-k
2^(125-f)) + 1`` (``f = floor(log2 10^-k)``), the sticky bit from the next 63
bits, which the paper proves exact; the products are done on 32-bit limbs.
When ``s < 100`` (a few of the smallest subnormals) the multiple of
``10^(k+1)`` may have as many digits as ``s`` (``10`` against ``9``), so the
integers near ``s`` are tried one by one instead.

Layout: ``repr``'s (``format(x, 'r')`` with ``Py_DTSF_ADD_DOT_0``): with
``d.ddd x 10^e``, positional when ``-4 <= e < 16`` (``.0`` after an
integer), else ``d.ddde+XX`` (no ``.`` for one digit, a signed exponent of at
least two digits); ``nan`` (whatever its sign), ``inf``, ``-inf``, ``0.0``,
``-0.0``.

:func:`csv_rows` lays out rows of columns as CSV text (``,`` between values,
``\\n`` after a row) straight into a byte buffer. Importing this module
imports numba: only the CSV writer's path does.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ilic_cli.jit import njit

Q_MIN = -1074
"""The binary exponent of the subnormals (``v = c 2^Q_MIN``)."""

Q_MAX = 2046 - 1075
"""The largest binary exponent of a finite float64 (``2^52 <= c < 2^53``)."""

K_MIN = -324
"""``floor(log10(2^Q_MIN))``: the smallest decimal exponent ``k``."""

K_MAX = 292
"""``floor(log10(2^Q_MAX))``: the largest decimal exponent ``k``."""

MAX_TEXT = 24
"""Bytes of the longest text (``-2.2250738585072014e-308``)."""

_U = np.uint64
_ONE = _U(1)
_TWO = _U(2)
_FOUR = _U(4)
_TEN = _U(10)
_HUNDRED = _U(100)
_ZERO = _U(0)
_M32 = _U(0xFFFFFFFF)
_M63 = _U((1 << 63) - 1)
_S32 = _U(32)
_S63 = _U(63)
_S52 = _U(52)
_FRAC = _U((1 << 52) - 1)
_HIDDEN = _U(1 << 52)
_EXP_MASK = _U(0x7FF)
_SIGN = _U(1 << 63)
_D0 = _U(48)
_E8 = _U(10**8)


@lru_cache(maxsize=1)
def tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The constants of the digit search, computed once with exact integers.

    Returns
    -------
    g1, g0 : (K_MAX - K_MIN + 1,) uint64
        ``g = g1 2^63 + g0 = floor(10^-k 2^(125-f)) + 1`` for ``k = K_MIN + i``,
        ``f = floor(log2(10^-k))``: ``2^125 < g < 2^126``.
    f : (K_MAX - K_MIN + 1,) int64
        ``floor(log2(10^-k))``.
    k_regular, k_irregular : (Q_MAX - Q_MIN + 1,) int64
        ``floor(log10(2^q))`` and ``floor(log10(3/4 2^q))`` for ``q = Q_MIN + i``.
    """
    ks = range(K_MIN, K_MAX + 1)
    g1 = np.empty(len(ks), dtype=np.uint64)
    g0 = np.empty(len(ks), dtype=np.uint64)
    f = np.empty(len(ks), dtype=np.int64)
    for i, k in enumerate(ks):
        if k <= 0:
            n = 10**-k
            fk = n.bit_length() - 1
            g = (n << (125 - fk) if fk <= 125 else n >> (fk - 125)) + 1
        else:
            d = 10**k  # not a power of two: 2^(b-1) < d < 2^b, floor(log2(1/d)) = -b
            fk = -d.bit_length()
            g = (1 << (125 - fk)) // d + 1
        g1[i], g0[i], f[i] = g >> 63, g & ((1 << 63) - 1), fk
    q = np.arange(Q_MIN, Q_MAX + 1, dtype=np.float64)
    # floor in float64 is exact here: q log10(2) is never within 1e-6 of an integer for these q (tested with integers)
    k_regular = np.floor(q * np.log10(2.0)).astype(np.int64)
    k_irregular = np.floor(q * np.log10(2.0) + np.log10(0.75)).astype(np.int64)
    return g1, g0, f, k_regular, k_irregular


@njit(cache=True, nogil=True, inline="always")
def _mulhi(a: np.uint64, b: np.uint64) -> np.uint64:
    """``floor(a b / 2^64)`` on 32-bit limbs."""
    a0 = a & _M32
    a1 = a >> _S32
    b0 = b & _M32
    b1 = b >> _S32
    p00 = a0 * b0
    p01 = a0 * b1
    p10 = a1 * b0
    mid = (p00 >> _S32) + (p01 & _M32) + (p10 & _M32)
    return a1 * b1 + (p01 >> _S32) + (p10 >> _S32) + (mid >> _S32)


@njit(cache=True, nogil=True, inline="always")
def _rop(g1: np.uint64, g0: np.uint64, cp: np.uint64) -> np.uint64:
    """``floor(g cp / 2^127)``, its lowest bit set when the next 63 bits are not all zero (round to odd)."""
    x1 = _mulhi(g0, cp)
    y0 = g1 * cp
    y1 = _mulhi(g1, cp)
    z = (y0 >> _ONE) + x1
    top = y1 + (z >> _S63)
    if (z & _M63) != _ZERO:
        top |= _ONE
    return top


@njit(cache=True, nogil=True, inline="always")
def _digit_count(d: np.uint64) -> int:
    """Decimal digits of ``d`` (< 10^19)."""
    n = 1
    if d >= _E8:
        n = 9
        d //= _E8
    p = _TEN
    while d >= p and n < 19:
        p *= _TEN
        n += 1
    return n


@njit(cache=True, nogil=True, inline="always")
def _put_digits(d: np.uint64, out: np.ndarray, end: int) -> None:
    """The decimal digits of ``d`` (> 0) into ``out`` ending before ``end``."""
    p = end
    while d >= _HUNDRED:
        r = d % _HUNDRED
        d //= _HUNDRED
        out[p - 1] = _D0 + r % _TEN
        out[p - 2] = _D0 + r // _TEN
        p -= 2
    if d >= _TEN:
        out[p - 1] = _D0 + d % _TEN
        out[p - 2] = _D0 + d // _TEN
    else:
        out[p - 1] = _D0 + d


@njit(cache=True, nogil=True, inline="always")
def _shortest_small(s: np.uint64, vb: np.uint64, vbl: np.uint64, vbr: np.uint64, out_: np.uint64) -> np.uint64:
    """The shortest, then nearest, integer ``n`` with ``4n`` in the rounding interval, tried one by one around ``s`` (< 100)."""
    best = _ZERO
    best_len = 99
    lo = s - _TEN if s > _TEN else _ONE
    n = lo
    while n <= s + _TEN:
        if vbl + out_ <= n << _TWO and (n << _TWO) + out_ <= vbr:
            m = n
            while m % _TEN == _ZERO:
                m //= _TEN
            length = _digit_count(m)
            if best == _ZERO or length < best_len:
                best, best_len = n, length
            elif length == best_len:
                mid = (n + best) << _ONE  # 4 (n + best) / 2: n > best, so n is nearer when v is above the midpoint
                if vb > mid or (vb == mid and (m & _ONE) == _ZERO):
                    best = n
        n += _ONE
    return best


@njit(cache=True, nogil=True, inline="always")
def _shortest(
    be: np.uint64, t: np.uint64, g1: np.ndarray, g0: np.ndarray, f: np.ndarray, k_regular: np.ndarray, k_irregular: np.ndarray
) -> tuple[np.uint64, int]:
    """The shortest, then nearest, decimal ``d 10^k`` that reads back as the positive finite float64 of biased exponent ``be`` and fraction ``t``."""
    if be != _ZERO:
        c = _HIDDEN | t
        q = int(be) - 1075
    else:
        c = t
        q = Q_MIN
    # the rounding interval's ends relative to 4c
    if t == _ZERO and be > _ONE:
        cbl = (c << _TWO) - _ONE
        k = k_irregular[q - Q_MIN]
    else:
        cbl = (c << _TWO) - _TWO
        k = k_regular[q - Q_MIN]
    cb = c << _TWO
    cbr = cb + _TWO
    h = _U(q + f[k - K_MIN] + 2)
    gh = g1[k - K_MIN]
    gl = g0[k - K_MIN]
    vb = _rop(gh, gl, cb << h)
    vbl = _rop(gh, gl, cbl << h)
    vbr = _rop(gh, gl, cbr << h)
    out_ = c & _ONE  # the ends are out of the interval when c is odd
    s = vb >> _TWO
    if s < _HUNDRED:
        d = _shortest_small(s, vb, vbl, vbr, out_)
    else:
        sp10 = (s // _TEN) * _TEN
        tp10 = sp10 + _TEN
        upin = vbl + out_ <= sp10 << _TWO
        wpin = (tp10 << _TWO) + out_ <= vbr
        if upin != wpin:
            d = sp10 if upin else tp10
        else:
            t1 = s + _ONE
            uin = vbl + out_ <= s << _TWO
            win = (t1 << _TWO) + out_ <= vbr
            if uin != win:
                d = s if uin else t1
            else:
                mid = (s + t1) << _ONE
                d = s if vb < mid or (vb == mid and (s & _ONE) == _ZERO) else t1
    return d, k


@njit(cache=True, nogil=True)
def put(bits: np.uint64, out: np.ndarray, pos: int, g1: np.ndarray, g0: np.ndarray, f: np.ndarray, k_regular: np.ndarray, k_irregular: np.ndarray) -> int:
    """``repr`` of the float64 whose bits are ``bits``, written into ``out`` at ``pos``; the position after it."""
    be = (bits >> _S52) & _EXP_MASK
    t = bits & _FRAC
    if be == _EXP_MASK:
        if t != _ZERO:
            out[pos] = 110  # nan
            out[pos + 1] = 97
            out[pos + 2] = 110
            return pos + 3
        if bits & _SIGN:
            out[pos] = 45
            pos += 1
        out[pos] = 105  # inf
        out[pos + 1] = 110
        out[pos + 2] = 102
        return pos + 3
    if bits & _SIGN:
        out[pos] = 45
        pos += 1
    if be == _ZERO and t == _ZERO:
        out[pos] = 48
        out[pos + 1] = 46
        out[pos + 2] = 48
        return pos + 3
    d, k = _shortest(be, t, g1, g0, f, k_regular, k_irregular)
    return _layout(d, k, out, pos)


@njit(cache=True, nogil=True, inline="always")
def _layout(d: np.uint64, k: int, out: np.ndarray, pos: int) -> int:
    """``repr``'s text of ``d 10^k`` (``d`` > 0) into ``out`` at ``pos``; the position after it."""
    # d 10^k, d > 0: strip its trailing zeros
    e10 = k
    while d % _TEN == _ZERO and d != _ZERO:  # d > 0 (a guard: a wrong d must not loop)
        d //= _TEN
        e10 += 1
    n = _digit_count(d)
    e = e10 + n - 1  # d.ddd x 10^e
    if -4 <= e < 16:
        if e < 0:
            out[pos] = 48
            out[pos + 1] = 46
            pos += 2
            for _ in range(-e - 1):
                out[pos] = 48
                pos += 1
            _put_digits(d, out, pos + n)
            return pos + n
        if e + 1 >= n:
            _put_digits(d, out, pos + n)
            pos += n
            for _ in range(e + 1 - n):
                out[pos] = 48
                pos += 1
            out[pos] = 46
            out[pos + 1] = 48
            return pos + 2
        # the digits one place right, then their first e + 1 one place left, before the point
        _put_digits(d, out, pos + n + 1)
        for i in range(pos, pos + e + 1):
            out[i] = out[i + 1]
        out[pos + e + 1] = 46
        return pos + n + 1
    if n == 1:
        out[pos] = _D0 + d
        pos += 1
    else:
        _put_digits(d, out, pos + n + 1)
        out[pos] = out[pos + 1]
        out[pos + 1] = 46
        pos += n + 1
    out[pos] = 101
    if e < 0:
        out[pos + 1] = 45
        e = -e
    else:
        out[pos + 1] = 43
    pos += 2
    if e >= 100:
        out[pos] = 48 + e // 100
        out[pos + 1] = 48 + (e // 10) % 10
        out[pos + 2] = 48 + e % 10
        return pos + 3
    out[pos] = 48 + e // 10
    out[pos + 1] = 48 + e % 10
    return pos + 2


@njit(cache=True, nogil=True)
def _texts(bits: np.ndarray, out: np.ndarray, ends: np.ndarray, g1: np.ndarray, g0: np.ndarray, f: np.ndarray, kr: np.ndarray, ki: np.ndarray) -> int:
    pos = np.int64(0)  # not the literal 0: put would compile a second time for it (3 s of CPU)
    for i in range(bits.shape[0]):
        pos = put(bits[i], out, pos, g1, g0, f, kr, ki)
        ends[i] = pos
    return int(pos)


def texts(values: np.ndarray) -> list[bytes]:
    """``repr`` of each value as bytes (for tests and measurements; the writer uses :func:`csv_rows`)."""
    bits = np.ascontiguousarray(values, dtype=np.float64).reshape(-1).view(np.uint64)
    out = np.empty(len(bits) * MAX_TEXT, dtype=np.uint8)
    ends = np.empty(len(bits), dtype=np.int64)
    _texts(bits, out, ends, *tables())
    raw = out.tobytes()
    starts = [0, *ends[:-1].tolist()]
    return [raw[a:b] for a, b in zip(starts, ends.tolist())]


@njit(cache=True, nogil=True)
def _rows(bits: np.ndarray, out: np.ndarray, g1: np.ndarray, g0: np.ndarray, f: np.ndarray, kr: np.ndarray, ki: np.ndarray) -> int:
    """Rows of ``bits`` (columns x rows) into ``out``; a value equal to the one above it in its column copies that one's text."""
    width = bits.shape[0]
    last_start = np.zeros(width, dtype=np.int64)
    last_len = np.full(width, -1, dtype=np.int64)
    pos = np.int64(0)  # not the literal 0: put would compile a second time for it (3 s of CPU)
    for i in range(bits.shape[1]):
        for j in range(width):
            b = bits[j, i]
            start = pos
            if last_len[j] >= 0 and bits[j, i - 1] == b:
                src = last_start[j]
                for m in range(last_len[j]):
                    out[pos + m] = out[src + m]
                pos += last_len[j]
            else:
                pos = put(b, out, pos, g1, g0, f, kr, ki)
            last_start[j] = start
            last_len[j] = pos - start
            out[pos] = 44 if j < width - 1 else 10
            pos += 1
    return int(pos)


def csv_rows(columns: list[np.ndarray], start: int, stop: int, buffer: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Rows ``start..stop-1`` of ``columns`` as CSV text: ``repr`` of every value, ``,`` between, ``\\n`` after.

    Parameters
    ----------
    columns : list of (N,) float64 arrays
        The columns, each at least ``stop`` long.
    start, stop : int
        The rows to lay out.
    buffer : (M,) uint8 array, optional
        Written into when large enough (``(stop - start) len(columns) (MAX_TEXT + 1)`` bytes), else a new one.

    Returns
    -------
    buffer : (M,) uint8 array
        The buffer written into.
    length : int
        The text's bytes: ``buffer[:length]``.
    """
    bits = np.stack([np.asarray(col[start:stop], dtype=np.float64).view(np.uint64) for col in columns])
    need = bits.size * (MAX_TEXT + 1)
    if buffer is None or len(buffer) < need:
        buffer = np.empty(need, dtype=np.uint8)
    return buffer, int(_rows(bits, buffer, *tables()))
