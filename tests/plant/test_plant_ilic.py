"""Online IDIM-ILIC in the loop: payload change (section VI-G) and loss of excitation (section V-E)."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.errors import ParameterError
from ilic_cli.simulation.online import ilic_update
from ilic_cli.simulation.scenarios import Overrides, run_scenario
from plant.closed_loop import LoopWindow, simulate_loop
from plant.controllers import CTCSettings
from plant.dynamics import RigidParameters
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
    res = simulate_loop(
        q_r=q_r,
        qd_r=qd_r,
        qdd_r=qdd_r,
        qd_log=qd_c,
        qdd_log=qdd_c,
        params=RigidParameters(95, 200, 20),
        effects={},
        controller=CTCSettings(),
        update=ilic_update,
    )
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


def test_the_loop_hands_each_full_window_to_the_update_it_is_given() -> None:
    """The plant knows no estimator: a CTC with ``ilic`` needs an update; the update sees every full window and its parameters are used."""
    traj = exciting_cycle(t_offset=0.0)
    n = 500  # two full windows of 0.2 s and half a window
    _, q_r, qd_r, qdd_r = traj.sample(n, 1000.0)
    ctl = CTCSettings(window_s=0.2)
    kw = dict(q_r=q_r, qd_r=qd_r, qdd_r=qdd_r, params=RigidParameters(95, 200, 20), effects={}, controller=ctl)
    with pytest.raises(ParameterError, match="online update"):
        simulate_loop(**kw)
    seen: list[LoopWindow] = []

    class Record:
        def __init__(self, k: int) -> None:
            self.k = k

        def to_dict(self) -> dict[str, int]:
            return {"k": self.k}

    def update(chi: np.ndarray, window: LoopWindow) -> tuple[np.ndarray, Record]:
        seen.append(window)
        return chi + 1.0, Record(window.k)

    res = simulate_loop(**kw, update=update)
    assert [w.k for w in seen] == [1, 2] and [r.k for r in res.windows] == [1, 2]
    assert [(w.t[0], len(w.t)) for w in seen] == [(0.0, 200), (0.2, 200)]
    np.testing.assert_array_equal(seen[1].q, res.q[200:400])
    np.testing.assert_array_equal(seen[1].q_ref, q_r[200:400])
    m0 = ctl.initial()["M"]
    assert res.chi[199, 0] == m0 and res.chi[200, 0] == m0 + 1.0 and res.chi[499, 0] == m0 + 2.0
