"""Stribeck friction at a trapezoid's dwells, proposed by the closed loop (``ilic_cli/diagnosis/dwell.py``), on corpus logs."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis import dwell, segments
from ilic_cli.diagnosis.core import diagnose
from ilic_cli.diagnosis.decide import in_its_place
from ilic_cli.diagnosis.heldout_replay import HeldoutReplays
from ilic_cli.diagnosis.report import to_markdown
from ilic_cli.diagnosis.system import Step
from ilic_cli.diagnosis.verdicts import Selection, Verdict
from ilic_cli.effects import EFFECTS
from ilic_cli.filtering import kept_indices
from tests.conftest import require_shared
from tests.corpus import CASES, robot, score
from tests.diagnose.corpus_cache import diagnosed


def test_stribeck_on_a_trapezoid_is_named_by_the_closed_loop_and_estimated_on_open_loop_segments() -> None:
    """The corpus's Stribeck trapezoid (sensor noise only): the inverse model fits Fs = -2.9 N there, outside Stribeck physics.

    The closed loop proposes it and the replay decides: held-out replay force error 1.35 % -> 0.914 % (p = 5e-14), estimates
    in 5 of 5 folds, Fs 2.45-2.61 N, vs 8.6-11.6 mm/s (their median 9.9 mm/s for 8: 23 % off). The open-loop segments'
    fit then estimates it (``segments.py``): Fs = 2.4734 +- 0.012 N, vs = 7.972 +- 0.040 mm/s (truth 2.47 N, 8 mm/s), every
    rigid parameter within 0.001 %, the residual 0.501 um RMS for a sensor noise of 0.551 um.
    """
    case = CASES["stribeck-trapezoid-sensor-s210"]
    diag = diagnosed(case.name)
    (f,) = diag.findings
    assert f.effect.id == "stribeck" and f.method == segments.METHOD
    truth = case.effects["stribeck"]
    for name in ("Fs", "vs"):
        est = f.parameters[name]
        assert abs(est.value - truth[name]) < 0.01 * truth[name], name
        # the fit's own standard deviation (white sensor noise): the truth within two of it
        assert est.std is not None and 0 < est.std < 0.01 * est.value and abs(est.value - truth[name]) < 2 * est.std, name
    (verdict,) = diag.decisions
    assert verdict.accepted and verdict.p_value is not None and verdict.p_value < 1e-6 and "5 of 5 folds" in verdict.reason
    assert verdict.proposed_by == dwell.METHOD and verdict.to_dict()["proposed_by"] == dwell.METHOD
    assert verdict.force_after is not None and verdict.force_before is not None and verdict.force_after < 0.75 * verdict.force_before
    assert score(case, [(x.effect.id, x.plant_effect) for x in diag.findings])["false_alarms"] == 0
    assert diag.refit is not None and diag.refit.accepted and diag.refit.segments is not None and diag.refit.segments.consistent
    seg = diag.refit.to_dict()["open_loop_segments"]
    assert seg["consistent"] and seg["residual_rms_um"] < 1.5 * seg["sensor_noise_um"] and seg["segments"] == 99
    rigid = diag.model_file["parameters"]
    assert all(rigid[n] == pytest.approx(v, rel=1e-4) for n, v in {"M": 95.0, "Fv": 200.0, "Fc": 20.0}.items()), rigid
    assert diag.model_file["effects"]["stribeck"]["Fs"] == pytest.approx(f.parameters["Fs"].value)
    assert diag.model_file["method"] == f"{segments.METHOD} + ilic diagnose"
    assert f.to_dict()["inverse_model_parameters"] is None
    text = to_markdown(diag)
    assert "proposed on the closed loop at the reference's dwells" in text and "Fs and vs searched on the closed loop" in text
    assert f"Estimates: the {segments.METHOD}'s; 99 segments of 0.3 s driven by the recorded force" in text and "This replay is noise-free" in text
    assert f"Estimated by the {segments.METHOD} (the inverse model has no estimate of it inside its physics); std: {segments.SPREAD}." in text
    assert "do not resolve the stick and break-away there" in text  # the inverse model's error need not fall
    (ev,) = [e for step in diag.tried for e in step if e.effect == "stribeck"][-1:]
    assert "outside the catalogue" in ev.reason and "proposed on the closed loop instead" in ev.reason


def test_a_refuted_effect_is_dropped_and_its_verdict_says_why() -> None:
    """The Stribeck trapezoid's kept effect and verdicts, refuted (the rule itself: ``test_segments.py``): the effect leaves the
    model, and its accepting verdict becomes a rejection that keeps the replay's figures and says why.

    Measured on the corpus's ripple trapezoid of seed 3220, where the replay accepts Stribeck friction beside the ripple: the
    segments' fit (the ripple's period fitted too: 20.000 mm for 20) explains the recording to its noise (0.499 um RMS for
    0.548 um) with a Stribeck level of -0.002 +- 0.003 N, and only the ripple is named (docs/diagnosis.md; a 33 s diagnosis, not run here).
    """
    from ilic_cli.diagnosis.core import without_last
    from ilic_cli.diagnosis.select import Step
    from ilic_cli.effects import EFFECTS

    diag = diagnosed("stribeck-trapezoid-sensor-s210")
    (verdict,) = diag.decisions
    ripple = Step(EFFECTS["position_ripple"], 0.02)
    kept, verdicts = without_last([ripple, Step(EFFECTS["stribeck"], 0.0125, level=(0.85,))], diag.decisions, "refuted (planted)")
    assert kept == [ripple] and len(verdicts) == 1 and not verdicts[0].accepted and verdict.accepted
    assert verdicts[0].reason == f"{verdict.reason}; refuted (planted)" and verdicts[0].force_after == verdict.force_after
    assert verdicts[0].to_dict()["accepted"] is False


def test_no_stribeck_at_the_dwells_of_a_clean_current_loop_trapezoid() -> None:
    """With the current loop realised as a first-order lag, the dwells show no Stribeck friction (as a pure 0.24 ms delay, they did).

    Measured: no fold's search found a level inside its grid; the loop's lag is named (0.24 ms beyond the hold: a 664 Hz loop in the model file).
    """
    case = CASES["clean-trapezoid-current_loop-s1"]  # also one of the clean logs of test_corpus_rates: diagnosed once
    diag = diagnosed(case.name)
    assert [f.effect.id for f in diag.findings] == ["delay"]
    (verdict,) = [v for v in diag.decisions if v.effect == "stribeck"]
    assert not verdict.accepted and "0 of 5 folds" in verdict.reason and verdict.proposed_by == dwell.METHOD
    assert set(diag.model_file["effects"]) == {"current_loop"}
    assert 500 < diag.model_file["effects"]["current_loop"]["bandwidth_hz"] < 900


def test_stribeck_beside_a_flexibility_that_the_held_out_test_leaves_unconfirmed_is_judged_on_the_closed_loop() -> None:
    """The Stribeck + flexibility EMPS log on a seed where the inverse model's F-test finds Stribeck friction but its held-out test does not confirm it.

    Measured (seed 1303): F-test p ~ 1e-35 and below, held-out p = 0.027; proposed on the closed loop, the replay accepts it
    (p = 9.5e-10 when the search held levels, not impulses); the refit (the searched level its start) then gives Fs 3.63 N
    (truth 3.53: 3 %), vs 7.76 mm/s (8: 3 %) and the flexibility within 2 %. Before, Stribeck friction was missed on
    this seed. Since the inverse model's held-out test confirms a proposal at 0.05, p = 0.027 confirms it as a proposal
    but not at 0.01 (``SelectSettings.alpha_confirm``): the closed loop values it still (the inverse model's peak was 130 % off).
    """
    from ilic_cli.diagnosis.select import Selection, SelectSettings
    from tests.corpus import case_of

    require_shared()  # the EMPS reference trajectory is DATA_EMPS.mat's
    name = "stribeck+flexibility-emps-current_loop-s303@s1303"
    case = case_of(name)
    diag = diagnosed(name)
    assert [f.effect.id for f in diag.findings] == ["flexibility", "delay", "stribeck"]
    sc = score(case, [(x.effect.id, x.plant_effect) for x in diag.findings])
    assert sc["false_alarms"] == 0 and sc["missed"] == []
    (ev,) = [e for step in diag.tried for e in step if e.effect == "stribeck"][-1:]
    assert ev.reason.startswith(Selection.ACCEPTED.value + "; valued on the closed loop instead: the replay agrees") and ev.test.p_adjusted < 1e-3
    assert ev.heldout_p_value is not None and SelectSettings().alpha_confirm <= ev.heldout_p_value < SelectSettings().alpha_heldout
    (verdict,) = [v for v in diag.decisions if v.effect == "stribeck"]
    assert verdict.accepted and verdict.proposed_by == dwell.METHOD and verdict.p_value is not None and verdict.p_value < 1e-6
    assert diag.refit is not None and diag.refit.accepted
    (f,) = [x for x in diag.findings if x.effect.id == "stribeck"]
    assert f.method != dwell.METHOD  # the refit's
    assert all(abs(e) <= 0.1 for e in sc["parameter_error"].values()), sc["parameter_error"]
    text = to_markdown(diag)
    assert "proposed on the closed loop, since the inverse model's F-test finds it" in text
    assert "This replay is noise-free" not in text and "do not resolve the stick and break-away there" not in text


def test_the_rows_in_motion_are_those_whose_span_touches_a_step_of_the_reference() -> None:
    """A dwell from sample 10 to 29 (the reference still there): undecimated, the samples that step in or out of it are in
    motion, the rest of it not; decimated by 4, a row is in motion where its span (3 samples either side of its kept
    sample, as ``valid_rows``) touches such a sample."""
    q = np.r_[np.linspace(0.0, 1.0, 11), np.ones(19), np.linspace(1.0, 0.0, 11)[1:]]
    every = dwell.reference_moving(q, 1)
    assert every[:11].all() and not every[11:29].any() and every[29:].all()
    rows = dwell.reference_moving(q, 4)
    kept = kept_indices(len(q), 4)
    assert rows.tolist() == [bool(every[max(k - 3, 0) : k + 4].any()) for k in kept]
    assert rows.any() and not rows.all()
    assert len(dwell.reference_moving(np.zeros(0), 4)) == 0 and not dwell.reference_moving(np.ones(7), 2).any()


def _replays(moving: np.ndarray) -> HeldoutReplays:
    """A held-out replay's bookkeeping without a log: every sample held out, the recorded force 1 N."""
    hr = object.__new__(HeldoutReplays)
    hr.moving_tau, hr.tau_dec, hr.idx_tau = moving, np.ones(len(moving)), np.arange(len(moving))
    return hr


def test_a_friction_at_low_speed_whose_replay_falls_at_rest_only_is_rejected() -> None:
    """The held-out test on the rows in motion: a fall at the dwells alone is rejected with the two errors in its sentence; the
    same fall with one where the reference moves too is kept."""
    rng = np.random.default_rng(4)
    n = 400
    moving = np.arange(n) % 4 != 0
    before = 0.05 * rng.standard_normal(n)
    at_rest_only = np.where(moving, before + 1e-4 * rng.standard_normal(n), 0.2 * before)
    hr = _replays(moving)
    verdict, why = hr.in_motion((before, before, None), (at_rest_only, at_rest_only, None), "agrees")
    assert verdict is Verdict.AT_REST_ONLY and "where the reference rests" in why and f"against {dwell.IN_MOTION_ALPHA:g}" in why
    both = 0.5 * before
    verdict, why = hr.in_motion((before, before, None), (both, both, None), "agrees")
    assert verdict is Verdict.AGREES and why.startswith("agrees; where the reference moves p = ")


def test_a_lag_the_segments_fit_holds_is_reported_as_the_inverse_models_estimate() -> None:
    """The open-loop segments' fit holds a value on a linear scale at its start (a drive lag, ``segment_refit``): beside Stribeck
    friction it estimates (robot corpus, lin12 trapezoid at 500 Hz with the 700 Hz current loop, s210), the lag is the inverse
    model's, and the report says so, in one column; it said "Estimated by the open-loop segments' output error" beside an
    identical inverse-model column (planted: the refit's method for every finding, fails)."""
    from ilic_cli.diagnosis.core import diagnose
    from tests.corpus.robot import build, case_named

    diag = diagnose(build(case_named("lin12/trapezoid/500Hz/current_loop/stribeck/s210")).log)
    methods = {f.effect.id: f.method for f in diag.findings}
    assert diag.refit is not None and diag.refit.accepted and diag.refit.method == segments.METHOD
    assert methods == {"delay": "IDIM-LS", "stribeck": segments.METHOD}
    lag = to_markdown(diag).split("`delay`")[1].split("###")[0]
    assert "Estimated by the inverse model (IDIM-LS)." in lag and "| parameter | value | std |" in lag


def test_the_closed_loops_proposal_takes_the_place_of_the_inverse_models_step() -> None:
    """:func:`decide.in_its_place`: where the inverse model proposed the effect (material or not), there; where it did not, last."""
    stribeck, delay, spring = (Step(EFFECTS[e], v) for e, v in (("stribeck", 0.06), ("delay", -3.7e-4), ("spring", None)))
    on_loop = Step(EFFECTS["stribeck"], 0.061, level=(29.8,))
    assert in_its_place([stribeck, delay], on_loop, ["stribeck", "delay"]) == [on_loop, delay]
    assert in_its_place([spring, stribeck, delay], on_loop, ["spring", "stribeck", "delay"]) == [spring, on_loop, delay]
    # proposed by the inverse model and found immaterial there: still in its place among the material steps
    assert in_its_place([spring, delay], on_loop, ["spring", "stribeck", "delay"]) == [spring, on_loop, delay]
    assert in_its_place([delay, spring], on_loop, ["delay", "spring"]) == [delay, spring, on_loop]
    assert in_its_place([], on_loop, []) == [on_loop]


def test_a_lag_proposed_after_a_stribeck_friction_is_judged_with_that_friction_in_the_replay() -> None:
    """``--beyond``'s 3 kg·m² S-curve at 1.5 kHz with the 700 Hz current loop and Stribeck friction of 4.8 Fc (s5059).

    The inverse model proposes the friction first, then a lag of -0.372 ms (the loop's is 0.227 ms: 64 % long); the closed
    loop values the friction at the dwells. Judged last, the friction left the lag judged on a plant without it, which kept
    it (held-out force error 25.9 % -> 24.9 %, p = 7.6e-12): a false finding. In the inverse model's place the friction is
    judged first (25.9 % -> 1.27 %) and the lag after it is rejected (1.20 % -> 1.21 %): the friction alone is named.
    """
    (case,) = [c for c in robot.beyond_cases() if c.name == "rev3/s-curve/1500Hz/current_loop/stribeck/s5059"]
    built = robot.build(case)
    diag = diagnose(built.log)
    assert [f.effect.id for f in diag.findings] == ["stribeck"]
    proposed = [[ev.effect for ev in step if ev.outcome is Selection.ACCEPTED] for step in diag.tried]
    assert proposed[:2] == [["stribeck"], ["delay"]]  # the inverse model's order: the friction, then the lag
    by = {v.effect: v for v in diag.decisions}
    friction, lag = by["stribeck"], by["delay"]
    assert friction.accepted and friction.proposed_by == dwell.METHOD and lag.verdict is Verdict.NO_FALL
    assert friction.force_after is not None and lag.force_before is not None and friction.force_before is not None
    assert lag.force_before < 0.1 * friction.force_before  # the lag judged on the plant with the friction, not without
    assert robot.score(built, [(f.effect.id, f.plant_effect, None) for f in diag.findings], {})["false_alarms"] == 0
