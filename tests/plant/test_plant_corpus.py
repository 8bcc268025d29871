"""The plant pieces of the diagnosis corpus (issue #11): disturbance, current loop, trajectories, corpus cases."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.effects import make_effects
from ilic_cli.errors import ParameterError
from ilic_cli.io import read_log
from plant.closed_loop import simulate_loop
from plant.controllers import OpenLoopSettings
from plant.dynamics import RigidParameters
from plant.sensors import draw_disturbance, draw_noise
from plant.trajectories import make_trajectory, multisine, trapezoid_moves
from tests.clirun import run_cli

FS = 1000.0


# ---------------------------------------------------------------------------
# band-limited force disturbance
# ---------------------------------------------------------------------------
def test_disturbance_has_its_std_and_bandwidth_and_its_own_stream() -> None:
    from scipy.signal import welch

    eff = make_effects({"disturbance": {"std": 1.5, "bandwidth_hz": 20.0}, "noise": {"tau_std": 0.1, "q_std": 1e-6}})
    d = draw_disturbance(200_000, 7, eff, FS)
    assert np.array_equal(d, draw_disturbance(200_000, 7, eff, FS))  # deterministic for a seed
    assert not np.allclose(d[:1000], draw_disturbance(1000, 8, eff, FS))
    assert np.std(d) == pytest.approx(1.5, rel=0.04)
    f, pxx = welch(d, fs=FS, nperseg=8192)
    low = float(np.mean(pxx[(f > 0.5) & (f < 4.0)]))
    at_corner = float(np.mean(pxx[(f > 19.0) & (f < 21.0)]))
    assert at_corner / low == pytest.approx(0.5, abs=0.12)  # -3 dB at bandwidth_hz
    assert float(np.mean(pxx[(f > 78.0) & (f < 82.0)])) / low < 0.01  # second order: -24 dB at 4x
    # the force and position noise of the same seed are unchanged by the disturbance
    plain = draw_noise(1000, 7, make_effects({"noise": {"tau_std": 0.1, "q_std": 1e-6}}))
    assert all(np.array_equal(a, b) for a, b in zip(plain, draw_noise(1000, 7, eff), strict=True))
    with pytest.raises(ParameterError, match="Nyquist"):
        draw_disturbance(10, 0, make_effects({"disturbance": {"bandwidth_hz": 600.0}}), FS)


def _open_loop(force: np.ndarray, effects: dict[str, dict[str, float]], seed: int = 0) -> np.ndarray:
    """Plant velocity under the drive command ``force`` (N) with no feedback, on a frictionless 95 kg axis."""
    zero = np.zeros(len(force))
    res = simulate_loop(
        q_r=zero, qd_r=zero, qdd_r=zero, params=RigidParameters(95.0, 0.0, 0.0, 0.0), effects=make_effects(effects),
        controller=OpenLoopSettings(gtau=1.0), pulses=force, tau_sensor="command", seed=seed,
    )  # fmt: skip
    return res.qd_true, res.qdd_true, res.tau


def test_disturbance_acts_on_the_axis_not_in_the_logged_force() -> None:
    n = 3000
    eff = {"disturbance": {"std": 2.0, "bandwidth_hz": 15.0}}
    _, qdd, tau = _open_loop(np.zeros(n), eff, seed=4)
    d = draw_disturbance(n, 4, make_effects(eff), FS)
    np.testing.assert_allclose(qdd * 95.0, d, rtol=0, atol=1e-9)  # the axis accelerates with it, sample by sample
    assert np.all(tau == 0.0)


# ---------------------------------------------------------------------------
# first-order current loop
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("bw", [700.0, 150.0])
def test_current_loop_lags_the_force_by_its_time_constant(bw: float) -> None:
    n = 400
    step = np.where(np.arange(n) >= 100, 95.0, 0.0)  # 1 m/s^2 from t = 0.1 s
    v_ideal, qdd_ideal, _ = _open_loop(step, {})
    v_lag, qdd_lag, tau = _open_loop(step, {"current_loop": {"bandwidth_hz": bw}})
    time_constant = 1.0 / (2.0 * math.pi * bw)
    # after the step, v(t) = (t - ts) - tau (1 - exp(-(t - ts)/tau)): the velocity is tau late
    assert (v_ideal[-1] - v_lag[-1]) / 1.0 == pytest.approx(time_constant, rel=1e-6)
    # the applied force at t_k+ follows 1 - exp(-(t - ts)/tau) on the sample grid
    k = np.arange(101, 110)
    np.testing.assert_allclose(qdd_lag[k], 1.0 - np.exp(-(k - 100) / FS / time_constant), rtol=0, atol=1e-12)
    assert np.array_equal(qdd_ideal[100:], np.ones(n - 100))
    np.testing.assert_array_equal(tau, step)  # the log keeps the command


# ---------------------------------------------------------------------------
# trajectories
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["multisine", "trapezoid"])
def test_trajectory_derivatives_are_consistent_and_reverse_often(kind: str) -> None:
    traj = make_trajectory(kind, 3)
    t = np.arange(0, 30.0, 1e-4)
    q, qd, qdd = traj.evaluate(t)
    h = 1e-4
    # velocity = derivative of position, acceleration = derivative of velocity (trapezoid: away from its jumps)
    np.testing.assert_allclose(np.diff(q) / h, 0.5 * (qd[1:] + qd[:-1]), rtol=0, atol=1e-7)  # trapezoidal rule: O(h^2)
    dv = np.diff(qd) / h
    smooth = np.abs(np.diff(qdd)) < 1e-9 if kind == "trapezoid" else np.ones(len(dv), bool)
    np.testing.assert_allclose(dv[smooth], 0.5 * (qdd[1:] + qdd[:-1])[smooth], rtol=0, atol=1e-5)
    moving = np.sign(qd[np.abs(qd) > 1e-3])
    reversals = int(np.count_nonzero(np.diff(moving)))
    assert reversals >= 20, reversals  # Coulomb friction is excited
    assert 0.03 < float(np.max(np.abs(qd))) < 0.35 and float(np.ptp(q)) < 0.4
    # the logged (centred) reference: exact one-sample averages
    _, qs, _, _, qdc, qddc = traj.sample_both(2000, FS)
    qa, va, _ = traj.evaluate(np.arange(2000) / FS - 0.5e-3)
    qb, vb, _ = traj.evaluate(np.arange(2000) / FS + 0.5e-3)
    np.testing.assert_allclose(qdc, (qb - qa) * FS, rtol=0, atol=1e-9)  # within the snap to the point value of sample_both
    np.testing.assert_allclose(qddc, (vb - va) * FS, rtol=0, atol=1e-7)


def test_trajectories_are_seeded() -> None:
    a, b = multisine(1), multisine(1)
    assert a == b and a.phases != multisine(2).phases
    t = np.linspace(0, 20, 5001)
    assert np.array_equal(a.evaluate(t)[0], b.evaluate(t)[0])
    tr = trapezoid_moves(5)
    assert tr.segments == trapezoid_moves(5).segments and tr.segments != trapezoid_moves(6).segments
    q_start, q_end = tr.evaluate(np.array([0.0, tr.period]))[0]
    assert q_end == pytest.approx(q_start, abs=1e-12)  # each cycle returns to its start
    with pytest.raises(ParameterError, match="trajectory"):
        make_trajectory("sawtooth")


def test_simulate_cli_takes_a_trajectory_and_the_new_effects(tmp_path: Path) -> None:
    out = tmp_path / "ms.mcap"
    res = run_cli(
        "simulate", "--trajectory", "multisine", "--trajectory-seed", "4", "--duration", "3", "--no-ilic",
        "--effect", "disturbance:std=1,bandwidth_hz=10", "--effect", "current_loop", "-o", str(out),
    )  # fmt: skip
    assert res.status == 0, res.stderr
    log = read_log(out)
    assert log.meta["scenario"]["trajectory"]["kind"] == "multisine" and log.meta["scenario"]["trajectory"]["seed"] == 4
    assert log.meta["effects"]["current_loop"] == {"bandwidth_hz": 700.0}
    np.testing.assert_allclose(log["q_ref"], multisine(4).evaluate(log.t)[0], rtol=0, atol=1e-15)
    res = run_cli("simulate", "--scenario", "emps-benchmark", "--trajectory", "trapezoid", "-o", str(tmp_path / "x.mcap"))
    assert res.status == 2 and res.stderr.count("\n") == 1 and res.stderr.startswith("ilic: error: --trajectory") and "Traceback" not in res.stderr


# ---------------------------------------------------------------------------
# the corpus
# ---------------------------------------------------------------------------
def test_corpus_covers_the_issue() -> None:
    from tests.corpus import CASES, CLEAN_CASES, EFFECT_CASES, NOISE_MODELS, PAIR_CASES, TRAJECTORY_KINDS

    assert len(CLEAN_CASES) >= 20 and len(CASES) == len(CLEAN_CASES) + len(EFFECT_CASES) + len(PAIR_CASES)
    assert {(c.trajectory, c.noise) for c in CLEAN_CASES} == {(t, n) for t in TRAJECTORY_KINDS for n in NOISE_MODELS}
    catalogue = {"asymmetric_friction", "stribeck", "position_ripple", "spring", "payload_change", "delay", "flexibility"}
    for eid in catalogue:  # every effect under every noise model
        assert {c.noise for c in EFFECT_CASES if set(c.effects) == {eid}} == set(NOISE_MODELS), eid
    for c in (*EFFECT_CASES, *PAIR_CASES):
        assert c.size_pts is not None and 0.2 <= c.size_pts <= 1.5, c.name
    assert all(len(c.effects) == 2 for c in PAIR_CASES)
    lags = [-c.effects["delay"]["delay"] for c in EFFECT_CASES if "delay" in c.effects]
    assert min(lags) >= 1e-3 and max(lags) <= 2e-3


@pytest.mark.parametrize("name", ["position_ripple-paper-current_loop-s222", "payload_change-multisine-disturbance-s241"])
def test_corpus_case_size_is_as_stored(name: str) -> None:
    from tests.corpus import CASES, size_points

    case = CASES[name]
    assert size_points(case) == pytest.approx(case.size_pts, abs=0.002)


def test_corpus_case_is_deterministic_and_carries_its_truth() -> None:
    from tests.corpus import CASES, build_case, expected_delay_s

    case = CASES["delay+spring-multisine-combined-s304"]
    a, b = build_case(case), build_case(case)
    assert all(np.array_equal(a[ch], b[ch]) for ch in a.channels)
    truth = a.meta["corpus"]["truth"]
    assert truth["effects"]["spring"] == case.effects["spring"] and truth["effects"]["current_loop"] == {"bandwidth_hz": 700.0}
    assert "effects" not in a.meta and "true_parameters" not in a.meta  # concealed from the tools
    assert a.meta["simulation"]["tau_sensor"] == "command"
    assert expected_delay_s(case) == pytest.approx(1.2e-3 + 1.0 / (2 * math.pi * 700.0))
    assert expected_delay_s(CASES["clean-paper-sensor-s1"]) == 0.0


def test_corpus_design_reproduces_a_stored_case() -> None:
    from tests.corpus import CASES, EFFECT_CASES, PAIR_CASES, design, recipes

    recipe = next(r for r in recipes() if r[0] == "single" and r[1][1] == "delay" and r[1][3] == "sensor")  # no search: two simulations
    case = design(recipe)
    assert CASES[case.name] == case
    assert len(recipes()) == len(EFFECT_CASES) + len(PAIR_CASES)


def test_score_judges_findings_against_the_truth() -> None:
    from tests.corpus import CASES, score

    clean_cl = CASES["clean-paper-current_loop-s1"]
    tau = 1.0 / (2 * math.pi * 700.0)
    s = score(clean_cl, [("offset", None), ("delay", {"delay": -1.2 * tau})])
    assert s["verdicts"] == ["right", "right"] and s["false_alarms"] == 0
    s = score(clean_cl, [("delay", {"delay": -0.8e-3}), ("spring", {"k": 30.0, "q0": 0.0})])
    assert s["verdicts"] == ["false alarm", "false alarm"] and s["false_alarms"] == 2
    assert score(CASES["clean-paper-sensor-s1"], [("delay", {"delay": -tau})])["false_alarms"] == 1  # no current loop there
    pair = CASES["delay+spring-multisine-combined-s304"]
    s = score(pair, [("spring", {"k": pair.effects["spring"]["k"] * 1.1, "q0": 0.0})])
    assert s["missed"] == ["delay"] and s["parameter_error"]["spring"] == pytest.approx(0.1)
    s = score(pair, [("delay", {"delay": -(1.2e-3 + tau)})])  # the lag beyond the hold: concealed lag + current loop
    assert s["parameter_error"]["delay"] == pytest.approx(0.0, abs=1e-12)
