"""A held-out fold whose fit is no plant of an effect is left out of the replay's judgement, and said (issue 29).

A fold's fit of a flexibility can put the load's inertia above the axis's (a load fraction outside (0, 1)). Its plant then
had no flexibility: ``model_parameters`` leaves out an effect that is no plant, and the fold was replayed as the rigid
model while the verdict spoke of the flexibility (16 logs of the robot corpus's two seed sets; rev0.5 s721 in two of its
five folds). Now such a fold is left out of both sides of the comparison, and the reason says so; fewer than
:data:`~ilic_cli.diagnosis.fold_plant.MIN_PLANT_FOLDS` folds left, no replay judges.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.fold_plant import MIN_PLANT_FOLDS, fold_fit, not_a_plant
from ilic_cli.diagnosis.heldout_replay import HeldoutReplays, _heldout_pct
from ilic_cli.diagnosis.model_values import model_parameters
from ilic_cli.diagnosis.propose import prepare_system
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.diagnosis.system import Step, moving_rows
from ilic_cli.effects import EFFECTS
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import get_model
from ilic_cli.usable import with_rest
from tests.corpus import robot

FLEX = EFFECTS["flexibility"]


def test_a_load_above_the_axis_is_no_plant() -> None:
    names = ("M", "Fv", "Fc", "offset", "M_load")
    step = Step(FLEX, (33.0, 0.13))
    assert not_a_plant([step], names, np.array([0.5, 0.8, 1.5, 0.0, 0.45])) == []
    assert not_a_plant([step], names, np.array([0.5, 0.8, 1.5, 0.0, 0.56])) == ["flexibility"]  # load fraction 1.12
    assert not_a_plant([step], names, np.array([0.5, 0.8, 1.5, 0.0, -0.1])) == ["flexibility"]
    assert MIN_PLANT_FOLDS == 3


def test_the_pairs_leave_out_the_same_samples_on_both_sides() -> None:
    nan = np.nan
    current = (np.array([1.0, 2.0, 3.0, 4.0]), np.array([1.0, 1.0]), [None, None])
    after = (np.array([0.5, nan, nan, 2.0]), np.array([nan, 0.5]), [None, None])
    c, a, left = HeldoutReplays.paired(current, after)
    assert left == 0.5 and np.isnan(c[0][1:3]).all() and np.isnan(c[1][0]) and c[0][0] == 1.0
    ref, idx = np.array([10.0, 10.0, 10.0, 10.0]), np.arange(4)
    assert _heldout_pct(a[0], ref, idx) == pytest.approx(100 * np.hypot(0.5, 2.0) / np.hypot(10.0, 10.0))
    assert HeldoutReplays.paired(current, current)[2] == 0.0


def test_rev05_s721_s_flexibility_is_judged_on_its_plant_folds() -> None:
    """The corpus's 1 kHz flexible elbow: at a resonance of 42 Hz, lightly damped, two of the five folds put the load above
    the axis. (Before the Coulomb column was the expected sign of the noisy velocity, the selection's 33.34 Hz did; now every
    fold's fit there is a plant, and the mechanism is held on a value where some are not.)"""
    case = robot.case_named("rev0.5/multisine/1000Hz/sensor/stribeck+flexibility/s721")
    built = robot.build(case)
    ls = DiagnosisSettings().ls.at_rate(built.log.fs_hz)
    base = get_model("rigid-offset")
    data = prepare_system(with_rest(prepare_log(built.log), ls), base, ls)
    rows = moving_rows(data)
    step = Step(FLEX, (42.0, 0.05))

    def plant_of(steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> tuple[dict[str, float], dict[str, object]]:
        return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))))

    replays = HeldoutReplays(built.log, data, base, rows, plant_of, 5, {})
    bad = [i for i, train in enumerate(replays.trains) if not_a_plant([step], *fold_fit(data, base, [step], rows, train)[:2])]
    assert len(bad) == 2, bad
    rigid, flexible = replays.heldout([]), replays.heldout([step])
    assert rigid is not None and flexible is not None
    assert np.isfinite(rigid[0]).all() and np.isnan(flexible[0]).mean() == pytest.approx(0.4, abs=0.05)
    assert [u is None for u in flexible[2]] == [i in bad for i in range(5)]


def test_a_candidate_that_diverges_in_the_recordings_loop_is_no_plant_and_a_users_replay_is_an_error() -> None:
    """A fold's candidate plant whose replay diverges (here a 12 kg axis modelled as 1 g under its 10 Hz loop) is refuted by it:
    no replay (``None``, an infinite training error), where it stopped the diagnosis with an error (corpus s9722). A replay asked
    for, and any other simulation error, still raise."""
    from ilic_cli.diagnosis.heldout_replay import _replayed_plant
    from ilic_cli.errors import DivergedError, SimulationError
    from ilic_cli.simulation.replay import replay

    log = robot.simulate(robot.Case("lin12", "s-curve", 1000.0, "sensor", 1), {})
    unstable = {"M": 1e-3, "Fv": 35.0, "Fc": 4.0}
    assert _replayed_plant(log, (unstable, {}), {}) is None
    with pytest.raises(DivergedError, match="the closed loop diverged"):
        replay(log, unstable, {}, seed=0)
    assert issubclass(DivergedError, SimulationError)  # a command's replay: one line, exit 2, as before
    stable = _replayed_plant(log, ({"M": 12.0, "Fv": 35.0, "Fc": 4.0}, {}), {})
    assert stable is not None and np.isfinite(stable["tau"]).all()
