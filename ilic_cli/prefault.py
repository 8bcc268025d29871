"""Fresh arrays backed by memory beside the work that fills them: ``madvise(MADV_POPULATE_WRITE)`` in a second thread.

An array from ``np.empty`` is address space only: each of its pages is given
memory when first written, by a page fault, inside whatever loop writes it. On
a virtual machine whose host backs the guest's memory lazily that costs far
more than the write itself (measured on this project's 2-core build machine:
4-5 ms a MB, 0.34 s to write 86 MB fresh, 0.01 s to write them again). A
compiled loop that fills a log sample by sample pays it on its own core.

:func:`populate_beside` asks the kernel to back the arrays' pages in a thread of
its own (``MADV_POPULATE_WRITE``, Linux 5.14 and later: the pages are faulted
in writable, their contents untouched), row blocks of every array in turn from
the first row, so the loop that starts writing at row 0 finds its pages ready
soon after it starts. Nothing is written to the arrays: the values, and every
output, are the same bits whether the thread runs, falls behind, or is not
available (another system, an older kernel, an error: then nothing is done).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import mmap
import sys
import threading
from collections.abc import Sequence
from typing import Any

import numpy as np

MADV_POPULATE_WRITE = 23
"""Linux's ``madvise`` advice that prefaults pages writable (``<linux/mman.h>``, since 5.14)."""

BLOCK_BYTES = 1 << 21
"""Bytes of one array populated before the next array's rows (2 MiB: a huge page)."""


@functools.cache
def _madvise() -> Any:
    """libc's ``madvise``, or None where it is not Linux's."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None
    fn = libc.madvise
    fn.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn


def page_ranges(arrays: Sequence[np.ndarray], block: int = BLOCK_BYTES) -> list[tuple[int, int]]:
    """``(address, length)`` of whole pages inside each C-contiguous array, in blocks of ``block`` bytes, interleaved across the arrays by row position."""
    page = mmap.PAGESIZE
    spans = []
    for a in arrays:
        if a.nbytes == 0 or not a.flags.c_contiguous:
            continue
        start, end = a.ctypes.data, a.ctypes.data + a.nbytes
        first, last = -(-start // page) * page, end // page * page
        if last > first:
            spans.append([(p, min(block, last - p)) for p in range(first, last, block)])
    longest = max((len(s) for s in spans), default=0)
    return [s[i] for i in range(longest) for s in spans if i < len(s)]


def _populate(ranges: list[tuple[int, int]]) -> None:
    madvise = _madvise()
    for address, length in ranges:
        if madvise(address, length, MADV_POPULATE_WRITE) != 0:
            return  # EINVAL (an older kernel), ENOMEM ...: the loop's own writes fault the pages in, as without this


def populate_beside(arrays: Sequence[np.ndarray]) -> threading.Thread | None:
    """Start a thread that backs ``arrays``' pages with memory (:data:`MADV_POPULATE_WRITE`); join it when the arrays are filled.

    None (nothing started) where ``madvise`` is not Linux's. The arrays must stay
    alive until the thread is joined (it holds only their addresses).
    """
    if _madvise() is None:
        return None
    ranges = page_ranges(arrays)
    if not ranges:
        return None
    thread = threading.Thread(target=_populate, args=(ranges,), name="ilic-populate", daemon=True)
    thread.start()
    return thread
