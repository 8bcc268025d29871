"""Stribeck friction at a trajectory's dwells (``ilic_cli/diagnosis/dwell.py``) and a lag within the sample as the current loop: the pure parts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ilic_cli.closed_loop_id import plant_of
from ilic_cli.diagnosis import dwell
from ilic_cli.diagnosis.core import model_parameters
from ilic_cli.diagnosis.select import Step
from ilic_cli.effects import EFFECTS, Fit
from ilic_cli.simulation.timing import vertex

STRIBECK = EFFECTS["stribeck"]


def test_reference_dwells_counts_rests_of_the_reference() -> None:
    fs = 1000.0
    t = np.arange(0, 4.0, 1 / fs)
    moving = np.sin(2 * np.pi * 0.5 * t)
    assert dwell.reference_dwells(moving, fs) == 0
    steps = np.floor(t / 0.5) * 0.01  # a staircase: at rest 0.5 s at a time, 8 rests (the jumps between them are moves)
    assert dwell.reference_dwells(steps, fs) == 8
    short = np.floor(t / 0.04) * 0.01  # rests of 40 ms: shorter than a dwell
    assert dwell.reference_dwells(short, fs) == 0
    assert dwell.reference_dwells(np.zeros(1), fs) == 0


def _surface(v0: float, f0: float):  # type: ignore[no-untyped-def]
    """A training error with its least at ``(v0, f0)``, quadratic in the logs of ``vs`` and of the impulse ``Fs·vs``."""
    calls: list[tuple[float, float]] = []

    def error(st: Step) -> float:
        assert st.level is not None
        calls.append((float(st.value), st.level[0]))
        return 1.0 + (math.log(float(st.value) / v0)) ** 2 + (math.log(st.level[0] * float(st.value) / (f0 * v0))) ** 2

    return error, calls


def _near(found: Step | None, v0: float, f0: float) -> bool:
    """``found`` within the search's resolution of ``(v0, f0)``: a sixteenth of each grid's step in ``vs`` and in the impulse."""
    vs, impulse = _grids()
    assert found is not None and found.level is not None
    dv, da = math.log(float(found.value) / v0), math.log(found.level[0] * float(found.value) / (f0 * v0))
    tol_v, tol_a = math.log(vs[1] / vs[0]) / 2 ** (dwell.HALVINGS + 1), math.log(impulse[1] / impulse[0]) / 2 ** (dwell.HALVINGS + 1)
    return abs(dv) <= tol_v * (1 + 1e-9) and abs(da) <= tol_a * (1 + 1e-9)


def _grids() -> tuple[np.ndarray, np.ndarray]:
    """The searched ``vs`` (8, the proposal's at the middle) and impulses, for a Coulomb level of 20 N."""
    vs = np.geomspace(0.002, 0.08, 8)
    return vs, 20.0 * float(vs[4]) * np.asarray(dwell.LEVELS_OF_FC)


def test_search_finds_an_interior_optimum_between_the_grid_points() -> None:
    vs, impulse = _grids()
    error, calls = _surface(0.011, 1.7)
    found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=2.0)
    assert _near(found, 0.011, 1.7)
    refining = 2 * 2 * dwell.HALVINGS  # each coordinate: two replays a halving
    assert len(set(calls)) <= len(impulse) + len(vs) + len(impulse) + refining < len(vs) * len(impulse)  # not the whole grid


def test_search_finds_a_peak_above_half_the_coulomb_level() -> None:
    """A static friction 1.7 times the Coulomb level (Fs = 0.7 Fc): inside the impulses searched, not on their edge."""
    vs, impulse = _grids()
    error, calls = _surface(0.011, 14.0)
    found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=2.0)
    assert _near(found, 0.011, 14.0)
    first = next(k for k, (v, _) in enumerate(calls) if v != vs[4])  # the impulse's profile first, at the proposal's vs,
    assert first == 4 + 1 + dwell.PROFILE_RISES < len(impulse)  # to its least (index 4, half Fc) and the rises past it


