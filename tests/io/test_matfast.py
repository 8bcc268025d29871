"""The MAT level 5 reader and writer without ``scipy.io`` (:mod:`ilic_cli.io.matfast`) against ``scipy.io`` itself (issue 33)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from ilic_cli.io import WriteOptions, mat, matfast, read_log, write_log


def _scipy_variables(raw: bytes) -> dict[str, np.ndarray]:
    loaded = scipy.io.loadmat(io.BytesIO(raw), squeeze_me=False, chars_as_strings=True, struct_as_record=True)
    return {k: v for k, v in loaded.items() if not k.startswith("__")}


def _same(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return list(a) == list(b) and all(a[k].dtype == b[k].dtype and a[k].shape == b[k].shape and np.array_equal(a[k], b[k]) for k in b)


def _saved(variables: dict[str, object], compress: bool = True) -> bytes:
    buffer = io.BytesIO()
    scipy.io.savemat(buffer, variables, do_compression=compress, oned_as="column")
    return buffer.getvalue()


def test_emps_recordings_read_as_scipy_reads_them(emps_dir: Path) -> None:
    for name in ("DATA_EMPS.mat", "DATA_EMPS_PULSES.mat"):
        raw = (emps_dir / name).read_bytes()
        fast = matfast.load(raw, mat.MAX_DECLARED_BYTES)
        assert fast is not None and _same(fast, _scipy_variables(raw)), name  # pulses_N: stored as uint8, given as uint8


@pytest.mark.parametrize("compress", [True, False])
def test_numeric_types_and_text_read_as_scipy_reads_them(compress: bool) -> None:
    rng = np.random.default_rng(3)
    variables = {
        "x": rng.normal(size=(7, 1)),
        "row": rng.normal(size=(1, 5)),
        "m": rng.normal(size=(3, 4)),
        "f4": rng.normal(size=(6, 1)).astype(np.float32),
        "i2": rng.integers(-300, 300, size=(9, 1)).astype(np.int16),
        "u8": np.arange(3, dtype=np.uint8).reshape(3, 1),
        "s": np.array([[2.5]]),
        "text": np.array('{"a": 1}'),
    }
    raw = _saved(variables, compress)
    fast = matfast.load(raw, mat.MAX_DECLARED_BYTES)
    assert fast is not None and _same(fast, _scipy_variables(raw))


@pytest.mark.parametrize(
    "variable",
    [np.array([[1 + 2j]]), np.array([[True, False]]), {"field": np.array([[1.0]])}, np.array(["a", "bc"], dtype=object), np.array("")],
    ids=["complex", "logical", "struct", "cell", "empty text"],
)
def test_unusual_variables_are_left_to_scipy(variable: object) -> None:
    raw = _saved({"t": np.zeros((3, 1)), "v": variable})
    assert matfast.load(raw, mat.MAX_DECLARED_BYTES) is None


def test_damaged_or_oversized_streams_are_left_to_scipy() -> None:
    raw = bytearray(_saved({"t": np.arange(1000.0).reshape(-1, 1)}))
    assert matfast.load(bytes(raw), 8 * 1000) is not None
    assert matfast.load(bytes(raw), 8 * 999) is None  # more declared than allowed: scipy.io's path refuses it
    raw[-5] ^= 0xFF  # the zlib stream's check value
    assert matfast.load(bytes(raw), mat.MAX_DECLARED_BYTES) is None
    assert matfast.load(bytes(raw[:200]), mat.MAX_DECLARED_BYTES) is None  # truncated


def _inflated(raw: bytes) -> tuple[bytes, list[bytes], list[int]]:
    """A MAT file's header, each compressed variable's element inflated, and each zlib stream's level bits (FLEVEL)."""
    import struct
    import zlib

    elements, levels, pos = [], [], 128
    while pos < len(raw):
        kind, size = struct.unpack_from("<II", raw, pos)
        assert kind == matfast.MI_COMPRESSED
        stream = raw[pos + 8 : pos + 8 + size]
        elements.append(zlib.decompress(stream))
        levels.append(stream[1] >> 6)
        pos += 8 + size
    return raw[:128], elements, levels


def test_written_bytes_are_scipys(tmp_path: Path, emps_dir: Path) -> None:
    """The threads' variables are ``scipy.io.savemat``'s once inflated (float64 and uint8 columns, scalars, JSON text), compressed at zlib level 1."""
    from tests.conftest import make_synthetic_log

    for log in (read_log(emps_dir / "DATA_EMPS_PULSES.mat"), make_synthetic_log(samples=5000)):
        fast = write_log(log, tmp_path / "fast.mat").read_bytes()
        variables = {k: v for k, v in _scipy_variables(fast).items()}
        variables = {k: (np.array(str(v.reshape(-1)[0])) if v.dtype.kind == "U" else v) for k, v in variables.items()}
        assert matfast.dump(variables, mat.HEADER_TEXT) is not None  # written by matfast, not scipy
        reference = bytearray(_saved(variables))
        reference[:116] = mat.HEADER_TEXT.ljust(116, b" ")
        head, elements, levels = _inflated(fast)
        ref_head, ref_elements, ref_levels = _inflated(bytes(reference))
        assert (head, elements) == (ref_head, ref_elements)
        assert set(levels) == {0} and set(ref_levels) == {2}  # zlib's FLEVEL: 0 for level 1 (fastest), 2 for scipy's 6 (default)
        assert write_log(log, tmp_path / "again.mat").read_bytes() == fast  # deterministic
        back = read_log(tmp_path / "fast.mat")
        assert all(np.array_equal(back.channels[k], log.channels[k]) for k in log.channels)


def test_unusual_channels_are_written_by_scipy(tmp_path: Path) -> None:
    """Non-ASCII metadata text goes through ``scipy.io``: the file reads back the same."""
    from tests.conftest import make_synthetic_log

    log = make_synthetic_log(samples=200)
    log.meta["note"] = "Δt"
    assert matfast.dump({"t": log.t.reshape(-1, 1), "ilic_meta": np.array("Δt")}, mat.HEADER_TEXT) is None
    path = write_log(log, tmp_path / "u.mat", options=WriteOptions())
    assert read_log(path).meta["note"] == "Δt"
