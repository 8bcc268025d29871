"""The PD loop's computation delay (``PDSettings.delay_samples``) and velocity estimate (``PDSettings.velocity``): where the command
acts, what is logged, and which law the log is read to follow."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.effects import make_effects
from ilic_cli.errors import ParameterError
from ilic_cli.simulation.pd_law import pd_law_residuals
from plant.closed_loop import simulate_loop
from plant.controllers import PDSettings
from plant.dynamics import RigidParameters
from plant.replay import simulate_replay
from tests.conftest import make_synthetic_log

PARAMS = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}


def _acting_share(delay_samples: float) -> tuple[np.ndarray, object]:
    """Least squares of the force balance over each period on the logged commands ``u[k-1], u[k]``: their shares of the period."""
    log = make_synthetic_log(samples=2000)
    sim = simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=delay_samples))
    T = sim.dt_s
    q, qd, u = sim["q"], sim["qd_plant"], sim["tau"]
    k = np.arange(1, len(q) - 1)
    v_mean = (q[k + 1] - q[k]) / T
    sliding = (np.abs(qd[k]) > 0.01) & (np.abs(qd[k + 1]) > 0.01) & (np.sign(qd[k]) == np.sign(qd[k + 1]))
    # M dv/T = mean applied force - Fv*mean velocity - Fc*sign - offset (friction is linear between reversals)
    y = PARAMS["M"] * (qd[k + 1] - qd[k]) / T + PARAMS["Fv"] * v_mean + PARAMS["Fc"] * np.sign(qd[k]) + PARAMS["offset"]
    A = np.c_[u[k - 1], u[k]][sliding]
    return np.linalg.lstsq(A, y[sliding], rcond=None)[0], sim


@pytest.mark.parametrize("delay", [0.0, 0.4, 0.75])
def test_a_same_sample_command_acts_after_its_lag(delay: float) -> None:
    """Inverse of forward: the command logged at k (the law on q(k)) acts over the last 1 - delay of the period, the one before over the first part."""
    share, sim = _acting_share(delay)
    np.testing.assert_allclose(share, [delay, 1.0 - delay], atol=2e-3)
    c = PDSettings()
    law = pd_law_residuals(sim["q"], sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, sim.dt_s)
    assert law.follows == "same" and law.same_pct < 1e-9  # logged as the EMPS recordings log it
    assert sim.meta["controller"]["delay_samples"] == delay


def test_the_documented_loop_is_unchanged() -> None:
    """delay_samples = 1 (the default): the command from the previous sample, acting over the whole period it is logged at."""
    share, sim = _acting_share(1.0)
    np.testing.assert_allclose(share, [0.0, 1.0], atol=2e-3)
    c = PDSettings()
    assert pd_law_residuals(sim["q"], sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, sim.dt_s).follows == "previous"
    assert sim.meta["controller"]["delay_samples"] == 1 and isinstance(sim.meta["controller"]["delay_samples"], int)


@pytest.mark.parametrize("delay", [0.0, 1.0])
def test_a_backward_difference_loop_is_read_as_such(delay: float) -> None:
    """``velocity="backward"``: the textbook loop differences the measured position itself; the law is read with that estimate, on
    the sample it is computed from, and the benchmark's averaged estimate leaves a residual of the command."""
    log = make_synthetic_log(samples=2000)
    sim = simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=delay, velocity="backward"))
    q, T = sim["q"], sim.dt_s
    c = PDSettings()
    v = c.kv * (c.kp * (sim["q_ref"][2:] - q[2:]) - (q[2:] - q[1:-1]) / T)  # the law, written out
    logged = sim["vir"][2:] - sim["pulses"][2:]
    np.testing.assert_allclose(logged if delay == 0.0 else logged[1:], np.clip(v if delay == 0.0 else v[:-1], -c.vmax, c.vmax), atol=1e-9)
    law = pd_law_residuals(q, sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, T)
    assert law.velocity == "backward" and law.follows == ("same" if delay == 0.0 else "previous")
    assert min(law.same_pct, law.previous_pct) < 1e-9 and law.other_pct is not None and law.other_pct > 0.5
    meta = sim.meta["controller"]
    assert meta["velocity"] == "backward" and meta["position_filter"] == [1.0]
    # the benchmark's loop keeps its metadata as it was (no velocity key) and is read with its own estimate
    bench = simulate_replay(log, PARAMS, controller=PDSettings())
    assert "velocity" not in bench.meta["controller"] and bench.meta["controller"]["position_filter"] == [0.5, 0.5]
    assert pd_law_residuals(bench["q"], bench["q_ref"], bench["vir"], bench["pulses"], c.kp, c.kv, c.vmax, T).velocity == "averaged"


