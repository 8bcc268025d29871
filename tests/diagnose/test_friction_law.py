"""The friction law near zero speed that the replays run, read from the recording (:mod:`ilic_cli.diagnosis.friction_law`).

Logs of the independent simulator (:mod:`tests.corpus.independent`: the textbook PD loop at its sample) whose Coulomb friction is
``Fc tanh(v / eps)``, without stiction, as simulators often write it. Replayed with the plant's stick/slip the replays held where the
recording crept: a 1.5 ms drive lag the inverse model found exactly was rejected by the replay (held-out 4.24 % -> 4.26 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.friction_law import SMOOTHING, FrictionLaw, with_friction_law
from ilic_cli.diagnosis.report import to_markdown
from ilic_cli.simulation.replay import replay
from tests.corpus.independent import run_loop, simulate
from tests.corpus.robot import AXES as ROBOT_AXES
from tests.corpus.robot import reference
from tests.logs.test_rates import AXES

EPS = 0.0025
"""The simulator's smoothing speed on the 12 kg axis (m/s): a hundredth of its top speed, 0.25 m/s."""


def test_a_smoothed_law_is_read_and_replayed_and_is_no_finding() -> None:
    """A clean log: the inverse model proposes the law (vc 2.76 mm/s for 2.5), the replay keeps it (position error 0.0072 % ->
    0.0012 %, force 5.78 % -> 5.48 %); the report says it with the control timing, and nothing is a finding."""
    diag = diagnose(simulate("linear", 1000.0, "same", {}, 18, smooth_speed=EPS), settings=DiagnoseSettings())
    law = diag.friction_law
    assert law is not None and law.vc == pytest.approx(EPS, rel=0.2) and law.p_value is not None and law.p_value < 1e-6, law
    assert law.after["position"] < 0.5 * law.before["position"] and law.after["force"] < law.before["force"], law
    assert diag.findings == []
    assert "Friction near zero speed: smooth near zero speed, Coulomb friction Fc tanh(qd/vc) with vc = " in to_markdown(diag)
    assert diag.to_dict()["friction_law"]["law"] == "smoothed Coulomb" and diag.to_dict()["friction_law"]["vc"] == law.vc
    assert diag.model_file["effects"] == {SMOOTHING: {"vc": law.vc}}  # ilic replay of the model file runs the law too


def test_a_drive_lag_beside_a_smoothed_law_is_named() -> None:
    """The robot corpus's 12 kg axis on its 10 s trapezoid at 1 kHz (``benchmarks/corpus_independent.py``'s case) with a 1.5 ms
    drive lag: the inverse model finds the lag (-1.5025 ms) and proposes no law (the rows leave out the samples near rest); the
    closed loop finds the law (its model with the lag), and the replay keeps the lag. Replayed with stick/slip the lag was
    rejected: held-out simulated force error 4.24 % -> 4.26 %, the folds' lags -0.10 to -0.006 ms."""
    axis = ROBOT_AXES["lin12"]
    _, q_ref = reference(axis, "trapezoid", 1000.0, 7, 10.0)
    log = run_loop(axis, 1000.0, q_ref, "same", {"delay": {"delay": 0.0015}}, 7, "lin12", 40, smooth_speed=0.01 * axis.speed)
    diag = diagnose(log, settings=DiagnoseSettings())
    law = diag.friction_law
    assert law is not None and law.vc is not None and law.p_value is None and "tried on the closed loop" in law.reason, law
    (f,) = diag.findings
    assert f.effect.id == "delay" and f.parameters["delay"].value == pytest.approx(-0.0015, rel=0.05)


def test_every_replay_of_the_log_runs_the_law_unless_the_model_states_its_own() -> None:
    log = simulate("linear", 1000.0, "same", {}, 5, smooth_speed=EPS)
    params = {k: AXES["linear"].truth[k] for k in ("M", "Fv", "Fc")}
    read = with_friction_law(log, FrictionLaw(EPS))
    np.testing.assert_array_equal(replay(read, params, {})["q"], replay(log, params, {SMOOTHING: {"vc": EPS}})["q"])
    np.testing.assert_array_equal(replay(read, params, {SMOOTHING: {"vc": 2 * EPS}})["q"], replay(log, params, {SMOOTHING: {"vc": 2 * EPS}})["q"])
    assert not np.array_equal(replay(read, params, {})["q"], replay(log, params, {})["q"])
    assert with_friction_law(log, FrictionLaw(None)) is log
