"""The rule for samples at rest (``ilic_cli.usable.rest_samples``, ``with_rest``): a dwell is at rest, a reversal passing through zero is not."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.idim_ls import LSSettings, differentiated, filtered_position
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import Kinematics, expected_sign
from ilic_cli.runlog import RunLog
from ilic_cli.usable import REST_MIN_S, identification_speed_noise, rest_samples, rows_left_out, with_rest

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
    log = RunLog({"t": t, "q": q, "tau": np.sin(t)}, {"t": "s", "q": "m", "tau": "N"}, {"source": "x"})  # a force that changes
    prepared = with_rest(prepare_log(log))
    assert prepared.rest is not None and prepared.valid is not None
    assert np.array_equal(prepared.valid, ~prepared.rest.mask)
    assert prepared.saturated is None and prepared.saturation_note() is None  # rest is not a saturated drive
    total, at_rest = rows_left_out(prepared.rest.mask, LSSettings())
    assert 0 < at_rest < total
    assert with_rest(prepared) is prepared  # looked for once


def test_the_velocity_noise_is_measured_over_the_dwells_alone() -> None:
    """``speed_noise``: the RMS of the filtered velocity over the dwells, beyond the filter's reach of the moves (its
    widening would add the moves' own speed), and 0 where nothing rests."""
    t, q = _position(0.4)
    noise = 2e-6 * np.random.default_rng(3).standard_normal(len(q))
    rest = rest_samples(q + noise, FS, LSSettings())
    clean = rest_samples(q, FS, LSSettings())
    assert rest.dwells == clean.dwells == 1
    settings = LSSettings().at_rate(FS)
    qd = differentiated(filtered_position(noise, FS, settings), FS, settings)[0]  # the noise's own velocity, trimmed
    a, b = int(2.0 * FS) - settings.trim, int(2.4 * FS) - settings.trim
    expected = float(np.sqrt(np.mean(qd[a + 20 : b - 20] ** 2)))
    assert 0.8 * expected < rest.speed_noise < 1.25 * expected, (rest.speed_noise, expected)
    assert clean.speed_noise < 0.15 * rest.speed_noise  # the noise, not the moves' speed (this sweep stops dead: the filter rings a little past its reach)
    assert rest_samples(q[: int(2.0 * FS)] + noise[: int(2.0 * FS)], FS, LSSettings()).speed_noise == 0.0  # no dwell


def test_the_coulomb_sign_of_a_log_with_rest_is_the_expected_sign_of_its_velocity() -> None:
    """:func:`identification_speed_noise`: the dwells' velocity noise once rows at rest are left out, 0 (the sign) else."""
    t, q = _position(0.3)
    q = q + 2e-6 * np.random.default_rng(4).standard_normal(len(q))
    log = RunLog({"t": t, "q": q, "tau": np.sin(t)}, {"t": "s", "q": "m", "tau": "N"}, {"source": "x"})  # a force that changes
    prepared = with_rest(prepare_log(log))
    assert prepared.rest is not None and identification_speed_noise(prepared) == prepared.rest.speed_noise > 0
    sweep = RunLog({"t": t[:2000], "q": q[:2000], "tau": np.sin(t[:2000])}, {"t": "s", "q": "m", "tau": "N"}, {"source": "y"})
    assert identification_speed_noise(with_rest(prepare_log(sweep))) == 0.0  # no standstill: the published procedure


def test_the_expected_sign_of_a_noisy_velocity() -> None:
    v = np.array([-1.0, -0.01, 0.0, 0.01, 1.0])
    assert np.array_equal(expected_sign(v, 0.0), np.sign(v))
    s = expected_sign(v, 0.01)
    assert s[2] == 0.0 and s[3] == pytest.approx(0.682689492, abs=1e-9) and s[1] == -s[3]  # erf(1/sqrt(2)): one sigma
    assert s[4] == 1.0 and s[0] == -1.0
    kin = Kinematics(qd=v, qdd=np.zeros_like(v), t=np.arange(5.0), speed_noise=0.01)
    assert np.array_equal(kin.sgn, s) and kin.later(0.5).speed_noise == 0.01
    assert np.array_equal(Kinematics(qd=v, qdd=v, sign_qd=np.ones(5), speed_noise=0.01).sgn, np.ones(5))  # the CTC law's own


def test_a_part_after_a_gap_that_holds_no_move_is_at_rest() -> None:
    """The top speed is the log's, not each part's: a part between gaps that holds only a dwell (its position noise, 1 um) is at
    rest, where against 1 % of its own noise most of it was not (and a fit took the stuck axis's force for friction)."""
    t, q = _position(0.2)
    rng = np.random.default_rng(5)
    dwell = q[-1] + 1e-6 * rng.standard_normal(3000)
    q2 = np.r_[q, dwell]
    segments = ((0, len(q)), (len(q), len(q2)))
    rest = rest_samples(q2, FS, LSSettings(), segments)
    alone = rest_samples(dwell, FS, LSSettings())
    assert rest.mask[len(q) :].all(), float(rest.mask[len(q) :].mean())
    assert alone.mask.mean() < 0.5  # its own top speed is its noise's: the rule, part by part, had found it moving
    assert rest.speed_threshold == rest_samples(q, FS, LSSettings()).speed_threshold  # the moving part's top speed
