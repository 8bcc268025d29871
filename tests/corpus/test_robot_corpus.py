"""The robot corpus (issue 29 item 8): its design, its rates, and its stratified subset in the suite.

The whole corpus (189 logs) is ``make corpus`` (``benchmarks/corpus_robot.py --check``; docs/diagnosis.md has its
table). Here, within the suite's time: one log per rate (250 Hz to 8 kHz) x joint type, clean and with an effect in
turn (:data:`tests.corpus.robot.CI_SLOTS`), each through the writer the corpus gives it (CSV or a ROS 2 bag read by
``ilic`` with the PD loop given by its flags, or the library), held to the issue's "Done when": a clean log has no
finding but ``offset`` (and, with a current loop, a lag of that size), an effect log is named exactly with its
parameters within 15 %, and ``identify --method ls`` is within 2 % of M, Fv, Fc on a clean dwell-and-move log and
fits the rows ``diagnose`` fits.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from statistics import NormalDist

import numpy as np
import pytest

from ilic_cli.effects import catalogue_ids
from tests.corpus.measure import IDENTIFY_TOLERANCE, failures, run_case, summary
from tests.corpus.robot import (
    AXES,
    BAND_PTS,
    BEYOND_AXES,
    BEYOND_RATES_HZ,
    DWELL_TRAJECTORIES,
    EDGE_RATES_HZ,
    RATES_HZ,
    TOLERANCE,
    TRAJECTORIES,
    beyond_cases,
    build,
    cases,
    ci_subset,
)

SUBSET = ci_subset()


def test_the_design_covers_the_issues_axes() -> None:
    """3+ rates, both joints, 3+ scales, the four trajectories, every catalogue effect, gravity, drift, pairs, 3 seeds each."""
    all_cases = cases()
    assert len({c.name for c in all_cases}) == len(all_cases)
    assert {c.fs_hz for c in all_cases} == {*RATES_HZ, *EDGE_RATES_HZ} and {c.trajectory for c in all_cases} == set(TRAJECTORIES)
    assert {a.joint for a in AXES.values()} == {"prismatic", "revolute"} and len(AXES) >= 3
    assert sum(c.clean for c in all_cases) >= 40  # enough to measure 1 in 40
    assert {c.writer for c in all_cases} == {"csv", "ros2", "library"}
    singles = Counter((c.axis, c.effects[0]) for c in all_cases if len(c.effects) == 1 and c.fs_hz in RATES_HZ)
    for name, axis in AXES.items():
        wanted = (set(catalogue_ids(axis.joint)) - {"offset"}) | {"friction_drift"}
        assert {e for a, e in singles if a == name} == wanted, name
    assert all(n >= 3 for n in singles.values())
    pairs = Counter(c.effects for c in all_cases if len(c.effects) == 2)
    assert len(pairs) >= 4 and all(n >= 3 for n in pairs.values())
    assert {(c.fs_hz, AXES[c.axis].joint) for c in SUBSET} == {(f, j) for f in (*RATES_HZ, *EDGE_RATES_HZ) for j in ("prismatic", "revolute")}


def test_the_logs_beyond_the_design_share_none_of_its_axes_rates_or_loop() -> None:
    """``--beyond``: other masses (2 and 50 kg, 0.002 and 3 kg·m²), rates (400 Hz, 1.5 and 4 kHz) and PD loops; every effect
    each axis can have, clean logs on every axis x rate x dwell trajectory, all four trajectories, both writers."""
    beyond = beyond_cases()
    assert len({c.name for c in beyond}) == len(beyond) and not {c.name for c in beyond} & {c.name for c in cases()}
    assert {c.axis for c in beyond} == set(BEYOND_AXES) and not set(BEYOND_AXES) & set(AXES)
    assert {c.fs_hz for c in beyond} == set(BEYOND_RATES_HZ) and not set(BEYOND_RATES_HZ) & {*RATES_HZ, *EDGE_RATES_HZ}
    assert {a.bandwidth_hz for a in BEYOND_AXES.values()} & {a.bandwidth_hz for a in AXES.values()} == set()
    assert {c.trajectory for c in beyond} == set(TRAJECTORIES) and {"csv", "library"} <= {c.writer for c in beyond}
    for name, axis in BEYOND_AXES.items():
        wanted = (set(catalogue_ids(axis.joint)) - {"offset"}) | {"friction_drift"}
        assert {c.effects[0] for c in beyond if c.axis == name and not c.clean} == wanted, name
        assert {(c.fs_hz, c.trajectory) for c in beyond if c.axis == name and c.clean} >= {(f, t) for f in BEYOND_RATES_HZ for t in DWELL_TRAJECTORIES}


def test_a_case_is_deterministic_and_sized_in_the_band() -> None:
    """Same case, bit-identical log; the effect is sized on its own log to change the rigid fit's error by 0.2-1.5 points."""
    case = next(c for c in cases() if c.fs_hz == 250.0 and c.effects == ("spring",))
    a, b = build(case), build(case)
    assert all(np.array_equal(a.log[n], b.log[n]) for n in ("t", "q", "tau", "q_ref")) and a.effects == b.effects
    assert BAND_PTS[0] <= a.size_pts <= BAND_PTS[1], a.size_pts


