"""Gravity and friction drift in the vocabulary: one definition each, the same in the regressor, the plant and the words (issue 29).

- ``tau = Y(q, qd, qdd) theta`` holds for the gravity column pair (``g cos q``, ``-g sin q``) and the plant's inverse dynamics;
- the plant's compiled gravity and drift equal their definitions;
- gravity is proposed on a revolute joint only; the joint type is the position's unit;
- the constant force of a vertical axis reads as the weight it is.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli import effects as fx
from ilic_cli import parameters, runlog
from ilic_cli.effects import EFFECTS, make_effects
from ilic_cli.regressor import GRAVITY_COLUMNS, Kinematics, get_model
from plant import kernel
from plant.dynamics import P_FC_NEG, P_FC_POS, P_FV_NEG, P_FV_POS, RigidParameters, force_model, plant_vector

G = parameters.STANDARD_GRAVITY


def test_gravity_columns_times_the_first_moments_are_the_plant_torque() -> None:
    rng = np.random.default_rng(29)
    n = 200
    q, qd, qdd = rng.uniform(-3.0, 3.0, n), rng.uniform(-2.0, 2.0, n), rng.uniform(-10.0, 10.0, n)
    rigid = {"M": 0.08, "Fv": 0.05, "Fc": 0.2, "offset": 0.01}
    moments = {"MX": 0.021, "MY": -0.013}
    model = get_model("rigid-offset").extend(*GRAVITY_COLUMNS.values())
    assert model.names == ("M", "Fv", "Fc", "offset", "MX", "MY")
    Y = model.matrix(Kinematics(qd=qd, qdd=qdd, q=q))
    theta = np.array([*rigid.values(), *moments.values()])
    tau = force_model(RigidParameters(**rigid), {"gravity": moments}, q, qd, qdd, np.zeros(n))
    np.testing.assert_allclose(Y @ theta, tau, rtol=1e-12, atol=1e-12)
    # the effect's own columns are the same pair, and its force is the definition's g (MX cos q - MY sin q)
    np.testing.assert_array_equal(EFFECTS["gravity"].matrix(Kinematics(qd=qd, qdd=qdd, q=q)), Y[:, 4:])
    force = EFFECTS["gravity"].plant_force(moments, Kinematics(qd=qd, qdd=qdd, q=q))
    np.testing.assert_allclose(force, G * (0.021 * np.cos(q) + 0.013 * np.sin(q)), rtol=1e-14, atol=1e-15)
    assert parameters.unit("MX", "revolute") == "kg·m" and fx.unit_of("MY") == "kg·m"


def test_gravity_estimates_read_back_as_first_moments() -> None:
    fit = fx.Fit(("M", "Fv", "Fc", "offset", "MX", "MY"), np.array([0.08, 0.05, 0.2, 0.0, 0.02, 0.01]), np.diag([1e-8, 1e-8, 1e-8, 1e-8, 4e-8, 9e-8]))
    est, plant, note = EFFECTS["gravity"].fit_to_plant(fit)
    assert plant == {"MX": 0.02, "MY": 0.01} and note == ""
    assert est["MX"].unit == "kg·m" and est["MY"].std == pytest.approx(3e-4)
    words = EFFECTS["gravity"].describe(est)
    assert "MX = 0.02 kg·m" in words and f"{G * math.hypot(0.02, 0.01):.4g} N·m" in words


def test_gravity_is_proposed_on_a_revolute_joint_only() -> None:
    assert runlog.joint_type("rad") == "revolute" and runlog.joint_type("m") == "prismatic"
    assert "gravity" in fx.catalogue_ids("revolute") and "gravity" not in fx.catalogue_ids("prismatic")
    assert fx.catalogue_ids("prismatic") == tuple(i for i in fx.catalogue_ids() if i != "gravity")
    assert "spring" in fx.catalogue_ids("revolute")  # both are tried there: the data choose


@pytest.mark.parametrize("t", [0.0, 0.25, 3.0, 17.5, 60.0])
def test_compiled_drift_is_the_definition(t: float) -> None:
    values = {"dFv": -66.5, "dFc": 1.5, "tau": 7.0, "Fv_rate": 0.25, "Fc_rate": -0.125}
    eff = make_effects({"friction_drift": values})
    p = plant_vector(RigidParameters(95.0, 200.0, 20.0, 0.0), eff)
    base = np.array([p[P_FV_POS], p[P_FV_NEG], p[P_FC_POS], p[P_FC_NEG]])
    q = p.copy()
    kernel._drifted(q, base, t)
    dfv = fx.drift_of(t, -66.5, 7.0, 0.25)
    dfc = fx.drift_of(t, 1.5, 7.0, -0.125)
    assert q[P_FV_POS] == pytest.approx(200.0 + dfv, rel=1e-14) and q[P_FV_NEG] == pytest.approx(200.0 + dfv, rel=1e-14)
    assert q[P_FC_POS] == pytest.approx(max(20.0 + dfc, 0.0), rel=1e-14, abs=1e-14)
    # force_model's friction at the same instant, sliding forwards at 0.1 m/s with no acceleration
    tau = force_model(RigidParameters(95.0, 200.0, 20.0, 0.0), eff, np.array([0.0]), np.array([0.1]), np.array([0.0]), np.array([t]))
    assert tau[0] == pytest.approx((200.0 + dfv) * 0.1 + max(20.0 + dfc, 0.0), rel=1e-13)


def test_drift_law_warms_up_exponentially_and_wears_linearly() -> None:
    t = np.array([0.0, 5.0, 1e6])
    np.testing.assert_allclose(fx.drift_of(t, -60.0, 5.0, 0.0), [0.0, -60.0 * (1 - math.exp(-1.0)), -60.0])
    np.testing.assert_allclose(fx.drift_of(t, 0.0, 5.0, 0.2), 0.2 * t)
    with pytest.raises(fx.ParameterError, match="friction_drift.tau"):
        EFFECTS["friction_drift"].values({"tau": 0.0})
    assert "friction_drift" in fx.plant_ids() and not EFFECTS["friction_drift"].identifiable


def test_a_vertical_axis_constant_force_is_a_weight() -> None:
    assert runlog.vertical({"vertical": True}) and runlog.vertical({"orientation": "Vertical"}) and runlog.vertical({"axis_vertical": "yes"})
    assert not runlog.vertical({}) and not runlog.vertical({"vertical": False})
    w = parameters.weight(117.68, 0.49)
    assert w["weight"] == (117.68, 0.49, "N")
    assert w["implied_mass"][0] == pytest.approx(12.0, rel=1e-4) and w["implied_mass"][1] == pytest.approx(0.05, rel=1e-3) and w["implied_mass"][2] == "kg"
