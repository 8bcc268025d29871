"""Physical consistency of base parameters: pseudo-inertia, the log-Cholesky fit, what it costs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.robot import model as rm  # noqa: E402
from ilic_cli.robot.base import base_parameters  # noqa: E402
from ilic_cli.robot.consistency import consistent_fit, inertial_of, link_consistent, pseudo_inertia  # noqa: E402
from ilic_cli.robot.idim import ROBOT_BAND_HZ, prepare, solve_system, validation_error_pct  # noqa: E402
from ilic_cli.robot.simulate import SimSettings, exciting_trajectory, simulate  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"


def test_pseudo_inertia_round_trip_and_rule() -> None:
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    p = robot.standard[14:24]
    J = pseudo_inertia(p)
    assert np.allclose(inertial_of(J), p) and np.all(np.linalg.eigvalsh(J) > 0)
    assert link_consistent(robot.standard, robot).all()
    bad = robot.standard.copy()
    bad[14 + 4] = -1.0  # a negative Ixx of link 2: no mass distribution has it
    assert list(link_consistent(bad, robot)) == [True, False, True, True, True, True]
    bad = robot.standard.copy()
    bad[robot.index("Fc", 3)] = -0.1
    assert not link_consistent(bad, robot)[3]


def test_consistent_fit_on_the_2_joint_arm() -> None:
    """The true base parameters admit a consistent set; a negative Coulomb level does not, and the fit clamps it."""
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    pi = robot.parameters({"Ia_shoulder": 0.05, "Ia_elbow": 0.03, "offset_shoulder": 0.4})
    base = base_parameters(robot)
    log = simulate(robot, pi, exciting_trajectory(np.array([0.3, 0.8]), np.array([2.0, 2.5]), seed=4), 8.0, SimSettings(torque_noise=(0.05, 0.03), seed=3))
    from ilic_cli.idim_ls import LSSettings

    system = prepare(log.q, log.tau, 1000.0, robot, base, LSSettings(cutoff_hz=50.0, trim=100, band_hz=ROBOT_BAND_HZ), min_speed=0.2)
    fit = solve_system(system)
    truth = consistent_fit(robot, base, base.values(pi), fit.covariance)
    assert truth.admits and truth.within_noise and link_consistent(truth.standard, robot).all()
    assert np.allclose(base.values(truth.standard), base.values(pi), rtol=1e-4, atol=1e-6)
    # the estimate: a consistent set within its noise, at (almost) no cost in relative error
    est = consistent_fit(robot, base, fit.theta, fit.covariance)
    assert est.within_noise and link_consistent(est.standard, robot).all()
    assert validation_error_pct(est.base, system) <= 1.05 * validation_error_pct(fit.theta, system)
    # a negative Coulomb level of the elbow: identified as such, clamped at 0, not admitted
    theta = fit.theta.copy()
    i = fit.names.index("Fc_elbow")
    theta[i] = -0.5
    neg = consistent_fit(robot, base, theta, fit.covariance)
    assert neg.identified_violations == ("Fc_elbow",) and not neg.admits and not neg.within_noise
    assert neg.standard[robot.index("Fc", 1)] >= 0 and abs(neg.base[i]) < 1e-6
    assert neg.to_dict()["admits_consistent_standard_set"] is False