def test_the_rates_fail_where_the_issue_says() -> None:
    """``make corpus`` exits 1 on 2 false alarms in 40 clean logs, on 89 % named exactly, on one identify beyond 2 %."""
    ok = {"clean": 40, "clean_with_false_alarm": 1, "effect_logs": 100, "named_exactly": 90, "effects_named": 100, "effects_total": 100}
    ok |= {"parameters_compared": 10, "parameters_within": 10, "identify_logs": 5, "identify_within": 5, "identify_same_rows": 5}
    assert failures(ok) == []
    assert len(failures({**ok, "clean_with_false_alarm": 2})) == 1 and len(failures({**ok, "named_exactly": 89})) == 1
    assert len(failures({**ok, "identify_within": 4})) == 1 and len(failures({**ok, "parameters_within": 9})) == 1


def test_an_effect_log_below_the_band_counts_in_no_rate() -> None:
    """A log whose concealed effect moves the rigid fit by less than the band's 0.2 points (its effect immaterial on it) is
    counted apart, neither named nor missed; at the band's edge it counts."""

    def row(size: float, exact: bool) -> dict[str, object]:
        return {"clean": False, "size_pts": size, "exact": exact, "truth": {"spring": {}}, "missed": [] if exact else ["spring"]}

    base = {"parameter_error": {}, "identify": None, "false_alarms": 0}
    s = summary([{**base, **row(0.5, True)}, {**base, **row(0.09, False)}, {**base, **row(BAND_PTS[0], False)}])
    assert (s["effect_logs"], s["named_exactly"], s["below_band"], s["effects_total"], s["effects_named"]) == (2, 1, 1, 2, 1)


def test_a_parameter_beyond_15_percent_is_judged_by_what_the_diagnosis_states_of_it() -> None:
    """Measured beside the rate: within 1.96 of its stated σ, or stated undetermined, counts as stated; a σ that does not
    reach the truth does not; a value the finding states no σ of is not judged; a lag is judged by the stated delay, a drift by its stated change and time
    constant."""
    from tests.corpus.robot import within_stated

    truth, got = {"MX": 1.0, "MY": 1.0}, {"MX": 1.5, "MY": 1.05}  # MY within 15 %: not judged
    assert within_stated(truth, got, {"MX": {"std": 0.3, "determined": True}}) is True
    assert within_stated(truth, got, {"MX": {"std": 0.2, "determined": True}}) is False
    assert within_stated(truth, got, {"MX": {"std": 0.01, "determined": False}}) is True
    assert within_stated(truth, got, {"MY": {"std": 1.0, "determined": True}}) is None
    assert within_stated({"lag": 1e-3}, {"lag": 2e-3}, {"delay": {"std": 0.4e-3, "determined": True}}) is False
    # a drift: its change and time constant, as the finding states them per drifting coefficient
    truth, got = {"dFv": -90.0, "dFc": 0.0, "tau": 2.5}, {"dFv": -115.0, "dFc": 0.0, "tau": 3.0}
    stated = {"Fv_change": {"std": 10.0, "determined": True}, "Fv_tau": {"std": 1.0, "determined": True}}
    assert within_stated(truth, got, stated) is False
    assert within_stated(truth, got, {**stated, "Fv_change": {"std": 13.0, "determined": True}}) is True
    assert within_stated(truth, got, {**stated, "Fv_tau": {"std": 0.2, "determined": True}}) is False
    rows = [{"clean": False, "size_pts": 0.5, "exact": True, "truth": {"gravity": {}}, "missed": [], "false_alarms": 0, "identify": None,
             "parameter_error": {"gravity": 0.5}, "parameter_stated": {"gravity": v}} for v in (True, False, None)]  # fmt: skip
    s = summary(rows)
    assert (s["parameters_within"], s["parameters_beyond_judged"], s["parameters_beyond_within_stated"]) == (0, 2, 1)


Z99 = NormalDist().inv_cdf(0.995)
"""The two-sided 99 % point of the normal distribution (over the corpus's 40 disturbance logs the truth lies within it on 114 of 120 of M, Fv,
Fc; within 1.96 on 99)."""

SHORT_OF_THE_DONE_WHEN: dict[str, str] = {
    # the 10 Hz force disturbance's spread: Fc -2.5 % where identify's own robust σ of Fc is 3.1 % (z = -0.8)
    "rev0.01/s-curve/500Hz/disturbance/clean/s25": "identify",
}
"""Subset logs on which the current code misses one part of the "Done when" (issue 29 stays open on them), by the part missed.
Every other part is held on them; the part missed is asserted to be missed still, so a fix fails here until its entry goes."""


