"""Each effect changes the force as documented, is off by default, and the stick/slip logic is deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.commands.common import parse_effect_option
from ilic_cli.effects import EFFECTS, make_effects, plant_ids
from ilic_cli.errors import IlicError, ParameterError
from plant.closed_loop import simulate_loop
from plant.controllers import CTCSettings, chi_vector
from plant.dynamics import RigidParameters, drive_lag_s, force_model, measurement_lag_s, plant_vector
from plant.kernel import run_periods
from plant.trajectories import exciting_cycle

P = RigidParameters(95.0, 200.0, 20.0, -3.0)
FS = 1000.0


@pytest.fixture(scope="module")
def motion() -> tuple[np.ndarray, ...]:
    t = np.arange(3000) / FS
    q = 0.1 + 0.05 * np.sin(2 * np.pi * 0.5 * t)
    qd = 0.05 * 2 * np.pi * 0.5 * np.cos(2 * np.pi * 0.5 * t)
    qdd = -0.05 * (2 * np.pi * 0.5) ** 2 * np.sin(2 * np.pi * 0.5 * t)
    return q, qd, qdd, t


def test_rigid_force_model(motion: tuple[np.ndarray, ...]) -> None:
    q, qd, qdd, t = motion
    np.testing.assert_allclose(force_model(P, {}, q, qd, qdd, t), 95 * qdd + 200 * qd + 20 * np.sign(qd) - 3.0, rtol=0, atol=1e-12)


def test_every_effect_off_by_default() -> None:
    base = plant_vector(P, {})
    assert np.array_equal(base, plant_vector(P, make_effects({})))
    log = _closed_loop({})
    assert set(log.meta["effects"]) == set()
    for eid in plant_ids():
        assert not np.array_equal(plant_vector(P, make_effects({eid: {}})), base) or eid in ("delay", "noise")


@pytest.mark.parametrize(
    ("eid", "params", "extra"),
    [
        ("spring", {"k": 300.0, "q0": 0.08}, lambda q, qd, qdd, t: 300.0 * (q - 0.08)),
        ("position_ripple", {"A": 2.0, "L": 0.01, "phase": 0.3}, lambda q, qd, qdd, t: 2.0 * np.sin(2 * np.pi * q / 0.01 + 0.3)),
        ("stribeck", {"Fs": 5.0, "vs": 0.02}, lambda q, qd, qdd, t: 5.0 * np.exp(-((qd / 0.02) ** 2)) * np.sign(qd)),
        ("payload_change", {"dM": 10.0, "t_change": 1.5}, lambda q, qd, qdd, t: np.where(t >= 1.5, 10.0 * qdd, 0.0)),
        (
            "asymmetric_friction",
            {"Fv_pos": 170.0, "Fv_neg": 240.0, "Fc_pos": 19.0, "Fc_neg": 21.0},
            lambda q, qd, qdd, t: np.where(qd > 0, 170 * qd + 19, np.where(qd < 0, 240 * qd - 21, 0.0)) - (200 * qd + 20 * np.sign(qd)),
        ),
    ],
)
def test_effect_adds_documented_force(motion: tuple[np.ndarray, ...], eid: str, params: dict, extra) -> None:  # type: ignore[no-untyped-def]
    q, qd, qdd, t = motion
    base = force_model(P, {}, q, qd, qdd, t)
    got = force_model(P, {eid: params}, q, qd, qdd, t)
    np.testing.assert_allclose(got - base, extra(q, qd, qdd, t), rtol=0, atol=1e-9)


def test_delay_shifts_force(motion: tuple[np.ndarray, ...]) -> None:
    q, qd, qdd, t = motion
    base = force_model(P, {}, q, qd, qdd, t)
    got = force_model(P, {"delay": {"delay": 0.005}}, q, qd, qdd, t)
    np.testing.assert_allclose(got[5:], base[:-5], atol=1e-9)


def test_flexibility_slow_motion_moves_whole_mass(motion: tuple[np.ndarray, ...]) -> None:
    q, qd, qdd, t = motion
    base = force_model(P, {}, q, qd, qdd, t)
    got = force_model(P, {"flexibility": {"stiffness": 2e6, "damping": 500.0, "load_fraction": 0.3}}, q, qd, qdd, t)
    # after the start transient the load follows: same force within 0.5 N
    assert np.abs(got[500:] - base[500:]).max() < 0.5
    assert np.abs(got[:50] - base[:50]).max() > 0.1  # the load lags at the start


def _closed_loop(effects: dict, *, sensor: str = "centred", seconds: float = 3.0, seed: int = 0):  # type: ignore[no-untyped-def]
    from plant.closed_loop import loop_log

    traj = exciting_cycle()
    n = int(seconds * FS)
    _, q_r, qd_r, qdd_r = traj.sample(n, FS)
    ctl = CTCSettings(ilic=False, chi0={"M": 95.0, "Fv": 200.0, "Fc": 20.0})
    eff = make_effects(effects)
    res = simulate_loop(q_r=q_r, qd_r=qd_r, qdd_r=qdd_r, params=P, effects=eff, controller=ctl, tau_sensor=sensor, seed=seed)
    log = loop_log(res, q_ref=q_r, qd_ref=qd_r, qdd_ref=qdd_r)
    return log


def test_closed_loop_delay_shifts_logged_force() -> None:
    a = _closed_loop({})
    b = _closed_loop({"delay": {"delay": 0.003}})
    np.testing.assert_array_equal(a["q"], b["q"])  # the motion is the same: only the measurement is late
    np.testing.assert_allclose(b["tau"][3:], a["tau"][:-3], atol=1e-9)


@pytest.mark.parametrize("eid", ["spring", "position_ripple", "stribeck", "payload_change", "asymmetric_friction", "flexibility"])
def test_closed_loop_each_physical_effect_changes_the_run(eid: str) -> None:
    params = {"payload_change": {"dM": 10.0, "t_change": 1.0}}.get(eid, {})
    a, b = _closed_loop({}), _closed_loop({eid: params})
    assert np.abs(a["tau"] - b["tau"]).max() > 0.5 or np.abs(a["q"] - b["q"]).max() > 1e-7
    assert b.meta["effects"][eid]


def test_payload_raises_force_after_change_only() -> None:
    a, b = _closed_loop({}), _closed_loop({"payload_change": {"dM": 10.0, "t_change": 1.0}})
    i = 1000
    np.testing.assert_array_equal(a["tau"][:i], b["tau"][:i])
    # in the next stretch the controller (fixed M_hat) lets the heavier axis lag: the force differs
    assert np.abs(a["tau"][i + 1 :] - b["tau"][i + 1 :]).max() > 1.0


def test_saturation_quantization_noise() -> None:
    sat = _closed_loop({"saturation": {"force_max": 150.0}}, sensor="command")
    assert np.abs(sat["tau"]).max() <= 150.0 + 1e-9
    assert np.isclose(np.abs(sat["tau"]).max(), 150.0)
    qz = _closed_loop({"quantization": {"resolution": 1e-6}})
    counts = qz["q"] / 1e-6
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    base = _closed_loop({})
    noisy = _closed_loop({"noise": {"tau_std": 0.5, "q_std": 0.0}}, seed=7)
    again = _closed_loop({"noise": {"tau_std": 0.5, "q_std": 0.0}}, seed=7)
    other = _closed_loop({"noise": {"tau_std": 0.5, "q_std": 0.0}}, seed=8)
    np.testing.assert_array_equal(noisy["tau"], again["tau"])
    assert not np.array_equal(noisy["tau"], other["tau"])
    np.testing.assert_array_equal(noisy["q"], base["q"])  # force noise is measurement only (CTC does not use tau)
    assert np.std(noisy["tau"] - base["tau"]) == pytest.approx(0.5, rel=0.05)


def _constant_force(force: float, periods: int = 1000) -> np.ndarray:
    """Drive the plant with a constant force through the compiled loop (CTC with only an offset)."""
    p = plant_vector(RigidParameters(95.0, 0.0, 20.0, 0.0), {})
    c = CTCSettings(model="rigid-offset").vector()
    chi = chi_vector(("offset",), {"offset": force})
    z = np.zeros(periods)
    x, cs = np.zeros(4), np.zeros(4)
    out = [np.zeros(periods) for _ in range(6)]
    assert run_periods(0, periods, x, cs, z, z, z, z, z, p, c, chi, 10, 1e-3, *out, z) == -1
    return out[3]


def test_stiction_holds_below_static_level_and_breaks_away_above() -> None:
    stuck = _constant_force(19.9)
    assert np.all(stuck == 0.0)
    moving = _constant_force(30.0)
    t = np.arange(1000) * 1e-3
    np.testing.assert_allclose(moving, 0.5 * (10.0 / 95.0) * t**2, atol=1e-12)
    neg = _constant_force(-30.0)
    np.testing.assert_allclose(neg, -moving, atol=1e-15)


def test_effect_option_parsing_and_errors() -> None:
    assert parse_effect_option("stribeck:Fs=5,vs=0.01") == ("stribeck", {"Fs": 5.0, "vs": 0.01})
    assert parse_effect_option("spring") == ("spring", {})
    for bad in ("nope", "stribeck:Fs", "stribeck:Fs=x"):
        with pytest.raises(IlicError, match="--effect"):
            parse_effect_option(bad)
    with pytest.raises(ParameterError, match="stribeck.vs = -1 must be > 0"):
        make_effects({"stribeck": {"vs": -1.0}})
    with pytest.raises(ParameterError, match="spring.stiffness"):
        make_effects({"spring": {"stiffness": 1.0}})
    for eid in plant_ids():
        eff = make_effects({eid: {}})[eid]
        assert make_effects({eid: eff.to_dict()})[eid] == eff, eid
        assert list(eff.to_dict()) == [p.name for p in EFFECTS[eid].params]


def _sliding_force_balance(log, params: RigidParameters, fs_extra=None) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """The force acting at each t_k+ from the plant's own states (M*qdd + friction + offset), on sliding samples."""
    qd, qdd = log["qd_plant"], log["qdd_plant"]
    acting = params.M * qdd + params.Fv * qd + params.Fc * np.sign(qd) + params.offset
    if fs_extra is not None:
        acting = acting + fs_extra(qd)
    return acting, np.abs(qd) > 1e-6


