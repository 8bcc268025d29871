"""Base parameters by QR with column pivoting against an independent rank (SVD), and their regrouping."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.robot import model as rm  # noqa: E402
from ilic_cli.robot.base import base_parameters, pivoted_qr, stacked_regressor, upper_solve  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"


@pytest.mark.parametrize("arm", ("axis1.urdf", "arm2.urdf", "ur5like.urdf"))
def test_base_count_is_the_rank_and_the_regrouping_is_exact(arm: str) -> None:
    robot = rm.load_urdf(FIXTURES / arm)
    base = base_parameters(robot, seed=0)
    Y = stacked_regressor(robot, 150, seed=11)  # other random states than the QR's
    assert base.b == np.linalg.matrix_rank(Y)  # SVD rank, numpy's own tolerance
    s = np.linalg.svd(Y, compute_uv=False)
    assert s[base.b - 1] / s[0] > 1e-8 > s[base.b] / s[0]  # a clear gap at b
    pi = robot.parameters({f"Ia_{j}": 0.2 for j in robot.joints})
    scale = np.abs(Y @ pi).max()
    assert np.abs(base.columns(Y) @ base.values(pi) - Y @ pi).max() < 1e-9 * max(scale, 1.0)
    # another random standard vector: the regrouping holds for any parameters
    other = np.random.default_rng(3).normal(size=len(pi))
    assert np.abs(base.columns(Y) @ base.values(other) - Y @ other).max() < 1e-9 * np.abs(Y @ other).max()


def test_arm2_counts_and_table() -> None:
    """The 2R arm in a vertical plane: 6 inertial base parameters, Ia of the elbow, Fv, Fc, offset of each joint (13).

    Inertial: ZZ1R (= ZZ1 + Ia1 + l1^2 M2), ZZ2, the first moments of both links
    along and across (MX1R, MY1R, MX2, MY2): 6. In a horizontal plane gravity
    drops the first link's moments: 4 inertial base parameters (the brief's count).
    """
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    base = base_parameters(robot)
    assert base.b == 13
    names = set(base.names)
    assert {"Fv_shoulder", "Fc_shoulder", "offset_shoulder", "Ia_elbow", "Fv_elbow"} <= names
    table = base.table()
    first = next(line for line in table.splitlines() if "+ 0.25 m_elbow" in line)
    assert "Ia_shoulder" in first  # ZZ1R regroups Ia1 and l1^2 m2 (l1 = 0.5 m)
    assert base.to_dict()["count"] == 13 and "m_shoulder" in base.unidentifiable
    # the same arm with gravity along the joints' axis (a horizontal plane)
    horizontal = rm.RobotModel(**{**robot.__dict__, "gravity": np.array([0.0, -9.81, 0.0])})
    assert base_parameters(horizontal).b == 13 - 2


def test_docs_show_the_table_as_printed() -> None:
    """The regrouping lines quoted in docs/robots.md are what ``table()`` prints for arm2."""
    doc = (Path(__file__).parents[2] / "docs" / "robots.md").read_text()
    quoted = [line for line in doc.splitlines() if line.startswith("base ") and " = " in line and "(" not in line]
    table = base_parameters(rm.load_urdf(FIXTURES / "arm2.urdf")).table().splitlines()
    assert len(quoted) == 2 and all(line in table for line in quoted)


@pytest.mark.parametrize("arm", ("axis1.urdf", "arm2.urdf", "ur5like.urdf"))
def test_active_columns_cover_the_nonzero_pattern(arm: str) -> None:
    """IDIM decimates only the base columns a joint's rows can touch: every nonzero one, and far from all."""
    from ilic_cli.robot.idim import active_columns

    robot = rm.load_urdf(FIXTURES / arm)
    base = base_parameters(robot)
    Y = base.columns(rm.regressor(robot, *random_states_for(robot), joint_major=False))
    active, nonzero = active_columns(robot, base), np.abs(Y).max(axis=1) > 0
    assert not (nonzero & ~active).any()
    assert robot.n == 1 or active.mean() < 0.75  # ur5like: 48 % (the last joint's rows touch only its own link's 13 columns)


def random_states_for(robot: rm.RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from ilic_cli.robot.base import random_states

    return random_states(robot, 50, seed=9)


@pytest.mark.parametrize("arm", ("axis1.urdf", "arm2.urdf", "ur5like.urdf"))
def test_the_qr_and_the_triangular_solve_are_scipys_bit_for_bit(arm: str) -> None:
    """``pivoted_qr`` and ``upper_solve`` call LAPACK without importing ``scipy.linalg``: the same bits as its ``qr`` and ``solve_triangular``."""
    from scipy.linalg import qr, solve_triangular

    Y = stacked_regressor(rm.load_urdf(FIXTURES / arm))
    _, R, perm = qr(Y, mode="economic", pivoting=True)
    R_, perm_ = pivoted_qr(Y)
    assert np.array_equal(R, R_) and np.array_equal(perm, perm_)
    for b in (np.linalg.matrix_rank(Y), Y.shape[1]):
        assert np.array_equal(solve_triangular(R[:b, :b], R[:b, b:]), upper_solve(R[:b, :b], R[:b, b:]))
    F = np.asfortranarray(R[:4, :4])  # the other branch: a Fortran-ordered matrix solved as it is
    assert np.array_equal(solve_triangular(F, R[:4, 4:]), upper_solve(F, R[:4, 4:]))


def test_the_base_parameters_do_not_import_scipy_linalg(monkeypatch: pytest.MonkeyPatch) -> None:
    """``scipy.linalg``'s package (0.17 s of imports) is not needed: with its import made to fail, the same base parameters."""
    robot = rm.load_urdf(FIXTURES / "arm2.urdf")
    expected = base_parameters(robot)
    monkeypatch.setitem(sys.modules, "scipy.linalg", None)  # an import of it raises ImportError
    monkeypatch.delitem(sys.modules, "scipy.linalg._flapack", raising=False)
    base = base_parameters(robot)
    assert np.array_equal(base.kept, expected.kept) and np.array_equal(base.regrouping, expected.regrouping)
