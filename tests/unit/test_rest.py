"""The rule for samples at rest (``ilic_cli.usable.rest_samples``, ``with_rest``): a dwell is at rest, a reversal passing through zero is not."""

from __future__ import annotations

import numpy as np

from ilic_cli.idim_ls import LSSettings
from ilic_cli.prepare import prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.usable import REST_MIN_S, rest_samples, rows_left_out, with_rest

FS = 1000.0


def _position(dwell_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A sine sweep of 2 s (its reversals pass through zero speed), then ``dwell_s`` at rest, then the sweep again."""
    t1 = np.arange(int(2.0 * FS)) / FS
    sweep = 0.05 * np.sin(2 * np.pi * 1.0 * t1)
    q = np.r_[sweep, np.full(int(dwell_s * FS), sweep[-1]), sweep[-1] + sweep]
    return np.arange(len(q)) / FS, q


def test_a_dwell_is_at_rest_and_a_reversal_is_not() -> None:
    t, q = _position(0.2)
    rest = rest_samples(q, FS, LSSettings())
    assert rest.dwells == 1
    a, b = int(2.0 * FS), int(2.2 * FS)
    reach = int(FS / LSSettings().cutoff_hz)
    assert rest.mask[a + 20 : b - 20].all()  # the dwell (the filtered speed rises within a few ms of its ends)
    assert not rest.mask[: a - 3 * reach].any() and not rest.mask[b + 3 * reach :].any()  # the sweep's reversals stay
    top = 0.05 * 2 * np.pi  # the sweep's top speed (m/s)
    assert 0.009 * top < rest.speed_threshold < 0.0101 * top  # 1 % of it


def test_a_stop_shorter_than_a_dwell_is_not_at_rest() -> None:
    t, q = _position(0.5 * REST_MIN_S)
    assert rest_samples(q, FS, LSSettings()).dwells == 0


def test_the_prepared_log_masks_rest_apart_from_saturation() -> None:
    t, q = _position(0.3)
    log = RunLog({"t": t, "q": q, "tau": np.zeros_like(q)}, {"t": "s", "q": "m", "tau": "N"}, {"source": "x"})
    prepared = with_rest(prepare_log(log))
    assert prepared.rest is not None and prepared.valid is not None
    assert np.array_equal(prepared.valid, ~prepared.rest.mask)
    assert prepared.saturated is None and prepared.saturation_note() is None  # rest is not a saturated drive
    total, at_rest = rows_left_out(prepared.rest.mask, LSSettings())
    assert 0 < at_rest < total
    assert with_rest(prepared) is prepared  # looked for once
