"""A PD law inside the simulator's dynamics (its ODE's right-hand side), read from the recording (:mod:`ilic_cli.diagnosis.loop_read`).

The independent simulator's ``"continuous"`` loop (:mod:`tests.corpus.independent`, 40 Euler steps a period) evaluates the law on
its state at every step and logs it at the samples. Read as the discrete loop fed the state, the inverse model's half-period hold
mistimed its force: a drive lag came out half a period short, and clean chirps got a viscous friction rising with the chirp's
frequency (corpus, 12 kg axis, 500 Hz: +6.7 %, named a drift).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.report import to_markdown
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.pd_law import CLEAR_GAIN
from tests.corpus.independent import run_loop
from tests.logs.test_rates import AXES, reference


def _log(name: str, fs_hz: float, effects: dict[str, dict[str, float]], seed: int) -> RunLog:
    _, q_ref = reference(AXES[name], fs_hz)
    return run_loop(AXES[name], fs_hz, q_ref, "continuous", effects, seed, name, 40)


def test_a_law_inside_the_dynamics_is_read_and_a_chirp_stays_clean() -> None:
    """The robot corpus's 12 kg axis on its chirp at 500 Hz (benchmarks/corpus_independent.py's case): read as held, a drift of
    Fv was named; read inside the dynamics (its replay's force error 0.08 of the held law's), nothing."""
    from tests.corpus.robot import AXES as ROBOT_AXES
    from tests.corpus.robot import reference as robot_reference

    axis = ROBOT_AXES["lin12"]
    _, q_ref = robot_reference(axis, "chirp", 500.0, 7, 10.0)
    diag = diagnose(run_loop(axis, 500.0, q_ref, "continuous", {}, 7, "lin12", 40), settings=DiagnoseSettings())
    timing = diag.timing
    assert timing is not None and timing.continuous and timing.refined["force"] < CLEAR_GAIN * timing.held["force"], timing
    assert diag.findings == []
    text = to_markdown(diag)
    assert "the law inside the dynamics, on the plant's state at every integration step" in text and "a drive lag this short" not in text
    assert diag.to_dict()["timing"]["continuous"] is True


def test_a_drive_lag_beside_a_law_inside_the_dynamics_is_whole() -> None:
    """A 1.5 ms actuator delay at 1 kHz: -1.52 ms (read as held: -1.12 ms, the hold's half period taken off it)."""
    diag = diagnose(_log("linear", 1000.0, {"delay": {"delay": 0.0015}}, 18), settings=DiagnoseSettings())
    assert diag.timing is not None and diag.timing.continuous
    (f,) = diag.findings
    assert f.effect.id == "delay" and f.parameters["delay"].value == pytest.approx(-0.0015, rel=0.05)
    assert np.isfinite(diag.timing.held["force"])
    assert f.if_inside == {} and "if_the_pd_law_acts_inside_the_dynamics" not in f.to_dict()  # taken inside: nothing to add


def test_a_drive_lag_read_as_held_says_the_lag_of_a_law_inside_the_dynamics() -> None:
    """The robot corpus's 12 kg axis on its chirp at 1 kHz (``benchmarks/corpus_independent.py``'s case), the law inside the
    dynamics with a 1.5 ms lag: the two loops' replays differ by less than the reading's margin (force error ratio 3.4, the held
    law's lag found 1.04 ms), so the replays hold the command, and the finding says the lag the other loop gives: 1.54 ms, typed
    and in words (``diagnosis.loop_read.lag_if_inside``)."""
    from tests.corpus.robot import AXES as ROBOT_AXES
    from tests.corpus.robot import reference as robot_reference

    axis = ROBOT_AXES["lin12"]
    _, q_ref = robot_reference(axis, "chirp", 1000.0, 7, 10.0)
    diag = diagnose(run_loop(axis, 1000.0, q_ref, "continuous", {"delay": {"delay": 0.0015}}, 7, "lin12", 40), settings=DiagnoseSettings())
    assert diag.timing is not None and not diag.timing.continuous
    (f,) = diag.findings
    held, inside = f.parameters["delay"].value, f.if_inside["delay"]
    assert inside == pytest.approx(held - 0.0005) and inside == pytest.approx(-0.0015, rel=0.05), (held, inside)
    assert f.to_dict()["if_the_pd_law_acts_inside_the_dynamics"] == {"delay": inside}
    assert f"the lag is half a period longer, {-1e3 * inside:.3g} ms" in to_markdown(diag)


def test_identify_reads_the_law_inside_the_dynamics() -> None:
    """``identify --method ls`` takes the force at a sample as the force there when the law acts inside the dynamics: the robot
    corpus's 0.5 kg·m² joint on its 500 Hz trapezoid within 0.2 % (with the half-period hold, Fc 3.2 % off); the discrete loop fed
    the state keeps the hold, and is not read so (its replays do not halve)."""
    from ilic_cli.identify import LAW_INSIDE, identify
    from tests.corpus.robot import AXES as ROBOT_AXES
    from tests.corpus.robot import reference as robot_reference

    axis = ROBOT_AXES["rev0.5"]
    _, q_ref = robot_reference(axis, "trapezoid", 500.0, 7, 10.0)
    for loop, inside in (("continuous", True), ("state", False)):
        report = identify(run_loop(axis, 500.0, q_ref, loop, {}, 7, "rev0.5", 40), method="ls")
        assert report.ls is not None
        est = dict(zip(report.ls.result.names, report.ls.result.theta, strict=True))
        assert all(abs(est[k] / axis.truth[k] - 1.0) < 0.005 for k in ("M", "Fv", "Fc")), (loop, est)
        assert (f"loop: {LAW_INSIDE}" in report.warnings) is inside
        assert report.usable.hold_s == (0.0 if inside else 0.5 / 500.0)


def test_replay_reads_the_law_inside_the_dynamics(tmp_path: Path) -> None:
    """``ilic replay`` of such a log (a CSV with its loop declared by flags) with the true model: it tries the law inside the dynamics
    beside the held one and runs it (force error 3.2 % -> 0.12 %), as the diagnosis and ``identify`` do."""
    import json

    import pandas as pd

    from ilic_cli.modelfile import model_document
    from tests.clirun import run_cli

    axis = AXES["linear"]
    log = _log("linear", 500.0, {}, 21)
    csv, model, out = tmp_path / "run.csv", tmp_path / "model.json", tmp_path / "replayed.csv"
    pd.DataFrame({k: log[k] for k in ("t", "q", "q_ref", "tau")}).to_csv(csv, index=False)
    model.write_text(json.dumps(model_document("rigid", {k: axis.truth[k] for k in ("M", "Fv", "Fc")}, method="truth")))
    kp, kv = axis.gains()
    res = run_cli("replay", str(csv), "--model", str(model), "--controller", "pd", "--kp", str(kp), "--kv", str(kv), "--drive-gain", "10", "-o", str(out))
    assert res.status == 0, res.stderr
    assert "ilic: loop: the law inside the dynamics" in res.stderr
    force = float(res.stderr.split("force error ")[-1].split(" %")[0])
    assert force < 0.5, res.stderr
