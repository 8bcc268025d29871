"""MAT level 5 files of plain columns, read and written without ``scipy.io``.

``scipy.io`` costs some 0.13 s to import (it brings ``scipy.sparse``): more
than ``ilic identify --method ls`` computes on DATA_EMPS.mat. The files
``ilic`` reads and writes are simple: compressed (or plain) variables, each a
real numeric matrix (double, single, integers) or a one-row char array. This
module reads those and gives what ``scipy.io.loadmat(..., squeeze_me=False,
chars_as_strings=True)`` gives for them (the same stored dtypes, shapes and values);
:func:`load` returns None for anything else (cell arrays, structs, sparse,
complex or logical arrays, big-endian files, version 7.3, a damaged stream),
and :mod:`ilic_cli.io.mat` then reads the file with ``scipy.io`` as before,
which reports what is wrong with it.

:func:`dump` writes the variables ``scipy.io.savemat(..., do_compression=True,
oned_as="column")`` writes for float64 and uint8 columns, scalars and ASCII
text -- each variable's element, once inflated, is scipy's byte for byte --
but compresses them at zlib level :data:`ZLIB_LEVEL`, not scipy's 6, in
threads (zlib releases the GIL); for anything else it returns None and the
caller uses ``scipy.io``.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from ilic_cli.parallel import ordered_map

MI_INT8, MI_UINT8, MI_INT16, MI_UINT16, MI_INT32, MI_UINT32 = 1, 2, 3, 4, 5, 6
MI_SINGLE, MI_DOUBLE, MI_INT64, MI_UINT64 = 7, 9, 12, 13
MI_MATRIX, MI_COMPRESSED, MI_UTF8 = 14, 15, 16

STORAGE = {
    MI_INT8: "<i1",
    MI_UINT8: "<u1",
    MI_INT16: "<i2",
    MI_UINT16: "<u2",
    MI_INT32: "<i4",
    MI_UINT32: "<u4",
    MI_SINGLE: "<f4",
    MI_DOUBLE: "<f8",
    MI_INT64: "<i8",
    MI_UINT64: "<u8",
}
"""Numeric data types of a data element -> NumPy dtype."""

MX_CHAR = 4
CLASSES = frozenset(range(6, 16))
"""Numeric array classes (double, single, integers): ``scipy.io`` returns their stored type."""

_TAG = struct.Struct("<II")

ZLIB_LEVEL = 1
"""zlib level of the written variables: a 300 s ``paper-sim`` log's 26.4 MB of columns take 0.31 s of CPU and 9.29 MB at level 1,
0.68 s and 9.10 MB at scipy's level 6 (2 % smaller for twice the time); any level inflates to the same bytes."""


class _Unusual(Exception):
    """Not a file this module reads: ``scipy.io`` reads it."""


def _element(buf: memoryview, pos: int, end: int) -> tuple[int, int, int, int]:
    """The data element at ``pos``: ``(type, data start, data stop, next element)``; small elements hold their data in the tag."""
    if pos + 8 > end:
        raise _Unusual
    first, second = _TAG.unpack_from(buf, pos)
    if first >> 16:  # small data element: type and size in the first word, data in the second
        size = first >> 16
        if size > 4:
            raise _Unusual
        return first & 0xFFFF, pos + 4, pos + 4 + size, pos + 8
    start = pos + 8
    stop = start + second
    if stop > end:
        raise _Unusual
    return first, start, stop, start + (-second % 8) + second


def _matrix(buf: memoryview, start: int, stop: int, budget: list[int]) -> tuple[str, np.ndarray]:
    """Name and array of the ``miMATRIX`` element whose data is ``buf[start:stop]``."""
    kind, a, b, pos = _element(buf, start, stop)
    if kind != MI_UINT32 or b - a != 8:
        raise _Unusual
    flags = _TAG.unpack_from(buf, a)[0]
    mclass = flags & 0xFF
    if flags & 0xFF00 or (mclass not in CLASSES and mclass != MX_CHAR):  # complex, global, logical, or another class
        raise _Unusual
    kind, a, b, pos = _element(buf, pos, stop)
    if kind != MI_INT32 or (b - a) % 4 or b - a < 8:
        raise _Unusual
    dims = tuple(int(d) for d in np.frombuffer(buf[a:b], dtype="<i4"))
    if min(dims) < 0:
        raise _Unusual
    count = 1
    for d in dims:
        count *= d
    budget[0] -= 8 * count
    if budget[0] < 0:  # the caller's limit of declared bytes: scipy.io's path refuses the file
        raise _Unusual
    kind, a, b, pos = _element(buf, pos, stop)
    if kind != MI_INT8:
        raise _Unusual
    name = bytes(buf[a:b]).decode("latin1")
    kind, a, b, pos = _element(buf, pos, stop)
    if pos < stop:
        raise _Unusual  # an imaginary part, or more
    if mclass == MX_CHAR:
        if kind != MI_UTF8 or len(dims) != 2 or dims[0] != 1 or dims[1] < 1:
            raise _Unusual
        text = bytes(buf[a:b]).decode("utf-8")
        if len(text) != dims[1]:
            raise _Unusual
        return name, np.array([text])
    dtype = STORAGE.get(kind)
    if dtype is None or (b - a) != count * np.dtype(dtype).itemsize:
        raise _Unusual
    # scipy.io (mat_dtype=False) gives the stored type, not the class; a copy: the file's buffer is let go
    values = np.frombuffer(buf[a:b], dtype=dtype).astype(np.dtype(dtype).newbyteorder("="))
    return name, values.reshape(dims, order="F")


