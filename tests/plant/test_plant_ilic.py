"""Online IDIM-ILIC in the loop: payload change (section VI-G) and loss of excitation (section V-E)."""

from __future__ import annotations

import numpy as np
import pytest

from plant.closed_loop import simulate_loop
from plant.controllers import CTCSettings
from plant.dynamics import RigidParameters
from plant.scenarios import Overrides, run_scenario
from plant.trajectories import T_CYCLE, exciting_cycle, with_constant_velocity


def test_payload_change_followed_within_two_windows() -> None:
    log = run_scenario("paper-payload", Overrides(duration_s=6.2 * 14))
    wins = log.meta["ilic_windows"]
    t_change = log.meta["effects"]["payload_change"]["t_change"]
    before = [w for w in wins if w["t_end"] < t_change]
    k_change = next(w["k"] for w in wins if w["t_end"] >= t_change)  # the window holding the change
    after = [w for w in wins if w["k"] >= k_change + 2]
    m_before = before[-1]["parameters"]["M"]["value"]
    assert after, "simulate long enough to see two windows after the change"
    for w in after:
        assert w["parameters"]["M"]["value"] - m_before == pytest.approx(10.0, abs=0.5)
    # the controller uses it: M_hat channel after the update
    i = int(round(after[0]["t_end"] * 1000)) + 1
    assert log["M_hat"][i] - m_before == pytest.approx(10.0, abs=0.5)


def test_loss_of_excitation_keeps_parameters_and_stays_stable() -> None:
    traj = with_constant_velocity(exciting_cycle(t_offset=0.0), cycles_before=2, v=0.05, hold_s=T_CYCLE + 0.3, cycles_after=1)
    n = int(round(6.2 * 5 * 1000))
    _, q_r, qd_r, qdd_r = traj.sample(n, 1000.0)
    _, _, qd_c, qdd_c = traj.sample_centred(n, 1000.0)
    res = simulate_loop(q_r=q_r, qd_r=qd_r, qdd_r=qdd_r, qd_log=qd_c, qdd_log=qdd_c, params=RigidParameters(95, 200, 20), effects={}, controller=CTCSettings())
    wins = res.windows
    # window 4 = [18.6, 24.8) s: constant velocity only
    lost = wins[3]
    a, b = int(6.2 * 3 * 1000), int(6.2 * 4 * 1000)
    assert np.all(qdd_r[a:b] == 0.0) and np.all(qd_r[a:b] == 0.05)
    assert not lost.essential[0], "the mass is not excited: its estimate must not be essential"
    assert "M" in lost.note or "rank" in lost.note
    # the controller keeps the previous mass (and every non-essential parameter)
    before = res.chi[b - 1]
    after = res.chi[b]
    assert after[0] == before[0]
    np.testing.assert_array_equal(after[~lost.essential], before[~lost.essential])
    # stable: tracking error stays as small as in the exciting windows
    e = np.abs(q_r - res.q)
    assert e[a:].max() < 5 * e[int(6.2 * 1000) : a].max()
    assert e.max() < 1e-3
