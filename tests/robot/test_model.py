"""The n-joint regressor against pinocchio (issue 30, Done-when: rnea to 1e-10 on 1000 random states of each fixture arm)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.errors import IlicError, ParameterError  # noqa: E402
from ilic_cli.robot import model as rm  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"
ARMS = ("axis1.urdf", "arm2.urdf", "ur5like.urdf")  # axis1: the one-joint case n = 1


def _truth(robot: rm.RobotModel) -> np.ndarray:
    """The URDF's parameters with rotor inertias and offsets (the URDF has neither)."""
    values = {f"Ia_{j}": 0.1 * (k + 1) for k, j in enumerate(robot.joints)}
    values |= {f"offset_{j}": 0.2 - 0.1 * k for k, j in enumerate(robot.joints)}
    return robot.parameters(values)


@pytest.mark.parametrize("arm", ARMS)
def test_regressor_reproduces_rnea_with_friction(arm: str) -> None:
    robot = rm.load_urdf(FIXTURES / arm)
    rng = np.random.default_rng(7)
    N = 1000
    q = rng.uniform(-np.pi, np.pi, (N, robot.n))
    qd, qdd = rng.normal(0, 2, (N, robot.n)), rng.normal(0, 5, (N, robot.n))
    pi = _truth(robot)
    tau = rm.inverse_dynamics(robot, pi, q, qd, qdd)  # pinocchio's rnea (with armature) + friction + offset
    Y = rm.regressor(robot, q, qd, qdd)
    assert Y.shape == (robot.n * N, 14 * robot.n)
    assert np.abs(Y @ pi - tau.T.ravel()).max() < 1e-10
    # the vectorised regressor is pinocchio's computeJointTorqueRegressor, column by column
    assert np.abs(Y - rm.regressor_loop(robot, q, qd, qdd)).max() < 1e-10
    # the friction columns are the joint's own: zeroing Fc changes only that joint's torque by Fc sign(qd)
    j = robot.n - 1
    pi2 = pi.copy()
    pi2[robot.index("Fc", j)] = 0.0
    d = (Y @ (pi - pi2)).reshape(robot.n, N)
    assert np.allclose(d[j], robot.drive(pi, "Fc")[j] * np.sign(qd[:, j])) and not d[:j].any()


def test_fixture_parameters_come_from_the_urdf() -> None:
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    assert robot.joints[0] == "shoulder_pan_joint" and robot.n == 6 and set(robot.kinds) == {"revolute"}
    masses = robot.standard[0::14]
    assert np.allclose(masses, [3.7, 8.393, 2.275, 1.219, 1.219, 0.1879])  # the UR5's published masses
    assert np.allclose(robot.drive(robot.standard, "Fv"), [2.0, 2.5, 1.5, 0.6, 0.6, 0.5])  # <dynamics damping>
    arm2 = rm.load_urdf(FIXTURES / "arm2.urdf")
    assert arm2.standard[arm2.index("m", 1)] == pytest.approx(2.8)  # link2 (2.5 kg) with the fixed tool (0.3 kg) merged
    assert len(arm2.sha256) == 64 and arm2.to_dict()["joints"][1] == {"name": "elbow", "type": "revolute", "parent": "shoulder"}


def test_bad_inputs_are_one_line_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(IlicError, match="no moving joint"):
        rm.load_urdf(bad)
    with pytest.raises(IlicError, match="cannot read the URDF"):
        rm.load_urdf(tmp_path / "missing.urdf")
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    with pytest.raises(ParameterError, match="Fv_wrist"):
        robot.parameters({"Fv_wrist": 1.0})
    monkeypatch.setitem(__import__("sys").modules, "pinocchio", None)  # import pinocchio now raises ImportError
    with pytest.raises(ParameterError) as err:
        rm.load_urdf(FIXTURES / "arm2.urdf")
    assert err.value.message() == "pinocchio is not installed: pip install 'ilic[robot]'"