def load(raw: bytes, max_declared: int) -> dict[str, np.ndarray] | None:
    """The variables of a MAT level 5 file's bytes, as ``scipy.io.loadmat`` gives them; None when this module does not read it.

    ``max_declared`` bounds ``8 x`` the elements the variables declare (as
    :func:`ilic_cli.io.mat._check_declared_sizes`); a compressed variable is
    decompressed to at most the size its header declares.
    """
    try:
        return _load(memoryview(raw), max_declared)
    except (_Unusual, zlib.error, UnicodeDecodeError, ValueError, struct.error):
        return None


def _load(buf: memoryview, max_declared: int) -> dict[str, np.ndarray]:
    if len(buf) < 128 or bytes(buf[124:128]) != b"\x00\x01IM" or bytes(buf[:6]) != b"MATLAB":
        raise _Unusual
    out: dict[str, np.ndarray] = {}
    budget = [max_declared]
    pos, end = 128, len(buf)
    while pos < end:
        kind, start, stop, pos = _element(buf, pos, end)
        if kind == MI_COMPRESSED:
            pos = stop  # compressed elements are not padded
            inner = zlib.decompressobj()
            head = inner.decompress(buf[start:stop], 8)
            if len(head) != 8:
                raise _Unusual
            mtype, size = _TAG.unpack(head)
            if mtype != MI_MATRIX or size > max_declared + 2**20:
                raise _Unusual
            body = inner.decompress(inner.unconsumed_tail, size + 1)
            if len(body) != size or not inner.eof or inner.unconsumed_tail or inner.unused_data:
                raise _Unusual  # scipy.io's verify_compressed_data_integrity: a whole, checked stream of the declared size
            name, value = _matrix(memoryview(body), 0, size, budget)
        elif kind == MI_MATRIX:
            name, value = _matrix(buf, start, stop, budget)
        else:
            raise _Unusual
        out[name] = value
    return out


# -- writing ------------------------------------------------------------------
def _tag(kind: int, data: bytes) -> bytes:
    """A data element as scipy writes it: small (data in the tag) up to 4 bytes, else padded to 8."""
    if len(data) <= 4:
        return struct.pack("<I", (len(data) << 16) + kind) + data.ljust(4, b"\0")
    return _TAG.pack(kind, len(data)) + data + b"\0" * (-len(data) % 8)


def _matrix_parts(name: str, value: np.ndarray) -> list[bytes | memoryview] | None:
    """The ``miMATRIX`` element of one variable in parts (the numbers as a view), or None when scipy must write it."""
    if not name or name[0] == "_":
        return None
    if value.dtype.kind == "U":
        if value.ndim != 0:
            return None
        text = str(value)
        if not text or not text.isascii():
            return None
        dims, mclass, kind, data = (1, len(text)), MX_CHAR, MI_UTF8, memoryview(text.encode("ascii"))
    elif value.dtype in (np.float64, np.uint8) and value.ndim == 2 and value.shape[1] == 1 and value.shape[0] >= 1:
        dims, mclass = value.shape, (6 if value.dtype == np.float64 else 9)
        kind = MI_DOUBLE if mclass == 6 else MI_UINT8
        flat = np.ascontiguousarray(value.reshape(-1).astype(value.dtype.newbyteorder("<"), copy=False))
        data = memoryview(flat).cast("B")  # type: ignore[arg-type]  # numpy's stubs give ndarray the buffer protocol only for Python >= 3.12
    else:
        return None
    head = _tag(MI_UINT32, struct.pack("<II", mclass, 0)) + _tag(MI_INT32, struct.pack("<2i", *dims)) + _tag(MI_INT8, name.encode("latin1"))
    size = len(data)
    parts: list[bytes | memoryview] = [head, _tag(kind, bytes(data))] if size <= 4 else [head, _TAG.pack(kind, size), data, b"\0" * (-size % 8)]
    total = sum(len(p) for p in parts)
    return [_TAG.pack(MI_MATRIX, total), *parts]


def _compressed(parts: list[bytes | memoryview]) -> bytes:
    """The joined parts compressed at :data:`ZLIB_LEVEL` (scipy compresses a variable whole, at level 6), fed part by part: no joined copy."""
    z = zlib.compressobj(ZLIB_LEVEL)
    out = [z.compress(p) for p in parts]
    out.append(z.flush())
    data = b"".join(out)
    return _TAG.pack(MI_COMPRESSED, len(data)) + data


def dump(variables: dict[str, np.ndarray], header_text: bytes) -> list[bytes] | None:
    """The bytes of the MAT file of ``variables`` (in order) with ``header_text``, as parts; None when ``scipy.io`` must write them.

    The variables are compressed in up to :func:`ilic_cli.parallel.threads` threads.
    """
    all_parts = [_matrix_parts(name, value) for name, value in variables.items()]
    elements = [parts for parts in all_parts if parts is not None]
    if len(elements) < len(all_parts):
        return None
    header = header_text.ljust(116, b" ")[:116] + bytes(8) + b"\x00\x01IM"
    biggest_first = sorted(range(len(elements)), key=lambda i: -sum(len(p) for p in elements[i]))
    done = dict(zip(biggest_first, ordered_map(lambda i: _compressed(elements[i]), biggest_first)))
    return [header, *(done[i] for i in range(len(elements)))]
