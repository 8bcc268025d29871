"""``ilic identify --urdf --method all``: IDIM-IV and DIDIM from the command line beat IDIM-LS on a log with large position noise (issue 30).

The log is the library test's (tests/robot/test_closed_loop.py): the 6-joint
arm under a per-joint PD with a rough model's feed-forward, 10 s at 1 kHz, 1 mrad
of position noise. Here it is written as a wide CSV that records its loop
(``meta["controller"]``: kind, settings, the controller's model), and the
command replays that loop.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.cli import main  # noqa: E402
from ilic_cli.idim_ls import LSSettings  # noqa: E402
from ilic_cli.io import jointlogs  # noqa: E402
from ilic_cli.jointlog import JointLog  # noqa: E402
from ilic_cli.robot.base import base_parameters  # noqa: E402
from ilic_cli.robot.idim import ROBOT_BAND_HZ, idim_ls  # noqa: E402
from ilic_cli.robot.model import load_urdf  # noqa: E402
from ilic_cli.robot.plant import LoopRun, LoopSettings, simulate_loop  # noqa: E402
from ilic_cli.robot.replay import SampledReference, controller_meta, replay_loop  # noqa: E402
from ilic_cli.robot.scenario import initial_model, true_parameters  # noqa: E402
from ilic_cli.robot.simulate import exciting_trajectory  # noqa: E402

UR5 = Path(__file__).parents[2] / "fixtures" / "ur5like.urdf"
TORQUE_NOISE = (0.3, 0.3, 0.2, 0.05, 0.05, 0.05)


def _log(robot: object, run: LoopRun, meta: dict[str, object]) -> JointLog:
    r = robot
    return JointLog(
        t=run.t, joints=r.joints, kinds=r.kinds, q=run.q.T.copy(), tau=run.tau.T.copy(),  # type: ignore[attr-defined]
        q_ref=run.q_ref.T.copy(), qd_ref=run.qd_ref.T.copy(), qdd_ref=run.qdd_ref.T.copy(), meta=meta,
    )  # fmt: skip


def test_identify_iv_and_didim_beat_idim_ls_under_large_position_noise(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robot = load_urdf(UR5)
    pi = true_parameters(robot)
    traj = exciting_trajectory(np.array([0.0, -1.2, 1.2, -1.5, -1.5, 0.0]), np.array([1.5, 2.0, 2.0, 2.0, 2.0, 2.5]), seed=1)
    model = initial_model(robot, 0.2)
    loop = LoopSettings(controller="pd", position_noise=(1e-3,) * 6, torque_noise=TORQUE_NOISE, seed=3)
    noisy = simulate_loop(robot, pi, traj, 10.0, model, loop)
    meta = {"controller": controller_meta(loop, [model]), "torque_held": True, "true_parameters": dict(zip(robot.names, pi.tolist()))}
    path = tmp_path / "noisy.csv"
    jointlogs.write(_log(robot, noisy, meta), path)
    # the recorded loop replayed with the true plant gives the logged torque but for its noise
    replayed = replay_loop(robot, pi, SampledReference(noisy.q_ref, noisy.qd_ref, noisy.qdd_ref), 1000.0, meta["controller"], robot.standard)
    assert np.std(noisy.tau - replayed.tau, axis=0) == pytest.approx(TORQUE_NOISE, rel=0.05)

    with pytest.raises(SystemExit) as exc:
        main(["identify", str(path), "--urdf", str(UR5), "--method", "all", "--max-iterations", "2", "--tolerance", "1", "--format", "json"])
    out, err = capsys.readouterr()
    assert exc.value.code == 0, err
    doc = json.loads(out)
    truth = doc["true_base_parameters"]
    # the parameters this loop determines: %sigma < 1 on the same log without the position noise (22 of 58)
    clean = simulate_loop(robot, pi, traj, 10.0, model, LoopSettings(controller="pd", torque_noise=TORQUE_NOISE, seed=3))
    base = base_parameters(robot)
    fit = idim_ls(clean.q, clean.tau, 1000.0, robot, base, LSSettings(cutoff_hz=50.0, trim=100, band_hz=ROBOT_BAND_HZ), min_speed=0.2, torque_held=True)
    well = [n for n, r in zip(base.names, fit.rel_std_pct) if r < 1.0]
    assert len(well) >= 15

    def errors(method: str) -> np.ndarray:
        p = doc["methods"][method]["parameters"]
        return np.array([100.0 * abs(p[n]["value"] - truth[n]) / abs(truth[n]) for n in well])

    ls = errors("IDIM-WLS")
    assert np.median(ls) > 5.0  # the differentiated noisy position biases IDIM-LS
    for method, factor in (("IDIM-IV", 4.0), ("DIDIM", 10.0)):
        e = errors(method)
        assert np.median(e) * factor < np.median(ls) and e.max() * factor < ls.max(), (method, np.median(e), e.max(), np.median(ls), ls.max())
        m = doc["methods"][method]
        assert len(m["iterations"]) == 3 and {f"{f}_shoulder_pan_joint" for f in ("Fv", "Fc", "offset")} <= set(m["friction"])


def test_closed_loop_methods_need_the_loop(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    robot = load_urdf(UR5)
    run = simulate_loop(
        robot, true_parameters(robot), exciting_trajectory(np.zeros(6), np.full(6, 1.0), seed=2), 0.5, robot.standard, LoopSettings(controller="pd")
    )
    path = tmp_path / "bare.csv"
    jointlogs.write(_log(robot, run, {}), path)
    for extra, needle in (([], "records no controller"), (["--controller", "pd", "--kp", "3"], "--kp")):
        with pytest.raises(SystemExit) as exc:
            main(["identify", str(path), "--urdf", str(UR5), "--method", "didim", *extra])
        out, err = capsys.readouterr()
        assert exc.value.code == 2 and out == "" and err.count("\n") == 1 and err.startswith("ilic: error: ") and needle in err, err
