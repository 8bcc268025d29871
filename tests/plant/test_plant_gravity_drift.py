"""The plant simulates gravity on a revolute link and friction that drifts: its force is the inverse dynamics of its motion (issue 29)."""

from __future__ import annotations

import numpy as np

from ilic_cli.effects import make_effects
from plant.dynamics import RigidParameters, force_model
from tests.corpus import REVOLUTE_JOINTS, Case, revolute_log, simulate_case


def _sliding(qd: np.ndarray) -> np.ndarray:
    return np.abs(qd) > 1e-6


def test_a_revolute_link_with_gravity_is_driven_by_its_inverse_dynamics() -> None:
    """With a noise-free sensor, the held command at each sample is the torque of the plant's own state then (``qdd`` just after)."""
    gravity = {"MX": 0.006, "MY": 0.003}
    log = revolute_log("small", {"gravity": gravity}, seed=3, duration_s=6.0, sensor=False)
    assert log.units["q"] == "rad" and log.units["tau"] == "N·m"
    q, qd, qdd = log["q"], log["qd_plant"], log["qdd_plant"]
    tau = force_model(RigidParameters(**REVOLUTE_JOINTS["small"]), make_effects({"gravity": gravity}), q, qd, qdd, log.t)
    s = _sliding(qd)
    assert s.mean() > 0.9 and np.ptp(q) > 2.0  # the link swings through more than 2 rad: gravity's cosine is not a constant
    np.testing.assert_allclose(tau[s], log["tau"][s], rtol=0, atol=1e-9 * np.abs(log["tau"]).max())
    # without gravity in the model the same motion needs other torques: the term is there
    bare = force_model(RigidParameters(**REVOLUTE_JOINTS["small"]), {}, q, qd, qdd, log.t)
    assert np.abs(bare[s] - log["tau"][s]).max() > 0.05


def test_friction_that_warms_up_is_simulated() -> None:
    """The plant's friction follows ``friction_drift`` in time: the command equals the drifting inverse dynamics (at each period's middle)."""
    drift = {"dFv": -200.0 / 3.0, "tau": 6.0}
    log = simulate_case(Case("warm-up", "paper", "sensor", 5), {"friction_drift": drift})
    truth = log.meta["true_parameters"]
    assert log.meta["effects"]["friction_drift"]["dFv"] == drift["dFv"]
    qd, qdd = log["qd_plant"], log["qdd_plant"]
    T = 1.0 / log.fs_hz
    eff = make_effects({"friction_drift": drift})
    q = log["q"]  # the position does not enter the rigid axis's force
    tau = force_model(RigidParameters.from_dict(truth), eff, q, qd, qdd, log.t + T / 2)
    s = _sliding(qd)
    np.testing.assert_allclose(tau[s], log["tau"][s], rtol=0, atol=1e-6 * np.abs(log["tau"]).max())
    # and it differs from the stationary plant by the warm-up: at the end, Fv is two thirds of its start
    still = force_model(RigidParameters.from_dict(truth), {}, q, qd, qdd, log.t)
    late = s & (log.t > 25.0) & (np.abs(qd) > 0.05)
    ratio = (log["tau"][late] - truth["M"] * qdd[late] - truth["Fc"] * np.sign(qd[late])) / qd[late]
    np.testing.assert_allclose(ratio, 200.0 + drift["dFv"] * (1 - np.exp(-(log.t[late] + T / 2) / 6.0)), rtol=1e-6)
    assert np.abs(still[late] - log["tau"][late]).max() > 5.0


def test_score_compares_a_drift_by_its_shape_parameters() -> None:
    from tests.corpus import parameter_error, score

    warm = Case("warm-up", "paper", "sensor", 5, {"friction_drift": {"dFv": -66.7, "dFc": 0.0, "tau": 6.0, "Fv_rate": 0.0, "Fc_rate": 0.0}})
    found = {"dFv": -71.5, "dFc": 0.0, "tau": 5.96, "Fv_rate": 0.0, "Fc_rate": 0.0}
    assert parameter_error("friction_drift", found, warm) == np.float64(abs(-71.5 + 66.7) / 66.7)
    wear = Case("wear", "paper", "sensor", 7, {"friction_drift": {"dFv": 0.0, "dFc": 0.0, "tau": 10.0, "Fv_rate": 0.0, "Fc_rate": 0.2}})
    linear = {"dFv": 0.0, "dFc": 0.0, "tau": 1.0, "Fv_rate": 0.0, "Fc_rate": 0.197}  # the found tau is no part of a linear drift
    assert abs(parameter_error("friction_drift", linear, wear) - 0.015) < 1e-12
    assert score(wear, [("friction_drift", linear)])["false_alarms"] == 0
    gravity = Case("g", "paper", "sensor", 1, {"gravity": {"MX": 0.006, "MY": 0.003}})
    assert abs(parameter_error("gravity", {"MX": 0.0063, "MY": 0.003}, gravity) - 0.05) < 1e-12
