"""Issue 30's Done-when: IDIM-IV and DIDIM through the n-joint closed loop beat IDIM-LS on a log with large position noise.

The 6-joint arm under a per-joint PD with the feed-forward of a rough model
(the URDF's inertias, rotor inertias guessed): 10 s at 1 kHz, 1 mrad of white
noise on the logged positions (the loop sees the encoders), torque noise. Each
iteration simulates the same loop with the plant of the last estimate.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.closed_loop_id import ClosedLoopSettings  # noqa: E402
from ilic_cli.errors import ParameterError  # noqa: E402
from ilic_cli.idim_ls import LSSettings  # noqa: E402
from ilic_cli.robot.base import base_parameters  # noqa: E402
from ilic_cli.robot.closed_loop import closed_loop_identify  # noqa: E402
from ilic_cli.robot.dynamics import kept_vector  # noqa: E402
from ilic_cli.robot.idim import ROBOT_BAND_HZ, idim_ls  # noqa: E402
from ilic_cli.robot.model import load_urdf  # noqa: E402
from ilic_cli.robot.plant import LoopSettings, simulate_loop  # noqa: E402
from ilic_cli.robot.scenario import initial_model, true_parameters  # noqa: E402
from ilic_cli.robot.simulate import exciting_trajectory  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"
DURATION = 10.0
TORQUE_NOISE = (0.3, 0.3, 0.2, 0.05, 0.05, 0.05)
LS = LSSettings(cutoff_hz=50.0, trim=100, band_hz=ROBOT_BAND_HZ)


def test_iv_and_didim_beat_idim_ls_under_large_position_noise() -> None:
    robot = load_urdf(FIXTURES / "ur5like.urdf")
    base = base_parameters(robot)
    pi = true_parameters(robot)
    beta = base.values(pi)
    traj = exciting_trajectory(np.array([0.0, -1.2, 1.2, -1.5, -1.5, 0.0]), np.array([1.5, 2.0, 2.0, 2.0, 2.0, 2.5]), seed=1)
    model = initial_model(robot, 0.2)
    noisy = simulate_loop(robot, pi, traj, DURATION, model, LoopSettings(controller="pd", position_noise=(1e-3,) * 6, torque_noise=TORQUE_NOISE, seed=3))
    clean = simulate_loop(robot, pi, traj, DURATION, model, LoopSettings(controller="pd", torque_noise=TORQUE_NOISE, seed=3))
    # the parameters this log determines (%sigma < 1 without the position noise): 22 of 58
    well = idim_ls(clean.q, clean.tau, 1000.0, robot, base, LS, min_speed=0.2, torque_held=True).rel_std_pct < 1.0
    assert well.sum() >= 15

    def errors(theta: np.ndarray) -> np.ndarray:
        return 100.0 * np.abs(theta - beta)[well] / np.abs(beta[well])

    def simulate(b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        run = simulate_loop(robot, kept_vector(base.kept, b, len(pi)), traj, DURATION, model, LoopSettings(controller="pd"))
        return run.q, run.tau

    ls = errors(idim_ls(noisy.q, noisy.tau, 1000.0, robot, base, LS, min_speed=0.2, torque_held=True).theta)
    assert np.median(ls) > 5.0  # the noise of the differentiated position biases IDIM-LS (17 % median measured)
    settings = ClosedLoopSettings(max_iterations=2, tolerance_pct=1.0)
    for method, factor in (("iv", 4.0), ("didim", 10.0)):
        res = closed_loop_identify(method, noisy.q, noisy.tau, 1000.0, robot, base, simulate, LS, settings, min_speed=0.2, torque_held=True)
        e = errors(res.theta)
        # measured: IV 1.7 % median (14.7 % max), DIDIM 0.29 % (2.3 %), against 16.7 % (191 %) for IDIM-LS
        assert np.median(e) * factor < np.median(ls) and e.max() * factor < ls.max(), (method, np.median(e), e.max())
        assert res.method == {"iv": "IDIM-IV", "didim": "DIDIM"}[method] and res.history[0][0] == 0 and len(res.history) >= 2
        assert res.to_dict()["parameters"][base.names[0]]["value"] == pytest.approx(res.theta[0])
    with pytest.raises(ParameterError):
        closed_loop_identify("oe", noisy.q, noisy.tau, 1000.0, robot, base, simulate, LS)