@pytest.mark.parametrize(("v0", "f0"), [(0.011, 96.0), (0.005, 600.0), (0.04, 70.0)])
def test_search_finds_a_peak_of_several_coulomb_levels(v0: float, f0: float) -> None:
    """Static friction of 4.8 to 30 times the Coulomb level (the corpus's S-curves s371 and s722: 4.8 Fc; s461 6.2 Fc at a
    vs above the middle one): inside the impulses searched, where levels up to 2 Fc were on their top edge in every fold."""
    vs, impulse = _grids()
    error, _ = _surface(v0, f0)
    found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=2.0)
    assert _near(found, v0, f0)


@pytest.mark.parametrize("x_min", [0.3, -0.45, 0.05])
def test_refined_finds_a_least_beside_a_cliff(x_min: float) -> None:
    """Gentle on one side, a hundred times steeper on the other (a level the axis sticks at): the least within a sixteenth
    of the grid's step, where the parabola through the grid's point and its neighbours falls up to half a step off."""
    h = 1.0

    def error(x: float) -> float:
        d = x - x_min
        return 1.0 + (d * d if d < 0 else 100.0 * d * d)

    calls: list[float] = []

    def counted(x: float) -> float:
        calls.append(x)
        return error(x)

    found, value = dwell.refined(counted, 0.0, error(0.0), h)
    assert value == error(found)
    assert abs(found - x_min) <= h / 16
    assert len(calls) == len(set(calls)) == 2 * dwell.HALVINGS  # each point replayed once
    naive = vertex(np.array([-h, 0.0, h]), np.array([error(-h), error(0.0), error(h)]), 1)
    assert abs(naive - x_min) > 2 * h / 16  # the grid's parabola: more than twice as far off


def test_a_replay_without_an_answer_is_never_the_least() -> None:
    """A point whose replay gives no number (``nan``) is passed over, in the grid and between its points."""
    vs, impulse = _grids()
    error, _ = _surface(0.011, 1.7)
    holes = lambda st: math.nan if float(st.value) > 0.05 or st.level[0] * float(st.value) < 0.005 else error(st)  # noqa: E731
    assert _near(dwell.search(dwell.proposal(vs, 20.0), vs, impulse, holes, baseline_error=2.0), 0.011, 1.7)
    assert dwell.refined(lambda x: math.nan if x < 0 else (x - 0.3) ** 2, 0.0, 0.09, 1.0)[0] == pytest.approx(0.25)


def test_search_follows_the_valley_of_a_held_impulse() -> None:
    """The loop feels the impulse ``Fs·vs``: the error's valley runs along it, and rises gently along the valley.

    A search whose ``vs`` profiles held the level stalled part way along it (s461 of the robot corpus: Fs 4.2 N, vs
    279 mm/s for 10.2 N, 120 mm/s)."""
    vs, impulse = _grids()
    v0, f0 = 0.006, 150.0

    def error(st: Step) -> float:
        assert st.level is not None
        across = math.log(st.level[0] * float(st.value) / (f0 * v0))
        along = math.log(float(st.value) / v0)
        return 1.0 + 25.0 * across**2 + 0.05 * along**2

    found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=100.0)
    assert _near(found, v0, f0)


@pytest.mark.parametrize(
    ("v0", "f0", "baseline", "why"),
    [
        (0.011, 0.2, 2.0, "the least impulse tried: no measured level"),
        (0.011, 2000.0, 2.0, "the largest impulse tried"),
        (0.0005, 40.0, 100.0, "below the vs grid (the impulse inside its grid, any fall enough)"),
        (0.5, 1.7, 100.0, "above the vs grid (the impulse inside its grid, any fall enough)"),
        (0.011, 1.7, 0.5, "does not beat the model without it"),
    ],
)
def test_search_finds_nothing_on_an_edge_or_without_a_fall(v0: float, f0: float, baseline: float, why: str) -> None:
    vs, impulse = _grids()
    error, _ = _surface(v0, f0)
    assert dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=baseline) is None, why


def test_an_impulse_that_reaches_the_grid_s_edge_after_vs_moved_is_no_estimate() -> None:
    """Inside the impulse's grid at the middle vs, its top edge at the best vs: no estimate, whatever the fall."""
    vs, impulse = _grids()
    v0, a0 = float(vs[6]), 17.6  # the least beyond the top impulse (10.5), reached once vs has moved up

    def error(st: Step) -> float:
        assert st.level is not None
        dv, da = math.log(float(st.value) / v0), math.log(st.level[0] * float(st.value) / a0)
        return 1.0 + dv * dv + (da - dv) ** 2

    assert dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=100.0) is None


