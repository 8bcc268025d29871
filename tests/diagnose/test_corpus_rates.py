"""The diagnosis on the corpus of plant logs with known truth (issue #11; ``tests/corpus/__init__.py``).

The whole corpus (32 clean, 32 concealed-effect logs) is run by
``python benchmarks/diagnose_corpus.py``; its figures are in docs/diagnosis.md. Here,
within the suite's time budget: 4 clean logs of seed 1, a Latin square of the
trajectory-by-noise grid (every trajectory once, every noise model once), must give no finding other than ``offset`` (the
issue's rate is >= 95 %; measured 32 of 32, so none is allowed here; a current
loop's lag is physics), and one concealed-effect log per effect must name that
effect, alone but for such a lag, within 15 % (:data:`ONE_PER_EFFECT`).
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.core import diagnose
from ilic_cli.effects.definition import Z95
from ilic_cli.runlog import RunLog
from tests.conftest import require_shared
from tests.corpus import CASES, CLEAN_CASES, DELAY_SIZE_TOLERANCE, NOISE_MODELS, PARAM_TOLERANCE, TRAJECTORY_KINDS, build_case, expected_delay_s, score
from tests.diagnose.corpus_cache import diagnosed

CLEAN_SEED_1 = [
    c.name
    for c in CLEAN_CASES
    if c.seed == 1 and (TRAJECTORY_KINDS.index(c.trajectory) + list(NOISE_MODELS).index(c.noise)) % 4 == 0  # a Latin square of the grid
]
"""The clean logs the suite diagnoses: a quarter of the seed's grid, balanced (the suite's time budget: the checkerboard's
other four cost 18 s of CPU; ``python benchmarks/diagnose_corpus.py`` diagnoses all 32)."""

ONE_PER_EFFECT = [
    "asymmetric_friction-multisine-disturbance-s201",
    "stribeck-trapezoid-sensor-s210",  # diagnosed for tests/diagnose/test_dwell.py too (shared); the multisine's s212 costs 12 s of CPU more
    "position_ripple-emps-disturbance-s221",  # the paper trajectory's s222 (10 s of CPU more) is diagnosed resampled below
    "spring-emps-sensor-s230",
    "payload_change-trapezoid-current_loop-s242",
    "delay-multisine-current_loop-s252",
]
"""A log per catalogue effect but the flexibility, which the closed-loop diagnosis names on the EMPS reference beside Stribeck
friction (``tests/diagnose/test_dwell.py``, s303 reseeded) and on three robot-corpus logs (``test_diagnose_refit.py``): its
own log here, ``flexibility-paper-sensor-s260``, cost 6.6 s of CPU (the suite's budget; ``python benchmarks/diagnose_corpus.py``
diagnoses it)."""


def _scored(name: str) -> tuple[dict, list[tuple[str, dict | None]]]:
    case = CASES[name]
    if case.trajectory == "emps":
        require_shared()  # the EMPS reference trajectory is DATA_EMPS.mat's
    diag = diagnosed(case.name)
    findings = [(f.effect.id, f.plant_effect) for f in diag.findings]
    return score(case, findings), findings


def test_the_clean_subset_has_every_trajectory_and_every_noise_model_once() -> None:
    cells = {(CASES[n].trajectory, CASES[n].noise) for n in CLEAN_SEED_1}
    assert len(CLEAN_SEED_1) == len(cells) == 4
    assert {t for t, _ in cells} == set(TRAJECTORY_KINDS) and {z for _, z in cells} == set(NOISE_MODELS)
    assert ("multisine", "combined") in cells  # the lag that the replay does not keep on the multisine (not asserted there)
    assert ("trapezoid", "current_loop") in cells  # diagnosed for tests/diagnose/test_dwell.py too (shared)


@pytest.mark.parametrize("name", CLEAN_SEED_1)
def test_a_clean_log_has_no_false_alarm(name: str) -> None:
    """No finding but ``offset`` and, with a current loop, the loop's lag (0.23 ms) as a drive lag.

    The lag is shorter than a sample; the replay judges it like any other effect (realised as the first-order
    current loop) and keeps it on every log with the loop and the paper, trapezoid or EMPS reference, on none
    without. Measured beyond the hold: 0.215-0.252 ms for the loop's 0.227 ms; right within
    :data:`tests.corpus.DELAY_SIZE_TOLERANCE` (50 %). On the multisine (below 1.2 Hz) the
    lag moves the replay too little to be kept, and it is not asserted there.
    """
    s, findings = _scored(name)
    assert s["false_alarms"] == 0, findings
    case = CASES[name]
    lags = [-plant["delay"] for eid, plant in findings if eid == "delay" and plant is not None]
    if "current_loop" not in NOISE_MODELS[case.noise]:
        assert not lags, findings
    elif case.trajectory != "multisine":
        assert len(lags) == 1 and abs(lags[0] - expected_delay_s(case)) <= DELAY_SIZE_TOLERANCE * expected_delay_s(case), findings


@pytest.mark.parametrize("name", ONE_PER_EFFECT)
def test_a_concealed_effect_is_named_alone(name: str) -> None:
    """The concealed effect is named, and nothing else but ``offset`` and a current loop's lag (:func:`tests.corpus.score`)."""
    s, findings = _scored(name)
    truth = set(CASES[name].effects)
    assert truth <= {eid for eid, _ in findings} and not s["missed"] and s["false_alarms"] == 0, findings
    # the delay measured beyond the hold, refined on the closed loop (the inverse model's lag was 38 % too long here)
    assert all(err <= PARAM_TOLERANCE for err in s["parameter_error"].values()), s


