"""The compiled rigid-body dynamics against pinocchio (issue 30 item 5: the plant's own loop checked against ``aba`` to 1e-10)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

pin = import_or_skip("pinocchio")

from ilic_cli.robot import dynamics as rd  # noqa: E402
from ilic_cli.robot import model as rm  # noqa: E402
from ilic_cli.robot.base import base_parameters  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"


@pytest.mark.parametrize("arm", ("axis1.urdf", "arm2.urdf", "ur5like.urdf"))
def test_rnea_crba_and_forward_dynamics_match_pinocchio(arm: str) -> None:
    robot = rm.load_urdf(FIXTURES / arm)
    pi = robot.parameters({f"Ia_{j}": 0.05 * (k + 1) for k, j in enumerate(robot.joints)})
    model = rm.pinocchio_model(robot, pi)
    data = model.createData()
    kin = rd.arrays(robot)
    rng = np.random.default_rng(11)
    n = robot.n
    tau, qdd, M = np.empty(n), np.empty(n), np.empty((n, n))
    free = np.zeros(n, dtype=bool)
    worst = np.zeros(3)
    for _ in range(1000):
        q, qd, a = rng.uniform(-np.pi, np.pi, n), rng.normal(0, 2, n), rng.normal(0, 5, n)
        qc = rm.configuration(robot, q)
        rd.rnea(*kin, robot.gravity, pi, q, qd, a, tau)
        ref = pin.rnea(model, data, qc, qd, a)
        rd.crba(*kin, pi, q, M)
        Mref = pin.crba(model, data, qc)
        Mref = np.triu(Mref) + np.triu(Mref, 1).T
        rd.forward(*kin, robot.gravity, pi, q, qd, ref, free, qdd)
        worst = np.maximum(worst, [np.abs(tau - ref).max(), np.abs(M - Mref).max(), np.abs(qdd - pin.aba(model, data, qc, qd, ref)).max()])
    assert np.all(worst < 1e-10), worst
    assert worst.max() > 0  # compared, not skipped


def test_a_held_joint_does_not_accelerate_and_the_others_obey_the_reduced_dynamics() -> None:
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    pi = robot.parameters({f"Ia_{j}": 0.1 for j in robot.joints})
    kin = rd.arrays(robot)
    rng = np.random.default_rng(3)
    q, qd, tau = rng.uniform(-2, 2, 6), rng.normal(0, 1, 6), rng.normal(0, 10, 6)
    qd[2] = 0.0
    locked = np.zeros(6, dtype=bool)
    locked[2] = True
    qdd = np.empty(6)
    rd.forward(*kin, robot.gravity, pi, q, qd, tau, locked, qdd)
    assert qdd[2] == 0.0
    back = np.empty(6)
    rd.rnea(*kin, robot.gravity, pi, q, qd, qdd, back)
    free = ~locked
    assert np.abs(back[free] - tau[free]).max() < 1e-10  # the free joints' torques balance; the held one takes the difference
    assert abs(back[2] - tau[2]) > 1e-3


def test_base_parameters_at_their_kept_columns_give_the_same_torques() -> None:
    robot = rm.load_urdf(FIXTURES / "ur5like.urdf")
    pi = robot.parameters({f"Ia_{j}": 0.1 for j in robot.joints})
    base = base_parameters(robot)
    kept = rd.kept_vector(base.kept, base.values(pi), len(pi))
    assert np.count_nonzero(kept) < np.count_nonzero(pi)  # a different standard vector
    kin = rd.arrays(robot)
    rng = np.random.default_rng(5)
    t1, t2 = np.empty(6), np.empty(6)
    for _ in range(50):
        q, qd, a = rng.uniform(-3, 3, 6), rng.normal(0, 2, 6), rng.normal(0, 5, 6)
        rd.rnea(*kin, robot.gravity, pi, q, qd, a, t1)
        rd.rnea(*kin, robot.gravity, kept, q, qd, a, t2)
        assert np.abs(t1 - t2).max() < 1e-9
