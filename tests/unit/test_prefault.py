"""``ilic_cli/prefault.py``: fresh arrays' pages backed beside the loop, their values untouched."""

from __future__ import annotations

import mmap
import sys

import numpy as np
import pytest

from ilic_cli.prefault import BLOCK_BYTES, page_ranges, populate_beside


def test_populating_keeps_every_value() -> None:
    # written values (and the zeros of a fresh np.zeros) are the same bits after the thread has backed the pages
    written = np.arange(3 * BLOCK_BYTES // 8, dtype=np.float64) * 0.5 + 0.25
    before = written.copy()
    fresh = np.zeros((BLOCK_BYTES // 8 + 123, 3))
    thread = populate_beside((written, fresh))
    if sys.platform.startswith("linux"):
        assert thread is not None
    if thread is not None:
        thread.join()
    assert np.array_equal(written, before)
    assert not fresh.any()


def test_page_ranges_are_whole_pages_inside_the_arrays_interleaved() -> None:
    page = mmap.PAGESIZE
    a = np.empty(5 * BLOCK_BYTES // 8 + 7)
    b = np.empty(5 * BLOCK_BYTES // 16 + 3)  # 2.5 blocks: at least two whole ones wherever it starts
    ranges = page_ranges((a, b))
    inside = [(x.ctypes.data, x.ctypes.data + x.nbytes) for x in (a, b)]
    for address, length in ranges:
        assert address % page == 0 and length % page == 0 and 0 < length <= BLOCK_BYTES
        assert any(lo <= address and address + length <= hi for lo, hi in inside)
    owner = [next(i for i, (lo, hi) in enumerate(inside) if lo <= addr < hi) for addr, _ in ranges]
    assert owner[:4] == [0, 1, 0, 1]  # a block of each array in turn from the first rows: the loop's rows come first
    covered = {i: sum(n for (addr, n), o in zip(ranges, owner, strict=True) if o == i) for i in (0, 1)}
    for i, (lo, hi) in enumerate(inside):  # every whole page inside each array, no more
        assert covered[i] == (hi // page) * page - (-(-lo // page)) * page


@pytest.mark.parametrize("array", [np.empty(0), np.empty((100, 4))[:, 1]])
def test_nothing_for_empty_or_strided_arrays(array: np.ndarray) -> None:
    assert page_ranges((array,)) == []
    assert populate_beside((array,)) is None
