"""Stribeck friction proposed by the closed loop: at dwells, where the inverse model cannot, and where its held-out test cannot confirm it.

A trajectory that rests between moves (a trapezoid's dwells) passes through
the Stribeck band only in the few milliseconds before a stop and after a
break-away, where the axis sticks and the IDIM filters smear the kinematics:
there the inverse model fits friction *below* Coulomb (a Stribeck level of
-3.9 N on a clean trapezoid; a concealed +2.5 N only lessens it), outside the
effect's physics, and never proposes it (README, "Stribeck friction at
dwells: the closed loop proposes"). The closed loop sees it: the replay of the recorded
reference sticks and breaks away as the axis does, and with the recording's
own sensor noise it creeps at the dwells as the axis does.

So on a log whose reference dwells (:func:`reference_dwells`), when the
inverse model did not propose Stribeck friction, :func:`proposal` adds it as a
last candidate for the replay; so too on any log where the inverse model's
F-test found it but its held-out test did not confirm it
(:meth:`ilic_cli.diagnosis.select.SelectionResult.unconfirmed`: on the EMPS
reference with a flexibility beside it, F-test p <= 1e-35 and held-out p =
0.027-0.5 on four seeds, where the replay accepts it at p <= 1.0e-9). The replay
judges it (:func:`ilic_cli.diagnosis.decide.replay_decide`)
with its level held (``Step.level``): on each fold's training blocks the level
``Fs`` and the velocity ``vs`` are searched on a grid by noisy closed-loop
replays (:func:`search`; the rigid parameters the inverse model's fit with
that Stribeck force taken off), and the held-out block judges the fold's
estimate as for any candidate. A fold whose optimum is on the edge of the grid
(the least level tried is no measured level), or that does not lower its
training error, keeps the model without it; fewer than :data:`MIN_FOLDS` folds
with an estimate is no finding. Once kept, a level found off the dwells is the
start of the closed-loop refit, a column again (:mod:`ilic_cli.diagnosis.refit`:
the folds hold the other effects at the inverse model's estimates, and the
level makes up for their bias; on seed 1303 2.5 N for 3.53, refitted 3.58 N).
One found at the dwells is not refitted so, since the refit replays noise-free
and the creep there is the noise's: it is estimated again on open-loop
segments driven by the recorded force (:mod:`ilic_cli.diagnosis.segments`),
which holds the loop's answer to the recording's own noise; where that fit
explains the recording to its noise, its estimate replaces the search's, and
a level it does not find above zero refutes the finding.

Measured on the corpus (``tests/corpus/__init__.py``): the Stribeck trapezoid without a
current loop, held-out replay force error 1.28 % -> 0.884 % (p = 5e-13, 5 of 5
folds; Fs 2.50 to 2.58 N, vs 12.5 to 14.1 mm/s for 2.47 N, 8 mm/s; the open-loop
segments then 2.473 N, 7.972 mm/s); the one with the loop and a force
disturbance, 2.18 % -> 2.14 % (p = 0.0074, 4 of 5 folds; Fs 1.06 to 1.14 N, vs
13.7 to 23.4 mm/s for 1.14 N, 20 mm/s); no fold found an
estimate on any of the 8 clean trapezoids, once the current loop's lag is realised as the loop it is
(:meth:`ilic_cli.effects.Effect.plant_entries`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ilic_cli.diagnosis.select import Step
from ilic_cli.effects import EFFECTS, Effect, unit_on
from ilic_cli.row_spans import valid_rows

DWELL_MIN_S = 0.05
"""A rest of the reference at least this long (s) is a dwell."""

DWELL_MIN_COUNT = 4
"""A log is searched for Stribeck friction at its dwells when its reference has at least this many."""

LEVELS_OF_FC = (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1, 2, 4, 8, 16, 32)
"""Stribeck impulses ``Fs·vs`` searched (:func:`grids`), as fractions of the fitted Coulomb level times the middle ``vs``
(geometric, factor 2): at the middle ``vs``, a static friction up to 33 times the Coulomb level; at a ``vs`` ``k`` times
smaller, ``k`` times more. Levels of ``Fs`` alone up to half of ``Fc`` first, a peak above that was on the grid's edge
and never found (the robot corpus: Fs of 0.85 and 1.4 times Fc at 500 Hz, 0 of 5 folds); up to 8 Fc then, the corpus's
dwell logs whose peak is 3.4 to 6.8 Fc (a peak sized to change the rigid fit's error by 0.2-1.5 points) were named,
and on a grid of impulses up to 8 times, the disturbed s461's (Fs = 6.2 Fc at 1.26 times the middle ``vs``) would be
its top point."""

START_LEVEL_OF_FC = 1 / 8
"""The level the proposal holds until the search (:func:`proposal`), as a fraction of ``|Fc|``: a held level marks the step
as one the folds search (:func:`search` starts from its ``vs`` and takes no level from it)."""

HALVINGS = 3
"""Halvings of the grid's step by which a fold's estimate is refined between the grid's points (:func:`refined`): the
impulse's step (a factor 2) and ``vs``'s (1.61) to an eighth: each within a sixteenth of its step (a factor 1.044 and
1.030), two replays a halving, twelve a fold."""

PROFILE_RISES = 3
"""A profile of the search (:func:`least_along`) is left once the training error has risen at this many consecutive
points past its least so far: along each profile the Stribeck valley has one minimum (a level beyond it sticks the axis
longer at every stop, a ``vs`` beyond it lengthens the impulse of every passage), so three rises (a factor 8 of the
impulse, 4.2 of ``vs``) end it. On a clean log the impulse's profile rises from its least level: 4 replays a fold, not 11."""

VS_EVERY = 4
"""The ``vs`` searched: every this many values of the effect's own grid (1-40 % of the top speed, 32 values)."""

MIN_FOLDS = 3
"""Folds (of 5) whose search must find an estimate inside its grid for the replay to judge the effect."""

IN_MOTION_ALPHA = 0.05
"""A Stribeck friction found at the dwells must also lower the held-out force error on the rows whose span touches a step of
the reference (:func:`reference_moving`), at this level (:meth:`ilic_cli.diagnosis.heldout_replay.HeldoutReplays.in_motion`):
the friction acts as the axis leaves and nears rest, so a fall at the dwells alone is a model that stops the axis elsewhere,
no friction at low speed. Measured (the one-sided held-out test on those rows): true levels of 0.12 to 7 Fc give p = 6.5e-10
to 0.0014 (the robot corpus's 12 kg trapezoid at 500 Hz under the current loop; the EMPS-like trapezoid s210, 0.12 Fc,
whose fall is mostly at rest, 1.8e-6); false ones, 0.04 to 0.15 Fc, beside a
flexibility or the 10 Hz disturbance p = 0.12 to 0.65 (rejected), beside a payload change under the disturbance 0.047 and
beside a drift under the current loop 0.0066 (both kept). The conventional level of a confirmation, not one fitted between them."""
METHOD = "closed-loop search of Fs and vs"
"""How a finding proposed here is estimated (its ``Finding.method``)."""

SPREAD = "the folds' delete-a-block jackknife (their scatter, the other parameters held at their estimates: not a bias those carry)"
"""Where its standard deviations come from (:func:`jackknife_std`), as the report says it."""


def _still(q: np.ndarray) -> np.ndarray:
    """Whether the reference rests between each sample and the next (its step within 1e-9 of its range)."""
    return np.abs(np.diff(q)) <= 1e-9 * max(float(np.ptp(q)), 1e-12)


def reference_moving(q_ref: np.ndarray, r: int) -> np.ndarray:
    """Whether each row of ``q_ref`` decimated by ``r`` (:func:`ilic_cli.filtering.kept_indices`) has a span that touches a
    sample where the reference moves, into or out of it (the span of :func:`ilic_cli.row_spans.valid_rows`): where a friction
    at low speed acts as the axis leaves and nears rest, beside where it holds it (:data:`IN_MOTION_ALPHA`)."""
    q = np.asarray(q_ref, dtype=np.float64)
    if len(q) == 0:
        return np.zeros(0, dtype=bool)
    moves = ~_still(q)
    return ~valid_rows(~(np.r_[False, moves] | np.r_[moves, False]), r)


def reference_dwells(q_ref: np.ndarray, fs_hz: float, min_s: float = DWELL_MIN_S) -> int:
    """How many times the reference rests (does not move) for at least ``min_s`` (:data:`DWELL_MIN_S`)."""
    q = np.asarray(q_ref, dtype=np.float64)
    if len(q) < 2:
        return 0
    still = _still(q)
    edges = np.diff(np.r_[0, still.astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return int(np.sum((ends - starts) >= min_s * fs_hz))


def dwells(q_ref: np.ndarray, fs_hz: float, min_s: float = DWELL_MIN_S, min_count: int = DWELL_MIN_COUNT) -> bool:
    """Whether the reference rests often enough for the search (at least ``min_count`` dwells of ``min_s``: :data:`DWELL_MIN_COUNT`)."""
    return reference_dwells(q_ref, fs_hz, min_s) >= min_count


def coulomb_N(names: tuple[str, ...], theta: np.ndarray) -> float | None:
    """The fitted Coulomb level (the mean of ``Fc_pos`` and ``Fc_neg`` for an asymmetric model), ``None`` without one."""
    fc = [float(v) for n, v in zip(names, theta, strict=True) if n in ("Fc", "Fc_pos", "Fc_neg")]
    return float(np.mean(fc)) if fc else None


def proposal(vs_grid: np.ndarray, fc_N: float, effect: Effect = EFFECTS["stribeck"]) -> Step:
    """The Stribeck candidate (``effect``) the replay searches (:func:`search`), at the middle of its ``vs`` grid and
    :data:`START_LEVEL_OF_FC` until then."""
    return Step(effect, float(vs_grid[len(vs_grid) // 2]), level=(abs(fc_N) * START_LEVEL_OF_FC,))


def grids(vs_grid: np.ndarray, fc_N: float) -> tuple[np.ndarray, np.ndarray]:
    """The ``vs`` (m/s) and the impulses ``Fs·vs`` (N·m/s) searched: :data:`VS_EVERY` of the effect's grid, and
    :data:`LEVELS_OF_FC` of ``|Fc|`` times the grid's middle ``vs`` (the proposal's, :func:`proposal`)."""
    grid = np.asarray(vs_grid, dtype=np.float64)
    return grid[::VS_EVERY], abs(fc_N) * float(grid[len(grid) // 2]) * np.asarray(LEVELS_OF_FC)


def search(step: Step, vs: np.ndarray, impulse: np.ndarray, training_error: Callable[[Step], float], baseline_error: float) -> Step | None:
    """The ``(vs, Fs)`` of the grid with the least training error, or ``None`` when it is on an edge or does not beat the model without it.

    The grid is of ``vs`` and of the impulse ``Fs·vs`` (the level is ``impulse / vs``): the loop feels
    Stribeck friction as the impulse it gives each passage through the low-speed band, which lasts in
    proportion to ``vs``, so the training error's valley runs along ``Fs·vs`` held, diagonal on a grid of
    ``Fs`` and ``vs``. On such a grid, a coordinate search stalled part way along the valley, towards the
    start's low level and high ``vs`` (eleven of the robot corpus's sixteen Stribeck logs at dwells, both seed
    sets: ``Fs`` 0.31 to 0.80 of the truth, ``vs`` 1.2 to 2.8 times it, ``Fs·vs`` 0.79 to 1.28 times; s461
    ``Fs`` 4.2 N, ``vs`` 279 mm/s for 10.2 N, 120 mm/s, where the whole grid's least was at 13 N, 95 mm/s with
    a fifth of the error).

    A coordinate search (each replay with Stribeck friction costs the general
    integration path, some 13 times the rigid one): the impulse's profile at
    the proposal's ``vs`` (the middle of its grid) first, the quantity the
    loop fixes best; the ``vs`` profile at the best impulse; and the impulse's
    profile, then the ``vs`` profile, again while the best point moves; every
    point is kept, so the grid points visited are each replayed once, and each
    profile is walked upwards and left three rises past its least
    (:func:`least_along`: the same point as the whole profile's least, with
    fewer replays). An
    impulse on the grid's edge at the middle ``vs`` is no estimate (the least
    impulse tried: no Stribeck friction; a clean log's search ends there). The
    estimate is then refined between the grid's points, the impulse then
    ``vs``, by halving steps (:func:`refined`).

    Parameters
    ----------
    step : Step
        The candidate (:func:`proposal`).
    vs, impulse : ndarray
        The grids (:func:`grids`), increasing.
    training_error : callable
        ``Step -> error`` of the model with that step on the fold's training blocks.
    baseline_error : float
        The same error without the step.
    """
    err: dict[tuple[int, int], float] = {}

    def at(i: int, j: int) -> float:
        if (i, j) not in err:
            err[i, j] = _finite(training_error(Step(step.effect, float(vs[i]), level=(float(impulse[j] / vs[i]),))))
        return err[i, j]

    def along_vs(j: int) -> int:  # the least vs at impulse j
        return least_along(len(vs), lambda k: at(k, j))

    def along_impulse(i: int) -> int:  # the least impulse at vs i
        return least_along(len(impulse), lambda k: at(i, k))

    i = int(np.argmin(np.abs(np.log(vs / float(step.value)))))  # the proposal's vs
    j = along_impulse(i)
    if j in (0, len(impulse) - 1):  # on the grid's edge at the middle vs: no estimate, and no more replays
        return None
    for _ in range(len(vs) + len(impulse)):  # alternate the profiles while the best point moves (each visits new points)
        i1 = along_vs(j)
        if i1 == i:
            break
        i = i1
        j1 = along_impulse(i)
        if j1 == j:
            break
        j = j1
    if not at(i, j) < baseline_error or i in (0, len(vs) - 1) or j in (0, len(impulse) - 1):
        return None
    # between the grid's points: the impulse, then vs, by halving steps on log scales (:func:`refined`)
    error = lambda v, a: training_error(Step(step.effect, float(np.exp(v)), level=(float(np.exp(a - v)),)))  # noqa: E731
    lv, la = float(np.log(vs[i])), float(np.log(impulse[j]))
    la, e = refined(lambda a: error(lv, a), la, at(i, j), float(np.log(impulse[1] / impulse[0])))
    lv, _ = refined(lambda v: error(v, la), lv, e, float(np.log(vs[1] / vs[0])))
    return Step(step.effect, float(np.exp(lv)), level=(float(np.exp(la - lv)),))


def least_along(n: int, error: Callable[[int], float], rises: int = PROFILE_RISES) -> int:
    """The first index of the least ``error`` over ``0 .. n-1``, walked upwards and left once it has risen ``rises``
    consecutive times past the least so far (:data:`PROFILE_RISES`): ``min(range(n), key=error)`` on a profile with one
    minimum, without replaying the points beyond it."""
    best, up = 0, 0
    e_best = e_prev = error(0)
    for k in range(1, n):
        e = error(k)
        if e < e_best:
            best, e_best, up = k, e, 0
        else:
            up = up + 1 if e > e_prev else 0
            if up >= rises:
                break
        e_prev = e
    return best


def _finite(e: float) -> float:
    """An error to compare: ``nan`` (a replay without a valid answer) as ``inf``, which ``min`` never prefers."""
    return e if e == e else math.inf


def refined(error: Callable[[float], float], x: float, y: float, h: float, halvings: int = HALVINGS) -> tuple[float, float]:
    """The least of ``error`` near ``x`` (its value ``y``; a grid's best point, its neighbours ``h`` away), within
    ``h / 2**(halvings + 1)``, and its value: ``halvings`` times the least of the point and those half the step either
    side.

    Not the vertex of a parabola: beside the Stribeck valley the error rises steeply on one side (a level the axis
    sticks at) and gently on the other, and the parabola's vertex falls towards the gentle side, by up to half the
    points' spacing (the robot corpus, through the grid's point and its neighbours: the impulse 0.62 to 0.88 of the
    truth at ``vs`` 0.99 to 1.32 times it; on s372 the grid's least point was the truth's, the vertex half a step below).
    """
    fine = h / 2**halvings  # the points tried are x + k fine: each replayed once
    seen: dict[int, float] = {0: y}

    def at(k: int) -> float:
        if k not in seen:
            seen[k] = _finite(error(x + k * fine))
        return seen[k]

    k, step = 0, 2**halvings
    for _ in range(halvings):
        step //= 2
        k = min((k - step, k, k + step), key=at)
    return x + k * fine, at(k)


def jackknife_std(values: np.ndarray) -> float:
    """Delete-a-block jackknife standard deviation of estimates each made without one block: ``sqrt((k-1)/k sum (x_i - mean)^2)``.

    The folds' training sets share all but one block each, so their estimates
    scatter less than the estimate itself would over independent recordings:
    their plain standard deviation understates its by about ``(k - 1)/sqrt(k)``,
    1.8 for 5 folds (Efron and Tibshirani, *An Introduction to the Bootstrap*,
    ch. 11; on the Stribeck trapezoid: ``vs`` 1.3 mm/s plain, 2.3 mm/s
    jackknife, for an estimate 1.9 mm/s off).
    """
    x = np.asarray(values, dtype=np.float64)
    k = len(x)
    return float(np.sqrt((k - 1) / k * np.sum((x - x.mean()) ** 2))) if k > 1 else float("nan")


def judged(found: list[Step | None], joint: str = "prismatic") -> tuple[Step | None, str]:
    """The step the folds' estimates give (medians; their :func:`jackknife_std` the standard deviations), and a sentence in the
    units of a ``joint``; ``None`` when too few."""
    ok = [s for s in found if s is not None and s.level is not None]
    if len(ok) < MIN_FOLDS:
        return None, f"its closed-loop search of Fs and vs finds an estimate inside its grid in {len(ok)} of {len(found)} folds (fewer than {MIN_FOLDS})"
    vs = np.array([float(s.value) for s in ok])
    fs = np.array([s.level[0] for s in ok if s.level is not None])
    step = Step(ok[0].effect, float(np.median(vs)), level=(float(np.median(fs)),), level_std=(jackknife_std(fs),), value_std=jackknife_std(vs))
    text = (
        f"Fs and vs searched on the closed loop of each fold's training blocks (noisy replays): estimates in {len(ok)} of {len(found)} folds, "
        f"Fs {fs.min():.3g} to {fs.max():.3g} {unit_on('N', joint)}, vs {vs.min() * 1e3:.3g} to {vs.max() * 1e3:.3g} m{unit_on('m/s', joint)}"
    )
    return step, text


def fold_values(found: list[Step | None]) -> list[Any]:
    """Each fold's ``(vs, Fs)``, ``None`` where it found none (for the verdict's record)."""
    return [None if s is None or s.level is None else (float(s.value), float(s.level[0])) for s in found]
