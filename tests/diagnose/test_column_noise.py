"""A flexibility's columns carry the position's noise (errors in the variables): the noise-corrected fit (issue 29).

``ilic_cli.diagnosis.system.column_noise`` realises the noise the measured position puts in the columns (white noise of
the log's position noise through the same filter, derivatives, hold and decimation), and
``ilic_cli.lsq.noise_corrected_lstsq`` takes its covariance off ``W'W``. Near a resonance the flexibility's column is the
position's fourth derivative, low-passed: on the robot corpus's 200 kg multisine at 500 Hz (s3340) plain least squares
fits the mass behind the spring 34 % low at the truth's resonance and damping, with the sensor noise, and 0.5 % without.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ilic_cli.diagnosis.column_noise import noise_kinematics
from ilic_cli.diagnosis.propose import prepare_system
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.diagnosis.system import NOISE_REALISATIONS, Step, column_noise, fit_system, moving_rows, system
from ilic_cli.effects import EFFECTS
from ilic_cli.lsq import lstsq
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import get_model
from ilic_cli.usable import with_rest
from tests.corpus import robot

FLEX = EFFECTS["flexibility"]
CASE = robot.case_named("lin200/multisine/500Hz/sensor/flexibility/s340")
TRUTH = {"stiffness": 5.96775e6, "damping": 8141.12, "load_fraction": 0.617}  # s3340's (the seed 3340)


def _data(quiet: bool):  # type: ignore[no-untyped-def]
    case = dataclasses.replace(CASE, seed=3340)
    effects = {"flexibility": TRUTH}
    if quiet:  # the same log without the sensor's noise and quantisation
        real = robot.noise_effects
        robot.noise_effects = lambda axis, kind: {k: v for k, v in real(axis, kind).items() if k not in ("noise", "quantization")}  # type: ignore[assignment]
        try:
            log = robot.simulate(case, effects)
        finally:
            robot.noise_effects = real  # type: ignore[assignment]
    else:
        log = robot.simulate(case, effects)
    ls = DiagnosisSettings().ls.at_rate(log.fs_hz)
    base = get_model("rigid-offset")
    return prepare_system(with_rest(prepare_log(log), ls), base, ls), base


def _truth_step(M: float) -> Step:
    m_load = TRUTH["load_fraction"] * M
    f = math.sqrt(TRUTH["stiffness"] / m_load) / (2 * math.pi)
    return Step(FLEX, (f, TRUTH["damping"] / (2 * math.sqrt(TRUTH["stiffness"] * m_load))))


@pytest.fixture(scope="module")
def noisy():  # type: ignore[no-untyped-def]
    return _data(quiet=False)


def test_the_mass_behind_the_spring_is_fitted_through_the_noise(noisy) -> None:  # noqa: ANN001
    data, base = noisy
    rows = moving_rows(data)
    M = dict(zip(*(lambda f: (f.names, f.theta))(fit_system(data, base, [], rows)), strict=True))["M"]
    step = _truth_step(M)
    truth = TRUTH["load_fraction"] * M
    corrected = dict(zip(*(lambda f: (f.names, f.theta))(fit_system(data, base, [step], rows)), strict=True))["M_load"]
    W, y, names = system(data, base, [step], rows)
    plain = lstsq(W, y)[0][names.index("M_load")]
    assert plain / truth - 1 < -0.25 and abs(corrected / truth - 1) < 0.15, (plain / truth, corrected / truth)
    quiet, qbase = _data(quiet=True)
    assert quiet.position_noise_std < 0.15 * data.position_noise_std  # (the motion above the position filter reads as a little noise)
    W, y, names = system(quiet, qbase, [step], moving_rows(quiet))
    assert abs(lstsq(W, y)[0][names.index("M_load")] / truth - 1) < 0.03


def test_the_column_noise_is_realised_for_a_noisy_column_only(noisy) -> None:  # noqa: ANN001
    data, base = noisy
    rows = moving_rows(data)
    assert data.position_noise_std == pytest.approx(robot.AXES["lin200"].noise, rel=0.25)  # estimated from the log
    assert column_noise(data, base, [], rows) is None and column_noise(data, base, [Step(EFFECTS["spring"])], rows) is None
    assert column_noise(dataclasses.replace(data, position_noise_std=0.0), base, [Step(FLEX, (35.0, 0.15))], rows) is None
    N = column_noise(data, base, [Step(FLEX, (35.0, 0.15))], rows)
    assert N is not None and N.shape == (NOISE_REALISATIONS, int(rows.sum()), len(base.names) + 1)
    assert np.all(N[:, :, base.names.index("offset")] == 0.0) and np.any(N[:, :, base.names.index("M")] != 0.0)
    a, b = noise_kinematics(data, 1), noise_kinematics(data, 1)
    assert np.array_equal(a.qdd, b.qdd) and not np.array_equal(a.qdd, noise_kinematics(data, 2).qdd)  # seeded, reproducible