@pytest.mark.parametrize("lag_s", [0.001, 0.0004, 0.0025])
def test_drive_lag_applies_the_command_later(lag_s: float) -> None:
    """``delay < 0``: the logged force is the command; the axis receives it ``-delay`` later (drive lag)."""
    a = _closed_loop({}, sensor="command")
    b = _closed_loop({"delay": {"delay": -lag_s}}, sensor="command")
    assert not np.array_equal(a["q"], b["q"])  # the motion changes (unlike a measurement delay)
    acting, sliding = _sliding_force_balance(b, P)
    # at t_k+ the axis feels the command of period k - ceil(lag/T) (the newer one only from t_k + lag mod T)
    back = int(np.ceil(lag_s * FS - 1e-9))
    tau = b["tau"]
    np.testing.assert_allclose(acting[back:][sliding[back:]], tau[:-back][sliding[back:]], rtol=0, atol=1e-8)
    # and the lagged run is close to the undelayed run shifted by the lag (CTC keeps tracking)
    assert np.abs(b["q"] - a["q"]).max() < 1e-4


def test_drive_lag_and_measurement_delay_are_one_effect() -> None:
    assert drive_lag_s(make_effects({"delay": {"delay": -0.0005}})) == 0.0005
    assert measurement_lag_s(make_effects({"delay": {"delay": 0.0005}})) == 0.0005
    with pytest.raises(ParameterError, match="delay"):
        make_effects({"delay": {"delay": -2.0}})