def test_an_irregularly_sampled_log_is_diagnosed_on_its_uniform_grid() -> None:
    """5 % of the samples lost at random: the ripple is still named, and the replay compares like with like.

    Measured: A = 1.87 N (truth 1.86), simulated force error 13.4 %; on the raw stamps the replay's error was 140 % and nothing was named.
    """
    case = CASES["position_ripple-paper-current_loop-s222"]
    log = build_case(case)
    keep = np.sort(np.random.default_rng(7).choice(len(log), size=int(0.95 * len(log)), replace=False))
    diag = diagnose(RunLog({k: v[keep] for k, v in log.channels.items()}, dict(log.units), dict(log.meta)))
    findings = [(f.effect.id, f.plant_effect) for f in diag.findings]
    s = score(case, findings)
    assert [eid for eid, _ in findings] == ["position_ripple"] and all(err <= PARAM_TOLERANCE for err in s["parameter_error"].values()), findings
    assert diag.fit["simulation_force_relative_error_pct"]["before"] < 20.0


def test_a_one_ms_lag_the_inverse_model_overestimates_is_judged_at_its_closed_loop_value() -> None:
    """The corpus's smallest drive lag (1.0 ms, sensor noise): the inverse model puts it at 1.66 ms.

    Judged at that value the replay's fall was not significant (1.36 % -> 1.29 %, p = 0.019) and the lag
    was missed. Searched on each fold's training blocks (``decide.fold_value``), measured: held-out
    1.36 % -> 0.966 % (p = 6e-15), fold values 0.94-1.0 ms; after the closed-loop refit 1.0006 ms.
    """
    name = "delay-multisine-sensor-s250"
    case = CASES[name]
    diag = diagnosed(case.name)
    findings = [(f.effect.id, f.plant_effect) for f in diag.findings]
    s = score(case, findings)
    assert {eid for eid, _ in findings} - {"offset"} == {"delay"} and s["parameter_error"]["delay"] <= PARAM_TOLERANCE, findings
    (verdict,) = [v for v in diag.decisions if v.effect == "delay"]
    assert verdict.accepted and "searched on the closed loop of each fold's training blocks" in verdict.reason, verdict.reason
    assert verdict.searched is not None and len(verdict.searched) == 5 and all(0.8e-3 < -v < 1.2e-3 for v in verdict.searched), verdict.searched
    assert verdict.to_dict()["fold_values"] == list(verdict.searched) and verdict.to_dict()["proposed_by"] == "inverse model"
    (ev,) = [e for e in diag.tried[0] if e.effect == "delay"]
    assert abs(ev.value) > 1.4e-3  # the inverse model's value the replay no longer judges


def test_stamp_jitter_is_not_read_as_timing() -> None:
    """The 1 ms lag's log with its stamps jittered by +-0.3 ms (30 % of a period): the samples were taken on time.

    Measured at +-0.2 ms: on the jittered stamps as they were, the delay's shift read the jitter as timing and the
    lag was missed (F = 0, "no significant mismatch"); restamped on the 1 kHz grid it is named at 1.0006 ms, as on
    the clean stamps. At +-0.3 ms the steps scatter over 0.4-1.6 periods: read by the steps alone, the log was
    irregular sampling, interpolated between the noisy stamps, and the replay of that log diverged (t = 4.4 s; on a
    clean EMPS-reference log it named a flexibility). The stamps are within 0.3 periods of one clock
    (:func:`ilic_cli.timebase.jittered_clock`), so they are restamped as at +-0.2 ms.
    """
    case = CASES["delay-multisine-sensor-s250"]
    log = build_case(case)
    t = log.t + np.random.default_rng(0).uniform(-0.3e-3, 0.3e-3, len(log))
    diag = diagnose(RunLog({**log.channels, "t": t}, dict(log.units), dict(log.meta)))
    findings = [(f.effect.id, f.plant_effect) for f in diag.findings]
    s = score(case, findings)
    assert {eid for eid, _ in findings} - {"offset"} == {"delay"} and s["parameter_error"]["delay"] <= PARAM_TOLERANCE, findings
    assert any("stamp jitter" in w and "restamped" in w for w in diag.warnings), diag.warnings
    (clean,) = [f.plant_effect["delay"] for f in diagnosed(case.name).findings if f.effect.id == "delay"]
    assert dict(findings)["delay"]["delay"] == pytest.approx(clean, rel=1e-6)  # the samples were on time: the same lag


def test_a_lag_refitted_on_the_closed_loop_is_stated_with_at_least_the_folds_spread() -> None:
    """The refit's curvature gave the 1.0 ms lag of s250 ± 0.018 ms at -0.952 ms (2.7 of it off); the five folds' values
    (the decision's replays, each searched on its training blocks) spread by a jackknife's 0.054 ms, which the finding and
    its search state (:func:`ilic_cli.diagnosis.refit.with_folds_spread`)."""
    diag = diagnosed("delay-multisine-sensor-s250")
    (verdict,) = [v for v in diag.decisions if v.effect == "delay"]
    assert diag.refit is not None
    (search,) = [s for s in diag.refit.searches if s.effect == "delay"]
    folds = np.asarray(verdict.searched, dtype=np.float64)
    jackknife = float(np.sqrt((len(folds) - 1) / len(folds) * np.sum((folds - folds.mean()) ** 2)))
    assert search.std == pytest.approx(jackknife, rel=1e-12) and "folds' jackknife" in search.reason, search
    (finding,) = [f for f in diag.findings if f.effect.id == "delay"]
    assert finding.parameters["delay"].std == pytest.approx(jackknife, rel=1e-12)
    assert abs(finding.parameters["delay"].value + 0.001) < Z95 * jackknife  # the truth within what is stated