@pytest.mark.parametrize(("f0", "edge"), [(0.2, 0), (2000.0, -1)])
def test_a_level_on_the_grid_s_edge_ends_the_search_before_the_second_vs_profile(f0: float, edge: int) -> None:
    """The least error's impulse on the edge gives no estimate whatever vs does there: the search stops, the answer the same.

    Each point is a closed-loop replay of the log: a clean log's search is the one profile, left once it has risen
    three times past its least level (4 replays a fold; 11 when the whole profile was walked, 17 when the vs profile
    came first, 24 before that)."""
    vs, impulse = _grids()
    error, calls = _surface(0.011, f0)
    assert dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=2.0) is None
    walked = 1 + dwell.PROFILE_RISES if edge == 0 else len(impulse)
    assert len(calls) == walked and {v for v, _ in calls} == {vs[4]}  # the impulse's profile at the proposal's vs, no more
    best = min(calls, key=lambda c: math.log(c[0] / 0.011) ** 2 + math.log(c[0] * c[1] / (0.011 * f0)) ** 2)  # the least point visited
    assert best[0] * best[1] == pytest.approx(impulse[edge])


def test_judged_needs_a_majority_of_folds() -> None:
    est = [Step(STRIBECK, v, level=(f,)) for v, f in [(0.008, 2.4), (0.010, 2.6), (0.012, 2.5)]]
    step, text = dwell.judged([*est, None, None])
    assert step is not None and step.value == pytest.approx(0.010) and step.level == (pytest.approx(2.5),)
    # the delete-a-block jackknife: sqrt((k - 1) / k * sum of squares), not the plain spread (0.1 N, 2 mm/s)
    assert step.level_std is not None and step.level_std[0] == pytest.approx(math.sqrt(2 / 3 * 0.02))
    assert step.value_std == pytest.approx(math.sqrt(2 / 3 * 8e-6))
    assert "3 of 5 folds" in text
    none, why = dwell.judged([est[0], None, None, est[1], None])
    assert none is None and "2 of 5 folds" in why
    assert dwell.fold_values([est[0], None]) == [(0.008, 2.4), None]


def test_jackknife_std() -> None:
    assert dwell.jackknife_std(np.array([1.0, 2.0, 3.0, 6.0])) == pytest.approx(math.sqrt(3 / 4 * 14.0))
    assert math.isnan(dwell.jackknife_std(np.array([1.0])))


def test_a_held_level_enters_the_plant_and_the_model_file() -> None:
    names = ("M", "Fv", "Fc", "offset")
    theta = np.array([95.0, 200.0, 20.0, 0.0])
    step = Step(STRIBECK, 0.009, level=(2.5,), level_std=(0.1,))
    rigid, effects = model_parameters([step], names, theta, np.zeros((4, 4)))
    assert rigid["Fc"] == 20.0 and effects == {"stribeck": {"Fs": 2.5, "vs": 0.009}}


def test_a_lag_within_the_sample_is_realised_as_the_current_loop() -> None:
    """Beyond the hold (half a sample), a lag shorter than the sample is the current loop's; a longer one a delay."""
    names = ("M", "Fv", "Fc", "offset")
    theta = np.array([95.0, 200.0, 20.0, 0.0])
    delay = EFFECTS["delay"]
    _, loop = model_parameters([Step(delay, -0.00024)], names, theta, np.zeros((4, 4)), 0.0005)
    assert set(loop) == {"current_loop"} and loop["current_loop"]["bandwidth_hz"] == pytest.approx(1 / (2 * math.pi * 0.00024))
    _, longer = model_parameters([Step(delay, -0.0013)], names, theta, np.zeros((4, 4)), 0.0005)
    assert longer == {"delay": {"delay": -0.0013}}
    _, unheld = model_parameters([Step(delay, -0.00024)], names, theta, np.zeros((4, 4)), 0.0)  # no held command: no sample bounds it
    assert unheld == {"delay": {"delay": -0.00024}}
    assert plant_of(names, theta, {"delay": -0.00024}, 0.0005)[1] == loop  # the closed-loop refit's plant: the same
    assert "current loop" in delay.fit_to_plant(Fit(names, theta, np.zeros((4, 4)), -0.00024, None, 0.0005))[2]