@pytest.mark.parametrize("case", SUBSET, ids=[c.name for c in SUBSET])
def test_the_subset_meets_the_done_when(case) -> None:  # noqa: ANN001 - a Case
    row = run_case(case)
    short = SHORT_OF_THE_DONE_WHEN.get(case.name)
    if short is None:
        assert failures(summary([row])) == [], (row["findings"], row["false_alarm_reasons"], row["missed_reasons"], row["parameter_error"], row["identify"])
    if case.clean:
        assert row["false_alarms"] == 0 and not row["missed"], row["findings"]
        if case.trajectory in DWELL_TRAJECTORIES:
            ident = row["identify"]
            assert ident is not None and ident["same_rows"], ident
            within = all(abs(e) <= IDENTIFY_TOLERANCE for e in ident["error"].values())
            assert within is (short != "identify"), ident
            if short == "identify":  # short of 2 %, never of what identify states: the truth within its 99 % robust interval
                assert all(abs(z) <= Z99 for z in ident["z"].values()), ident
    else:
        assert row["exact"] and set(row["parameter_error"]) == set(case.effects), (row["findings"], row["missed_reasons"])
        within = all(e <= TOLERANCE for e in row["parameter_error"].values())
        assert within is (short != "parameters"), row["parameter_error"]
        assert BAND_PTS[0] <= row["size_pts"] <= BAND_PTS[1], row["size_pts"]


def test_a_size_whose_log_is_refused_is_beyond_the_band(monkeypatch: pytest.MonkeyPatch) -> None:
    """A size at which the loop saturates the drive gives a log ``identify`` refuses (``--reseed 9`` s27510's flexibility): the
    calibration takes it for a change beyond the band and sizes below it, not a crash of the whole corpus run (planted: the
    refusal not caught, fails)."""
    from ilic_cli.errors import IdentificationError
    from tests.corpus import robot

    size = [0.0]  # the size of the effect last simulated
    real = robot.effect_of_size

    def sized(eid: str, s: float, *args: object) -> dict[str, float]:
        size[0] = s
        return real(eid, s, *args)  # type: ignore[arg-type]

    def error_pct(log: object) -> float:
        if size[0] > 0.5:  # the doubling's 0.8 and the bisection's 0.566 saturate
            raise IdentificationError(
                "robot-corpus", "only 3 decimated rows are left once the samples left out (a saturated drive, the axis at rest, a gap's edges) are masked"
            )
        return 1.0 + size[0]

    monkeypatch.setattr(robot, "effect_of_size", sized)
    monkeypatch.setattr(robot, "simulate", lambda case, effects: None)
    monkeypatch.setattr(robot, "relative_error_pct", error_pct)
    s, change = robot.calibrate(robot.case_named("rev0.5/trapezoid/500Hz/sensor/flexibility/s510"), "flexibility", 0.5, 1.0)
    assert 0.4 < s <= 0.5 and change == pytest.approx(s) and BAND_PTS[0] <= change <= BAND_PTS[1]


SIZED_AT_B0588D = (
    ("lin12/chirp/1000Hz/sensor/clean/s8", None, 4.707549068213841),
    ("lin12/trapezoid/500Hz/current_loop/clean/s4", None, 0.5027450896269856),
    ("lin12/trapezoid/250Hz/current_loop/clean/s103", "stribeck", 2.449920555752864),
    ("rev0.5/s-curve/250Hz/sensor/clean/s113", "stribeck", 3.0713394248206485),
)
"""``identify --method ls``'s relative error (%) at b0588dd, with no lag, on logs of the corpus (clean, or with a Stribeck friction
of 2.4 times the calibration's first size; every log of the corpus starts and ends at rest)."""


@pytest.mark.parametrize(("name", "effect", "error_pct"), SIZED_AT_B0588D, ids=[f"{n}/{e}" for n, e, _ in SIZED_AT_B0588D])
def test_the_corpus_sizes_its_effects_as_identify_did_when_it_was_sized(name: str, effect: str | None, error_pct: float) -> None:
    """The corpus's own size measure (``robot.relative_error_pct``, held apart from ``identify`` so that a change to how ``identify``
    builds its rows does not resize the corpus) gives ``identify``'s error of b0588dd bit for bit (measured on 510 logs: the
    corpus's clean logs and its effects at twice and sixteen times the calibration's first size, all equal; planted: the rows at
    rest kept, fails)."""
    from tests.corpus import robot

    case = robot.case_named(name)
    effects = {} if effect is None else {effect: robot.effect_of_size(effect, 2.4, robot.ALL_AXES[case.axis], case.variant, case.duration_s)}
    assert robot.relative_error_pct(robot.simulate(case, effects)) == error_pct


def test_the_corpus_size_measure_is_identify_s_error_where_no_sample_is_left_out(emps_mat: Path) -> None:
    """Where ``identify`` leaves no sample out (``DATA_EMPS.mat``: no dwell, no saturation) the corpus measure's rows are its rows:
    the same preparation, model and rows, the same error bit for bit."""
    from ilic_cli.identify import identify
    from ilic_cli.io import read_log
    from tests.corpus import robot

    log = read_log(emps_mat)
    report = identify(log, method="ls", effects={"delay": 0.0})
    assert report.ls is not None and report.usable.at_rest == 0 and report.usable.saturated == 0
    assert robot.relative_error_pct(log) == float(report.ls.result.relative_error_pct)