def test_negative_stribeck_lowers_low_speed_friction() -> None:
    params = {"Fs": -4.0, "vs": 0.02}
    log = _closed_loop({"stribeck": params}, sensor="command")
    extra = lambda qd: params["Fs"] * np.exp(-((qd / params["vs"]) ** 2)) * np.sign(qd)  # noqa: E731
    acting, sliding = _sliding_force_balance(log, P, extra)
    np.testing.assert_allclose(acting[sliding], log["tau"][sliding], rtol=0, atol=1e-8)
    # the static level Fc + Fs may not be negative
    with pytest.raises(ParameterError, match="static friction level"):
        plant_vector(P, make_effects({"stribeck": {"Fs": -25.0, "vs": 0.02}}))


def test_ramped_pulses_and_replay_clock() -> None:
    """``pulse_input="ramp"`` moves the pulse force linearly over the period (the published simulation's input);
    ``clock_s`` runs the replay on another control period, sample k for sample k."""
    from dataclasses import replace

    from plant.controllers import PDSettings
    from plant.replay import simulate_replay
    from tests.conftest import make_synthetic_log

    log = make_synthetic_log(samples=600)
    params = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}
    held = simulate_replay(log, params, controller=PDSettings(), seed=0)
    ramp = simulate_replay(log, params, controller=PDSettings(pulse_input="ramp"), seed=0)
    assert ramp.meta["controller"]["pulse_input"] == "ramp"
    np.testing.assert_array_equal(held["vir"][:50], ramp["vir"][:50])  # identical until the first pulse edge (sample 50)
    # the first edge (0 -> 5 V at sample 50): held applies it over period 50, ramped over period 49 -> 50
    assert ramp["q"][50] > held["q"][50] and np.array_equal(held["q"][:50], ramp["q"][:50])
    dv = np.diff(ramp["qd_plant"][45:55]) - np.diff(held["qd_plant"][45:55])
    assert np.all(dv[:4] == 0.0) and dv[4] > 0  # dv[i]: over period 45 + i; period 49 gains velocity only when ramped
    # no change of the pulses, no change: a log without pulse edges runs bit-identically either way
    flat = make_synthetic_log(samples=40)
    a = simulate_replay(flat, params, controller=PDSettings(), seed=0)
    b = simulate_replay(flat, params, controller=PDSettings(pulse_input="ramp"), seed=0)
    np.testing.assert_array_equal(a["q"], b["q"])
    # another clock: same number of samples on k*clock_s; the reference is interpolated there
    slow = simulate_replay(log, params, controller=PDSettings(), clock_s=1.001e-3)
    assert len(slow) == len(log) and slow.t[-1] == pytest.approx(599 * 1.001e-3, abs=1e-12)
    assert slow.meta["replay_clock_s"] == 1.001e-3
    np.testing.assert_allclose(slow["q_ref"], np.interp(slow.t, log.t, log["q_ref"]), rtol=0, atol=1e-15)
    with pytest.raises(ParameterError, match="clock"):
        simulate_replay(log, params, controller=PDSettings(), clock_s=-1.0)
    with pytest.raises(ParameterError, match="ramped pulses"):
        simulate_replay(log, params, {"delay": {"delay": -0.0005}}, controller=PDSettings(pulse_input="ramp"))
    with pytest.raises(ParameterError, match="pulse_input"):
        simulate_replay(log, params, controller=replace(PDSettings(), pulse_input="square"))