def test_a_dwell_is_a_rest_of_at_least_fifty_ms_of_a_still_reference() -> None:
    fs = 1000.0
    n_rest = int(dwell.DWELL_MIN_S * fs)  # n samples at the level the move ended on: n differences of zero

    def staircase(creep_m: float, n: int = n_rest) -> np.ndarray:
        """Four rests of ``n`` samples between moves of 0.1 m, each rest creeping ``creep_m`` a sample."""
        parts = [np.linspace(0.0, 0.1, 200)]
        for _ in range(4):
            end = parts[-1][-1]
            parts += [end + creep_m * np.arange(1, n + 1)]
            end = parts[-1][-1]
            parts += [np.linspace(end, end + 0.1, 200)[1:]]
        return np.concatenate(parts)

    q = staircase(0.0)
    assert dwell.reference_dwells(q, fs) == 4  # rests of exactly DWELL_MIN_S
    assert dwell.reference_dwells(staircase(0.0, n_rest - 1), fs) == 0  # one sample short
    span = 0.5
    assert dwell.reference_dwells(staircase(0.5e-9 * span), fs) == 4  # creeping by 0.5e-9 of the stroke a sample: still at rest
    assert dwell.reference_dwells(staircase(2e-9 * span), fs) == 0  # 2e-9 of the stroke a sample is motion
    assert (
        dwell.reference_dwells(np.zeros(2), fs) == 0
        and dwell.reference_dwells(np.zeros(n_rest + 1), fs) == 1
        and dwell.reference_dwells(np.zeros(n_rest), fs) == 0
    )
    assert dwell.dwells(q, fs) and not dwell.dwells(staircase(0.0, n_rest - 1), fs)  # the search's rule: 4 dwells


def test_the_coulomb_level_and_the_grids() -> None:
    assert dwell.coulomb_N(("M", "Fv", "Fc", "offset"), np.array([95.0, 200.0, 20.0, 1.0])) == 20.0
    assert dwell.coulomb_N(("M", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg"), np.array([95.0, 200.0, 210.0, 19.0, 21.0])) == 20.0
    assert dwell.coulomb_N(("M", "Fv"), np.array([95.0, 200.0])) is None
    vs_grid = np.geomspace(0.001, 0.04, 32)
    vs, impulse = dwell.grids(vs_grid, -20.0)
    assert np.array_equal(vs, vs_grid[:: dwell.VS_EVERY]) and len(vs) == 8
    levels_at_the_middle = [0.625, 1.25, 2.5, 5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0, 640.0]  # Fc / 32 to 32 Fc
    assert (impulse / vs_grid[16]).tolist() == pytest.approx(levels_at_the_middle)
    first = dwell.proposal(vs_grid, -20.0)
    assert first.effect is STRIBECK and first.value == vs_grid[16] and first.level == (2.5,)


def test_search_follows_a_best_point_that_moves() -> None:
    """A valley oblique to both coordinates: the profiles alternate while the best point moves, and end on its least."""
    vs, impulse = _grids()
    v0, a0 = float(vs[2]), float(impulse[5])
    calls: list[float] = []

    def error(st: Step) -> float:
        assert st.level is not None
        calls.append(float(st.value))
        dv, da = math.log(float(st.value) / v0), math.log(st.level[0] * float(st.value) / a0)
        return 1.0 + (dv - 0.5 * da) ** 2 + da**2

    found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=50.0)
    assert found is not None and found.level is not None
    assert found.value == pytest.approx(v0) and found.level == (pytest.approx(a0 / v0),)
    assert len(set(calls)) > 2 and len(calls) > len(impulse) + len(vs)  # more than one profile of each coordinate


@pytest.mark.parametrize("i", [1, 6])
def test_search_takes_an_optimum_next_to_the_edges(i: int) -> None:
    vs, impulse = _grids()
    for j in (1, 3, 9):
        error, _ = _surface(float(vs[i]), float(impulse[j] / vs[i]))
        found = dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=2.0)
        assert found is not None and found.value == pytest.approx(vs[i]) and found.level == (pytest.approx(impulse[j] / vs[i]),)
    error, _ = _surface(float(vs[3]), float(impulse[2] / vs[3]))
    assert dwell.search(dwell.proposal(vs, 20.0), vs, impulse, error, baseline_error=1.0) is None  # equal to the model without it: no fall


