"""Which full-rate samples a decimated row may rest on, the one definition: the samples that may be used
(:func:`usable_mask`) and the rows whose span touches none of the others (:func:`valid_rows`).

A decimated row is a low-pass of its neighbourhood: the rows whose span touches a sample that may not be used (a saturated
drive, the axis at rest) are left out. The filter's tail reaches further than a row's span; zeroing the dwells before it
was measured and not kept (docs/methods.md, *Measured, not kept: the samples at rest zero before the decimation*).
"""

from __future__ import annotations

import numpy as np

from ilic_cli.filtering import kept_indices


def usable_mask(valid: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """``valid`` as a boolean array checked against the log's ``shape``; ``None`` when every sample may be used."""
    if valid is None:
        return None
    valid = np.asarray(valid, dtype=bool)
    if valid.shape != shape:
        raise ValueError(f"valid has {valid.shape} samples, the log {shape}")
    return None if valid.all() else valid


def valid_rows(valid: np.ndarray, r: int) -> np.ndarray:
    """Decimated rows whose decimation span holds only valid full-rate samples.

    Parameters
    ----------
    valid : ndarray of bool, shape (..., n)
        Full-rate samples that may be used (False: e.g. a saturated drive).
    r : int
        Decimation factor; the kept samples are :func:`kept_indices` (end-aligned).

    Returns
    -------
    ndarray of bool, shape (..., ceil(n / r))
        False for a row whose kept sample lies within ``r - 1`` samples of an
        invalid one (the zero-phase anti-alias filter mixes that neighbourhood).
    """
    valid = np.asarray(valid, dtype=bool)
    n = valid.shape[-1]
    # count of invalid samples in [i - (r - 1), i + (r - 1)] by a running sum (4 bytes a sample up to 2^31 samples)
    csum = np.cumsum(~valid, axis=-1, dtype=np.int32 if n < 2**31 else np.int64)
    idx = kept_indices(n, r)
    hi = np.minimum(idx + r, n)
    lo = np.maximum(idx - (r - 1), 0)
    before = np.where(lo > 0, np.take(csum, np.maximum(lo - 1, 0), axis=-1), 0)  # invalid samples before lo
    return (np.take(csum, hi - 1, axis=-1) - before) == 0
