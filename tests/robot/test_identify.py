"""Issue 30's Done-when on a simulated 6-joint arm: IDIM-WLS recovers the base parameters, friction and validation.

The arm: fixtures/ur5like.urdf with rotor inertias and offsets, PD tracking of
a sum of sines (5 harmonics of 0.1 Hz per joint), 2^17-count encoders, torque
noise, 20 s at 1 kHz per log; a second log (other seed and trajectory) validates.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.derivatives import central_difference  # noqa: E402
from ilic_cli.filtering import butter_lowpass_zero_phase, rows_decimation  # noqa: E402
from ilic_cli.idim_ls import LSSettings, _decimate  # noqa: E402
from ilic_cli.robot import model as rm  # noqa: E402
from ilic_cli.robot.base import base_parameters  # noqa: E402
from ilic_cli.robot.idim import ROBOT_BAND_HZ, active_columns, idim_ls, prepare, solve_system, validation_error_pct  # noqa: E402
from ilic_cli.robot.simulate import SimSettings, exciting_trajectory, simulate  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"
Q0 = np.array([0.0, -1.2, 1.2, -1.5, -1.5, 0.0])
SPEED = np.array([1.5, 2.0, 2.0, 2.0, 2.0, 2.5])  # rad/s, the bound of each joint's reference velocity (the UR5's limit: 3.15)
NOISE = (0.6, 0.6, 0.4, 0.15, 0.15, 0.1)  # N·m, std of the logged torque's noise
SETTINGS = LSSettings(cutoff_hz=50.0, trim=100, band_hz=ROBOT_BAND_HZ)  # position filter above the 20 Hz of the decimation, as the 1-DOF chain (100 over 40 Hz)
MIN_SPEED = 0.2  # rad/s: rows near rest (sticking) left out


@pytest.fixture(scope="module")
def arm() -> tuple[rm.RobotModel, np.ndarray]:
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    values = {f"Ia_{j}": a for j, a in zip(robot.joints, (0.35, 0.35, 0.2, 0.1, 0.1, 0.1))}
    values |= {f"offset_{j}": o for j, o in zip(robot.joints, (0.2, -0.3, 0.1, 0.05, -0.05, 0.02))}
    return robot, robot.parameters(values)


@pytest.fixture(scope="module")
def logs(arm: tuple[rm.RobotModel, np.ndarray]) -> tuple:
    robot, pi = arm
    return tuple(simulate(robot, pi, exciting_trajectory(Q0, SPEED, seed=s), 20.0, SimSettings(torque_noise=NOISE, seed=s)) for s in (1, 2))


def test_idim_wls_recovers_the_base_parameters_and_friction(arm: tuple, logs: tuple) -> None:
    robot, pi = arm
    base = base_parameters(robot)
    beta = base.values(pi)
    system = prepare(logs[0].q, logs[0].tau, 1000.0, robot, base, SETTINGS, min_speed=MIN_SPEED, torque_held=True)
    fit = solve_system(system)
    assert fit.method == "IDIM-WLS" and fit.names == base.names
    well = fit.rel_std_pct < 1.0
    assert well.sum() >= 15  # not a vacuous check: 20 base parameters have %sigma < 1 on this log (17 to 21 on seeds 1-11)
    z = (fit.theta - beta) / fit.std
    assert np.all(np.abs(z[well]) < 3.0), dict(zip(np.array(fit.names)[well], np.round(z[well], 2)))
    for p in ("Fv", "Fc"):
        for j in robot.joints:
            truth = pi[robot.names.index(f"{p}_{j}")]
            assert fit.value(f"{p}_{j}") == pytest.approx(truth, rel=0.03), f"{p}_{j}"
    # weighted: each joint's rows were divided by its error's std (wrist errors are smaller than the shoulder's)
    assert fit.joint_std[0] > 2 * fit.joint_std[3]
    assert np.allclose(np.sqrt(np.diag(fit.covariance)), fit.std)
    d = fit.to_dict()
    assert d["parameters"]["Fc_elbow_joint"]["value"] == pytest.approx(fit.value("Fc_elbow_joint"))
    # validation on the second log: within 1.2x the true parameters' relative error
    other = prepare(logs[1].q, logs[1].tau, 1000.0, robot, base, SETTINGS, min_speed=MIN_SPEED, torque_held=True)
    assert validation_error_pct(fit.theta, other) <= 1.2 * validation_error_pct(beta, other)
    # the torque as logged, without the half-period of the held command: the shoulder's Fv comes out low by ~3 sigma (1.7 %)
    raw = solve_system(prepare(logs[0].q, logs[0].tau, 1000.0, robot, base, SETTINGS, min_speed=MIN_SPEED))
    i = raw.names.index("Fv_shoulder_lift_joint")
    assert (raw.theta[i] - beta[i]) / raw.std[i] < -2.5 and abs(raw.theta[i] - beta[i]) > 3 * abs(fit.theta[i] - beta[i])
    # the unweighted fit is the other method, and differs
    plain = solve_system(system, weighted=False)
    assert plain.method == "IDIM-LS" and not np.allclose(plain.theta, fit.theta)


def test_simulation_is_deterministic_and_quantised(arm: tuple, logs: tuple) -> None:
    robot, pi = arm
    again = simulate(robot, pi, exciting_trajectory(Q0, SPEED, seed=1), 0.5, SimSettings(torque_noise=NOISE, seed=1))
    assert np.array_equal(again.tau, logs[0].tau[:500]) and np.array_equal(again.q, logs[0].q[:500])
    step = 2 * np.pi / 2**17
    assert np.allclose(logs[0].q / step, np.round(logs[0].q / step), atol=1e-6)
    assert 0 < np.abs(logs[0].q - logs[0].q_true).max() <= step / 2 + 1e-12
    # the PD tracks: error well below the trajectories' amplitude
    assert np.abs(logs[0].q_true - logs[0].q_ref).max() < 0.05
    # the logged torque without its noise is the model's (smooth Coulomb) torque at the true state
    qdd = np.gradient(logs[0].qd_true, 1e-3, axis=0)
    k = slice(100, 2000)
    model = rm.inverse_dynamics(robot, pi, logs[0].q_true[k], logs[0].qd_true[k], qdd[k])
    assert np.median(np.abs(model - logs[0].tau[k])) < 3 * max(NOISE)


def test_arm2_without_noise_is_identified_almost_exactly() -> None:
    """The 2-joint arm, exact encoders and torque: the model explains the torque to 0.05 %, the friction within 0.5 %.

    The base parameters with %sigma < 1 come within 1 % (0.85 % at most: the
    elbow's Ia); the rest (the elbow's ``mz`` and offset, %sigma 1.3-1.4) within a
    few %: the smooth Coulomb rule near rest is the model error left.
    """
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    pi = robot.parameters({"Ia_shoulder": 0.05, "Ia_elbow": 0.03, "offset_shoulder": 0.4, "offset_elbow": -0.2})
    base = base_parameters(robot)
    settings = SimSettings(encoder_counts=2**40)
    log = simulate(robot, pi, exciting_trajectory(np.array([0.3, 0.8]), np.array([2.0, 2.5]), seed=4), 12.0, settings)
    fit = idim_ls(log.q, log.tau, 1000.0, robot, base, SETTINGS, min_speed=MIN_SPEED, torque_held=True)
    beta = base.values(pi)
    assert fit.relative_error_pct < 0.05
    well = fit.rel_std_pct < 1.0
    assert well.sum() >= 9 and np.all(np.abs(fit.theta - beta)[well] <= 0.01 * np.abs(beta[well]))
    for name in ("Fv_shoulder", "Fc_shoulder", "Fv_elbow", "Fc_elbow"):
        assert fit.value(name) == pytest.approx(beta[fit.names.index(name)], rel=0.005), name
    with pytest.raises(ValueError, match="too few samples"):
        idim_ls(log.q[:200], log.tau[:200], 1000.0, robot, base, SETTINGS)


def test_prepared_system_is_the_regressor_decimated_joint_by_joint() -> None:
    """``prepare``'s compiled base columns, decimated in one compiled call, equal the straightforward chain to 1e-11.

    The straightforward chain (the code before the compiled columns): the whole
    standard regressor, each joint's base columns picked from it, each joint's
    columns and torque decimated on their own by the 1-DOF chain's ``decimate_matlab``,
    then stacked. The compiled decimation (:func:`ilic_cli.robot.idim.decimate_columns`)
    runs the same filter in another order of operations: the same zeros, the values
    within 1e-11 of the largest (measured: 1e-13).
    """
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    base = base_parameters(robot)
    rng = np.random.default_rng(5)
    t = np.arange(3000) / 1000.0
    q = exciting_trajectory(Q0, SPEED, seed=3).at(t)[0] + rng.normal(0.0, 1e-5, (len(t), robot.n))
    tau = rng.normal(0.0, 5.0, q.shape)
    system = prepare(q, tau, 1000.0, robot, base, SETTINGS)
    qf = butter_lowpass_zero_phase(q, SETTINGS.cutoff_hz, 1000.0, SETTINGS.order, matlab=SETTINGS.matlab, axis=0)
    qd = central_difference(qf, 1e-3)
    qdd = central_difference(qd, 1e-3)
    s = slice(SETTINGS.trim, None)
    Y = rm.regressor(robot, qf[s], qd[s], qdd[s], joint_major=False)
    active = active_columns(robot, base)
    assert 0.3 < active.mean() < 0.7  # the zero columns are left out: not every column is active, nor none
    W, y = [], []
    for j in range(robot.n):
        d = _decimate(np.column_stack([Y[j][:, base.kept[active[j]]], tau[s, j]]), SETTINGS.at_rate(1000.0), 1000.0)
        part = np.zeros((len(d), base.b))
        part[:, active[j]] = d[:, :-1]
        W.append(part)
        y.append(d[:, -1])
    W, y = np.concatenate(W), np.concatenate(y)
    assert np.array_equal(system.W == 0, W == 0)
    np.testing.assert_allclose(system.W, W, rtol=0, atol=1e-11 * np.abs(W).max())
    np.testing.assert_allclose(system.y, y, rtol=0, atol=1e-11 * np.abs(y).max())
    assert np.array_equal(system.joint, np.repeat(np.arange(robot.n), len(y) // robot.n))
    assert system.settings.decimation == 20


def test_decimation_follows_the_log_rate_by_the_one_rule() -> None:
    """``prepare`` decimates by :func:`ilic_cli.filtering.rows_decimation` at the log's rate (20 at 1 kHz, 40 at 2 kHz), unless given."""
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    base = base_parameters(robot)
    traj = exciting_trajectory(np.zeros(2), np.array([1.5, 2.0]), seed=2)
    rows = {}
    for fs in (1000.0, 2000.0):
        t = np.arange(int(3.0 * fs)) / fs
        q = traj.at(t)[0]
        tau = np.random.default_rng(1).normal(0.0, 1.0, q.shape)
        system = prepare(q, tau, fs, robot, base, SETTINGS)
        assert system.settings.decimation == rows_decimation(fs, ROBOT_BAND_HZ) == {1000.0: 20, 2000.0: 40}[fs]
        rows[fs] = len(system.y)
        given = prepare(q, tau, fs, robot, base, LSSettings(cutoff_hz=50.0, trim=100, decimation=10, band_hz=None))
        assert given.settings.decimation == 10
    assert abs(rows[2000.0] - rows[1000.0]) <= 0.05 * rows[1000.0]  # the same 3 s in about as many rows (the same band) at either rate