def test_judged_text_gives_the_folds_ranges() -> None:
    est = [Step(STRIBECK, v, level=(f,)) for v, f in [(0.008, 2.4), (0.010, 2.6), (0.012, 2.5)]]
    _, text = dwell.judged(est)
    assert text == (
        "Fs and vs searched on the closed loop of each fold's training blocks (noisy replays): estimates in 3 of 3 folds, Fs 2.4 to 2.6 N, vs 8 to 12 mm/s"
    )
    _, why = dwell.judged([None, None, None])
    assert why == "its closed-loop search of Fs and vs finds an estimate inside its grid in 0 of 3 folds (fewer than 3)"
    _, text = dwell.judged(est, "revolute")  # in the joint's units (corpus s3041 said "vs 90.7 to 197 mm/s" of a revolute joint)
    assert text.endswith("Fs 2.4 to 2.6 N·m, vs 8 to 12 mrad/s")


def test_a_proposal_that_cannot_be_replayed_is_still_the_closed_loops(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every verdict on a closed-loop proposal names who proposed it, the one without a replay too."""
    from ilic_cli.diagnosis import decide, heldout_replay
    from ilic_cli.diagnosis.core import _prepare
    from ilic_cli.diagnosis.select import moving_rows
    from ilic_cli.idim_ls import LSSettings
    from ilic_cli.prepare import prepare_log
    from ilic_cli.regressor import get_model
    from tests.conftest import make_synthetic_log

    log = make_synthetic_log(4000)
    base = get_model("rigid-offset")
    data = _prepare(prepare_log(log), base, LSSettings())
    monkeypatch.setattr(heldout_replay, "_replayed_plant", lambda *a, **k: None)  # no model is a valid plant (every replay goes through it)
    step = dwell.proposal(np.geomspace(0.002, 0.08, 32), 20.0)
    plant = lambda steps, names, theta: model_parameters(steps, names, theta, np.zeros((len(theta),) * 2))  # noqa: E731
    _, (verdict,) = decide.replay_decide(log, data, base, [], [step], moving_rows(data), plant, sensor_noise=False)
    assert not verdict.accepted and "no replay" in verdict.reason and verdict.proposed_by == dwell.METHOD


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=12), st.integers(0, 11), st.sampled_from([0.0, math.inf]))
def test_least_along_is_the_first_least_of_a_profile_with_one_minimum(drops: list[float], m: int, cliff: float) -> None:
    """Falling to a minimum then rising (plateaus and unreplayable points, ``inf``, on the way up): the index
    ``min(range(n), key=error)`` gives, with no point beyond the third rise past it replayed."""
    n = len(drops)
    m = min(m, n - 1)
    down = np.cumsum(drops[: m + 1][::-1])[::-1]  # non-increasing to index m
    up = down[m] + np.cumsum(drops[m + 1 :])  # non-decreasing after it
    e = np.concatenate([down, up]) if m + 1 < n else down
    if cliff and n > m + 2:
        e[-1] = cliff  # a replay without an answer at the far end
    seen: list[int] = []
    found = dwell.least_along(n, lambda k: seen.append(k) or float(e[k]))
    assert found == min(range(n), key=lambda k: e[k])
    assert seen == list(range(len(seen)))  # each point once, in order
    rises = np.flatnonzero(np.diff(e[found:]) > 0)
    if len(rises) >= dwell.PROFILE_RISES and np.all(np.diff(rises[: dwell.PROFILE_RISES]) == 1) and rises[0] == 0:
        assert len(seen) == found + 1 + dwell.PROFILE_RISES  # left at the third rise


def test_least_along_counts_consecutive_rises_only() -> None:
    """A fall (even one above the least so far) starts the count again: the later least is found; three rises in a row
    past it end the walk."""
    e = [5.0, 4.0, 4.5, 4.2, 4.6, 4.7, 3.0, 3.5, 3.6, 3.7, 9.0, 0.0]
    seen: list[int] = []
    assert dwell.least_along(len(e), lambda k: seen.append(k) or e[k]) == 6
    assert seen == list(range(10))  # left at the third rise past index 6: index 11's 0.0 is beyond it
