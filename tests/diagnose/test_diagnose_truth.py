"""A diagnosis that tells the truth: the sample hold and reversals in the baseline, materiality, the replay decides.

Clean logs come from the plant's closed loop (benchmark PD controller) with no
physics beyond the rigid model; a finding other than ``offset`` on them is a
false alarm.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.baseline import held, hold_s, reversal_samples
from ilic_cli.diagnosis.core import model_parameters
from ilic_cli.diagnosis.decide import MATERIAL_FORCE, immaterial, materiality, replay_decide
from ilic_cli.diagnosis.select import Step, moving_rows
from ilic_cli.effects import EFFECTS
from ilic_cli.idim_ls import LSSettings, lsq_rows
from ilic_cli.regressor import get_model
from ilic_cli.runlog import RunLog
from tests.diagnose.test_diagnose_effects import DEFAULT_MOVES, LOG_META, PD, SLOW, TRUE, exciting_cycle, make_effects, plant_cl


def clean_log(seed: int, traj_seed: int | None, noise: dict, sensor: str = "command", moves: tuple = DEFAULT_MOVES, effects: dict | None = None) -> RunLog:
    """A PD run of the rigid plant (plus ``effects``), 24.8 s after a 0.5 s warm-up, its force logged by ``sensor``."""
    cyc = exciting_cycle(moves, seed=traj_seed)
    t, q_r, qd_r, qdd_r = cyc.sample(25300, 1000.0)
    spec = {**noise, **(effects or {})}
    run = plant_cl.simulate_loop(q_r=q_r, qd_r=qd_r, qdd_r=qdd_r, params=TRUE, effects=make_effects(spec), controller=PD, seed=seed, tau_sensor=sensor)
    c = slice(500, None)
    meta = LOG_META | {"simulation": {"tau_sensor": sensor}, "source": f"clean-{seed}"}
    return RunLog({"t": t[c], "q": run.q[c], "tau": run.tau[c], "q_ref": q_r[c]}, meta=meta)


def test_hold_is_half_a_sample_of_a_held_command_only() -> None:
    assert hold_s("command", 1000.0) == 0.0005
    assert hold_s("centred", 1000.0) == 0.0 and hold_s(None, 1000.0) == 0.0
    t = np.arange(3000) / 1000.0
    q = 0.1 * np.sin(2 * np.pi * 0.7 * t)
    model = get_model("rigid-offset")
    data = lsq_rows(t, q, np.zeros_like(t), 1000.0, model, LSSettings())
    later = held(data, model, 0.0005)
    inner = slice(5, -5)
    assert np.allclose(later.kin.qd[inner], np.interp(data.kin.t + 0.0005, data.kin.t, data.kin.qd)[inner], rtol=0, atol=1e-15)
    assert not np.allclose(later.kin.qd, data.kin.qd)
    assert np.array_equal(later.kin.t, data.kin.t) and np.array_equal(later.y, data.y)
    assert later.W[:, 1] == pytest.approx(data.decimate(later.kin.qd), abs=1e-12)  # the regressor is rebuilt from the later kinematics
    assert held(data, model, 0.0) is data


def test_reversal_samples_mark_both_sides_of_a_sign_change() -> None:
    qd = np.array([2.0, 1.0, -1.0, -2.0, -1.0, 0.0, 0.0, 1.0])
    assert reversal_samples(qd).tolist() == [False, True, True, False, True, True, True, True]


def test_materiality_rules() -> None:
    assert "not material" in (immaterial(0.99 * MATERIAL_FORCE * 50.0, 50.0) or "")
    assert "(0.0495 N·m RMS) is below 0.3 % of the force (50 N·m RMS)" in (immaterial(0.33 * MATERIAL_FORCE * 50.0, 50.0, unit="N·m") or "")
    assert immaterial(1.01 * MATERIAL_FORCE * 50.0, 50.0) is None
    assert immaterial(0.0, 0.0) is None


def test_a_biased_value_is_material_where_the_replay_may_put_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """Stribeck ``vs`` (searched on the closed loop): immaterial only when its force is small over the whole search.

    On the corpus's Stribeck + flexibility log the inverse model's vs (21 mm/s, truth 8) gave 0.21 % of the force
    once the current loop's lag was kept, and the effect was lost; the search's largest is 0.33 %.
    """
    import ilic_cli.diagnosis.materiality as decide  # where materiality finds the force it weighs

    kin = lsq_rows(np.arange(2000) / 1000.0, 0.1 * np.sin(np.arange(2000) / 300.0), np.zeros(2000), 1000.0, get_model("rigid-offset"), LSSettings()).kin
    data = type("Data", (), {"kin": kin, "fs_hz": 1000.0, "joint": "prismatic"})()
    grid = EFFECTS["stribeck"].scan.grid(kin, 1000.0)
    at = float(grid[16])
    small, large = 0.5 * MATERIAL_FORCE * 50.0, 2.0 * MATERIAL_FORCE * 50.0
    monkeypatch.setattr(decide, "effect_force_rms", lambda d, b, k, st, r: (large if st.value == float(grid[10]) else small, 50.0))
    assert materiality(data, get_model("rigid-offset"), [], Step(EFFECTS["stribeck"], at), np.ones(1, bool)) is None  # 6 grid steps away: searched
    monkeypatch.setattr(decide, "effect_force_rms", lambda d, b, k, st, r: (large if st.value == float(grid[0]) else small, 50.0))
    assert "not material" in (materiality(data, get_model("rigid-offset"), [], Step(EFFECTS["stribeck"], at), np.ones(1, bool)) or "")  # beyond it
    ripple = EFFECTS["position_ripple"]  # a value the closed loop does not search: its own force only
    monkeypatch.setattr(decide, "effect_force_rms", lambda d, b, k, st, r: (small, 50.0))
    assert "not material" in (materiality(data, get_model("rigid-offset"), [], Step(ripple, 0.02), np.ones(1, bool)) or "")


CLEAN = [
    # seed, trajectory seed, noise, sensor, moves
    (201, 2, {"noise": {"tau_std": 2.0}, "quantization": {"resolution": 5e-8}}, "command", DEFAULT_MOVES),
    (202, 5, {"noise": {"tau_std": 1.0}, "quantization": {"resolution": 1e-6}}, "command", DEFAULT_MOVES + SLOW),
    (203, 7, {"noise": {"q_std": 1e-6, "tau_std": 0.5}}, "centred", DEFAULT_MOVES),
    (204, 2, {}, "command", DEFAULT_MOVES),  # noise-free: only discretisation is left
]


def test_clean_logs_no_false_alarm_and_no_hold_delay() -> None:
    """False alarms on a fast subset of the clean corpus: at most 5 % (here: none of 4)."""
    alarms = []
    for seed, traj, noise, sensor, moves in CLEAN:
        d = diagnose(clean_log(seed, traj, noise, sensor, moves), settings=DiagnoseSettings(simulate=True))
        alarms += [(seed, f.effect.id) for f in d.findings if f.effect.id != "offset"]
        # the hold is in the baseline: the inverse model does not even propose a delay (it did, at -0.50 ms, on every held-command log)
        first = {ev.effect: ev for ev in d.tried[0]}
        assert first["delay"].test.p_adjusted >= 0.001 or abs(first["delay"].value) < 1e-4, (seed, first["delay"])
    assert len(alarms) <= 0.05 * len(CLEAN), alarms


@pytest.fixture(scope="module")
def spurious_and_real() -> tuple[RunLog, RunLog]:
    noise = {"noise": {"tau_std": 2.0}, "quantization": {"resolution": 5e-8}}
    asym = {"asymmetric_friction": {"Fv_pos": 203.5, "Fv_neg": 218.5, "Fc_pos": 20.39, "Fc_neg": 20.39}}
    return clean_log(211, 3, noise), clean_log(212, 3, noise, effects=asym)


def _decide(log: RunLog, step: Step) -> tuple[list[Step], list]:
    base = get_model("rigid-offset")
    data = held(lsq_rows(log.t, log["q"], log["tau"], 1000.0, base, LSSettings()), base, hold_s("command", 1000.0))
    rows = moving_rows(data)

    def plant_of(steps, names, theta):  # type: ignore[no-untyped-def]
        return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))), 0.0005)

    return replay_decide(log, data, base, [], [step], rows, plant_of)


def test_replay_rejects_a_spurious_effect(spurious_and_real: tuple[RunLog, RunLog]) -> None:
    clean, _ = spurious_and_real
    kept, (verdict,) = _decide(clean, Step(EFFECTS["stribeck"], 0.01))
    # noise-free replays: the error did not fall; with the recording's sensor noise, loop-corrected, it falls by 0.12 % of
    # itself, p = 0.024 by the squared loss alone (0.03 %, p = 0.35, with the uncorrected estimate), 0.017 with the absolute
    # loss's statistic too (a fall that small, in most samples): not significant at the replay's level, 0.01
    assert kept == [] and not verdict.accepted and "rejected by the replay" in verdict.reason, verdict
    assert verdict.force_after >= verdict.force_before or (verdict.p_value is not None and verdict.p_value > 0.015), verdict


def test_replay_keeps_a_real_effect(spurious_and_real: tuple[RunLog, RunLog]) -> None:
    _, real = spurious_and_real
    kept, (verdict,) = _decide(real, Step(EFFECTS["asymmetric_friction"]))
    assert [s.effect.id for s in kept] == ["asymmetric_friction"], verdict
    assert verdict.force_after < verdict.force_before and verdict.p_value < 0.01
    assert "held-out simulated force error" in verdict.reason
