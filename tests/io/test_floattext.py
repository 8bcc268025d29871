"""The compiled float formatter (``ilic_cli/io/floattext.py``, issue 33) writes exactly Python's ``repr`` of every float64.

Each case compares the bytes of whole columns with ``repr``'s; the CSV writer's
compiled path is compared with its ``repr`` path (``fast=False``) byte for byte.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.io import WriteOptions, csvlog, floattext
from ilic_cli.runlog import RunLog


def _assert_repr(values: np.ndarray | list[float]) -> None:
    """The formatter's text of ``values`` (as CSV rows of one column) is ``repr``'s, byte for byte."""
    column = np.asarray(values, dtype=np.float64).reshape(-1)
    buffer, length = floattext.csv_rows([column], 0, len(column))
    got = buffer[:length].tobytes()
    want = ("\n".join(map(repr, column.tolist())) + "\n").encode()
    if got != want:
        pairs = [(w, g) for w, g in zip(want.split(b"\n"), got.split(b"\n")) if w != g]
        raise AssertionError(f"{len(pairs)} values differ from repr, e.g. (repr, ours): {pairs[:5]}")


def _neighbours(values: np.ndarray) -> np.ndarray:
    """``values`` and the float64 on either side of each."""
    values = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore"):  # the largest float's upper neighbour is inf
        return np.concatenate([values, np.nextafter(values, np.inf), np.nextafter(values, -np.inf)])


def test_special_values_and_zeros() -> None:
    nan_negative = struct.unpack("<d", struct.pack("<Q", 0xFFF8000000000000))[0]
    nan_payload = struct.unpack("<d", struct.pack("<Q", 0x7FF0000000000001))[0]
    values = [math.nan, nan_negative, nan_payload, math.inf, -math.inf, 0.0, -0.0]
    _assert_repr(values)
    buffer, length = floattext.csv_rows([np.array(values)], 0, len(values))
    assert buffer[:length].tobytes() == b"nan\nnan\nnan\ninf\n-inf\n0.0\n-0.0\n"


def test_subnormals_and_the_ends_of_the_range() -> None:
    tiny = 5e-324
    largest_subnormal = struct.unpack("<d", struct.pack("<Q", (1 << 52) - 1))[0]
    smallest_normal = 2.2250738585072014e-308
    largest = 1.7976931348623157e308
    ends = np.array([tiny, largest_subnormal, smallest_normal, largest])
    _assert_repr(_neighbours(ends))
    _assert_repr(-_neighbours(ends))
    _assert_repr(np.arange(1, 5000) * tiny)  # the smallest subnormals: their integers near s are tried one by one
    _assert_repr(np.arange(1, 4096, dtype=np.uint64).view(np.float64)[::-1])


def test_powers_of_two_and_ten_over_the_whole_range() -> None:
    twos = np.ldexp(1.0, np.arange(-1074, 1024))
    _assert_repr(_neighbours(twos))  # 2^q: the irregular interval (its lower half-width a quarter of the spacing)
    _assert_repr(-_neighbours(twos))
    tens = np.array([float(f"1e{e}") for e in range(-323, 309)])
    _assert_repr(_neighbours(tens))
    _assert_repr(np.array([float(f"{d}e{e}") for d in range(1, 10) for e in range(-320, 308, 7)]))


def test_the_switch_between_positional_and_scientific() -> None:
    around = [1e-5, 0.0001, 0.001, 9.999999999999999e-05, 1e15, 9.999999999999999e15, 1e16, 1e17, 1.5e16, 1.2345e15, 123456789012345.67]
    values = _neighbours(np.array(around))
    _assert_repr(values)
    _assert_repr(-values)
    assert floattext.texts(np.array([1e16, 9.999999999999998e15, 1e-5, 0.0001, 1e-4 * 0.5])) == [
        b"1e+16",
        b"9999999999999998.0",
        b"1e-05",
        b"0.0001",
        b"5e-05",
    ]


def test_integers() -> None:
    _assert_repr(np.arange(-20000, 20000, dtype=np.float64))
    big = np.array([2.0**53, 2.0**53 - 1, 2.0**53 + 2, 2.0**60, 2.0**63, 2.0**64, 10.0**22, 10.0**23, 2.0**1023])
    _assert_repr(_neighbours(big))
    _assert_repr(np.random.default_rng(5).integers(-(2**62), 2**62, size=100_000).astype(np.float64))


def test_exact_ties_go_to_the_even_digit() -> None:
    # 2^50 + j/4 (j odd) lies exactly half-way between two shortest decimals of one digit after the point
    values = 2.0**50 + np.arange(1, 4000, 2) / 4.0
    _assert_repr(values)
    assert floattext.texts(np.array([2.0**50 + 0.25, 2.0**50 + 0.75])) == [b"1125899906842624.2", b"1125899906842624.8"]


def test_decimal_patterns() -> None:
    k = np.arange(0, 100_000, dtype=np.float64)
    _assert_repr(k / 1000.0)
    _assert_repr(k * 0.001)
    _assert_repr(k * 1e-6)
    _assert_repr(k / 3.0)


@pytest.mark.parametrize("seed", range(4))
def test_random_bit_patterns(seed: int) -> None:
    bits = np.random.default_rng(33 + seed).integers(0, 2**64, size=250_000, dtype=np.uint64, endpoint=False)  # 1M in all
    _assert_repr(bits.view(np.float64))


@pytest.mark.parametrize("scale", [1e-300, 1e-20, 1e-6, 1.0, 1e4, 1e17, 1e300])
def test_random_normals_and_uniforms(scale: float) -> None:
    rng = np.random.default_rng(int(math.log10(scale)) + 400)
    _assert_repr(rng.standard_normal(100_000) * scale)
    _assert_repr(rng.uniform(0.0, 1.0, 50_000) * scale)


def test_the_tables_are_exact() -> None:
    g1, g0, f, k_regular, k_irregular = floattext.tables()
    for i, k in enumerate(range(floattext.K_MIN, floattext.K_MAX + 1)):
        g = (int(g1[i]) << 63) + int(g0[i])
        assert 2**125 < g < 2**126 and int(g0[i]) < 2**63
        # g - 1 = floor(10^-k 2^(125 - f)) and 2^f <= 10^-k < 2^(f + 1)
        if k <= 0:
            num, den = 10**-k, 1
        else:
            num, den = 1, 10**k
        fk = int(f[i])
        scaled_num, scaled_den = (num << (125 - fk), den) if fk <= 125 else (num, den << (fk - 125))
        assert g - 1 == scaled_num // scaled_den
        assert (num << max(0, -fk)) >= (den << max(0, fk)) and (num << max(0, -fk - 1)) < (den << max(0, fk + 1))
    for i, q in enumerate(range(floattext.Q_MIN, floattext.Q_MAX + 1)):
        for k, (num, den) in ((int(k_regular[i]), (1, 1)), (int(k_irregular[i]), (3, 4))):
            # 10^k <= num/den 2^q < 10^(k+1), all in integers
            lhs_num, lhs_den = num * 2 ** max(q, 0), den * 2 ** max(-q, 0)
            assert lhs_num * 10 ** max(-k, 0) >= lhs_den * 10 ** max(k, 0)
            assert lhs_num * 10 ** max(-k - 1, 0) < lhs_den * 10 ** max(k + 1, 0)


def test_csv_writer_is_the_repr_writer_byte_for_byte(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(7)
    n = 2500
    steps = np.repeat(rng.standard_normal(25), 100)  # runs of a repeated value, as the estimates
    signed_zeros = np.where(np.arange(n) % 3 == 0, 0.0, -0.0)  # equal as floats, written differently
    specials = np.array([math.nan, math.inf, -math.inf, 0.0, -0.0] * (n // 5))
    log = RunLog(
        {
            "t": np.arange(n) / 1000.0,
            "q": rng.standard_normal(n) * 1e-3,
            "hat": steps,
            "z": signed_zeros,
            "s": specials,
            "bits": rng.integers(0, 2**64, size=n, dtype=np.uint64, endpoint=False).view(np.float64),
        },
        {"t": "s", "q": "m"},
        {"sample_rate_hz": 1000.0},
    )
    monkeypatch.setattr(csvlog, "ROWS_PER_BLOCK", 1000)  # blocks that end inside the runs
    fast, slow = tmp_path / "fast.csv", tmp_path / "slow.csv"
    csvlog.write(log, fast, WriteOptions(fast=True))
    csvlog.write(log, slow, WriteOptions(fast=False))
    assert fast.read_bytes() == slow.read_bytes()
    assert fast.read_bytes().count(b"\n") == n + 3


def test_short_decimals_and_their_neighbours() -> None:
    # a decimal of few digits read as float64 prints as itself: the one-digit-shorter candidate's path, and its neighbours' near misses
    rng = np.random.default_rng(17)
    digits = rng.integers(1, 18, size=30_000).tolist()
    exponents = rng.integers(-340, 310, size=30_000).tolist()
    values = np.array([float(f"{int(rng.integers(10 ** (d - 1), 10**d))}e{e}") for d, e in zip(digits, exponents)])
    values = values[np.isfinite(values) & (values != 0.0)]
    _assert_repr(_neighbours(values))