def test_a_loop_fed_the_plant_s_velocity_is_read_as_such() -> None:
    """``velocity="exact"``: the command is the law on the plant's own velocity at its sample; read with the velocity IDIM-LS
    estimates, that law leaves the position noise's filtered trace, the differences far more."""
    log = make_synthetic_log(samples=3000)
    c = PDSettings(delay_samples=0.0, velocity="exact")
    sim = simulate_replay(log, PARAMS, {"quantization": {"resolution": 5e-8}}, controller=c)
    v = c.kv * (c.kp * (sim["q_ref"] - sim["q"]) - sim["qd_plant"])  # the law, written out on the plant's velocity at the sample
    np.testing.assert_allclose(sim["vir"] - sim["pulses"], np.clip(v, -c.vmax, c.vmax), atol=1e-9)
    law = pd_law_residuals(sim["q"], sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, sim.dt_s)
    assert law.velocity == "exact" and law.follows == "same"
    assert law.other_pct is not None and min(law.same_pct, law.previous_pct) < 0.5 * law.other_pct
    assert "position_filter" in sim.meta["controller"] and sim.meta["controller"]["position_filter"] is None


def test_delay_samples_is_checked() -> None:
    log = make_synthetic_log(samples=200)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ParameterError, match="delay_samples"):
            simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=bad))
    with pytest.raises(ParameterError, match="ramped pulses"):
        simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=0.5, pulse_input="ramp"))
    with pytest.raises(ParameterError, match="velocity"):
        simulate_replay(log, PARAMS, controller=PDSettings(velocity="filtered"))


def test_a_law_inside_the_dynamics_is_evaluated_every_step_on_the_state() -> None:
    """``continuous``: the law on the plant's state at every integration step (a solver's right-hand side). Logged at the samples as the
    law on the plant's velocity there; between them the force follows the state, so a log of such a simulator (the independent
    simulator's ``"continuous"`` loop, 40 Euler steps a period) replays with the true model far closer than with the law held over
    the period. A drive lag delays the force by whole steps; the run is the same in one piece or in the chunks a progress bar asks."""
    from dataclasses import replace

    from ilic_cli.idim_ls import LSSettings
    from ilic_cli.simulation.replay import relative_errors, replay
    from plant.replay import controller_from_log
    from tests.corpus.independent import run_loop
    from tests.logs.test_rates import AXES, reference

    axis = AXES["linear"]
    _, q_ref = reference(axis, 500.0)
    log = run_loop(axis, 500.0, q_ref, "continuous", {}, 3, "linear", 40)
    held = replace(controller_from_log(log), velocity="exact", delay_samples=0.0)
    truth = {k: axis.truth[k] for k in ("M", "Fv", "Fc")}
    errors = [relative_errors(log, replay(log, truth, {}, controller=c), LSSettings().at_rate(500.0)) for c in (held, replace(held, continuous=True))]
    assert errors[1]["force"] < 0.1 * errors[0]["force"] and errors[1]["position"] < 0.5 * errors[0]["position"], errors
    sim = replay(log, truth, {}, controller=replace(held, continuous=True))  # noise-free: its q is the plant's
    v = held.kv * (held.kp * (sim["q_ref"] - sim["q"]) - sim["qd_plant"])  # logged: the law on the state at the sample
    np.testing.assert_allclose(sim["vir"], np.clip(v, -held.vmax, held.vmax), atol=1e-9)
    assert sim.meta["controller"]["continuous"] is True and "continuous" not in PDSettings().to_dict()
    inside = replace(held, continuous=True)
    run = {
        chunks: simulate_loop(
            q_r=log["q_ref"],
            qd_r=np.zeros(len(log)),
            qdd_r=np.zeros(len(log)),
            params=RigidParameters(**truth),
            effects=make_effects({"delay": {"delay": -0.0016}}),
            controller=inside,
            fs_hz=500.0,
            progress=(lambda a, b: None) if chunks else None,
        ).q
        for chunks in (False, True)
    }
    np.testing.assert_array_equal(run[False], run[True])  # the lag's commands kept across what would be chunks
    assert not np.allclose(run[False], sim["q"], atol=1e-6)  # and the lag acts
    for bad in ({"velocity": "backward"}, {"delay_samples": 0.5}):
        with pytest.raises(ParameterError, match="continuous"):
            simulate_replay(log, truth, controller=replace(held, continuous=True, **bad))
