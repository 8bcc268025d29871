"""The closed-loop search of the kept effects' nonlinear values, one at a time on the output error (:func:`search_all`), for the refit."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.fits import Point, ValueSearch
from ilic_cli.diagnosis.search import at_edge, search_range
from ilic_cli.diagnosis.stats import variance_inflation
from ilic_cli.diagnosis.system import Step
from ilic_cli.effects.definition import Z95

XATOL_STEPS = 0.05
"""Tolerance of the bounded search on the value, in grid steps (on the grid's own scale)."""

CURVATURE_STEPS = 0.25
"""Step of the finite difference that gives a searched value's standard deviation from the profile's curvature (grid steps)."""


def _scale(log_scale: bool) -> tuple[Callable[[float], float], Callable[[float], float]]:
    return (math.log, math.exp) if log_scale else (lambda v: v, lambda u: u)


MAX_ROUNDS = 5
"""Most rounds of the coordinate search of the nonlinear values (:func:`search_all`)."""

ROUND_GAIN = 0.01
"""A round of the coordinate search is repeated while it lowers the output error by more than this share of it."""


def search_all(
    known: list[Step],
    steps: list[Step],
    grids: Mapping[str, np.ndarray],
    start: Point,
    profile: Callable[[list[Step], np.ndarray], Point],
    replays: list[int],
    n_rows: int,
    *,
    restart: bool = False,
    max_rounds: int = MAX_ROUNDS,
    round_gain: float = ROUND_GAIN,
    joint: str = "prismatic",
) -> tuple[list[ValueSearch], list[Step], Point]:
    """Each nonlinear parameter of ``steps`` (not ``known``'s) searched in turn on ``profile``: the searches, the steps at the values found, the last point.

    Each search goes on from the previous one's optimum; ``restart``: from a
    new profile point at its estimate (one replay: a DIDIM step from there),
    and the round of searches is repeated (a coordinate descent) while a
    round lowers the output error by more than ``round_gain`` of it (:data:`ROUND_GAIN`), at
    most ``max_rounds`` (:data:`MAX_ROUNDS`) rounds, when more than one parameter is searched:
    the values couple. Measured on the corpus's Stribeck + flexibility log
    with the current loop (s303): one round left the drive lag at 0.267 ms
    for the loop's 0.227 ms, the resonance 9.5 % and the Stribeck level 16 %
    off (output error 0.762 %); four rounds give 0.236 ms, 0.4 % and 3.6 %
    (0.708 %). One :class:`ValueSearch` per parameter is returned
    (:func:`_rounds`).
    """
    steps = list(steps)
    slots = slots_of(known, steps, grids, joint)
    rounds: list[list[ValueSearch]] = []
    point = start
    for _ in range(max_rounds if restart and len(slots) > 1 else 1):
        searches: list[ValueSearch] = []
        begin = point.error
        for j, pname, unit, slot in slots:
            last = searches[-1] if searches else (rounds[-1][-1] if rounds else None)
            if restart and last is not None and last.accepted:
                point = profile(steps, point.theta)
            found, point = _search(steps, j, slot, pname, unit, grids[steps[j].effect.id], point, profile, replays, n_rows - len(point.theta), joint)
            searches.append(found)
            if found.accepted:
                st = steps[j]
                steps[j] = Step(st.effect, with_slot(st.value, slot, found.value))
        rounds.append(searches)
        if not any(f.accepted for f in searches) or not point.error < (1.0 - round_gain) * begin:
            break
    return _rounds(rounds), steps, point


def slots_of(known: list[Step], steps: list[Step], grids: Mapping[str, np.ndarray], joint: str = "prismatic") -> list[tuple[int, str, str, int]]:
    """The nonlinear values of ``steps`` (not ``known``'s) the closed loop searches: ``(index in steps, parameter, unit, slot)``.

    Slot 0 is an effect's value on its grid, slot 1 its secondary value (a resonance's damping ratio).
    """
    slots: list[tuple[int, str, str, int]] = []
    for j in range(len(known), len(steps)):
        scan = steps[j].effect.scan
        if scan is None or steps[j].effect.id not in grids:
            continue
        slots.append((j, scan.name, steps[j].effect.unit_on(scan.unit, joint), 0))
        if scan.secondary is not None and isinstance(steps[j].value, tuple):
            slots.append((j, scan.secondary[0], scan.secondary[1], 1))
    return slots


def slot_value(value: Any, slot: int) -> float:
    """Slot ``slot`` of an effect's value (a scalar value is its own slot 0)."""
    return float(value[slot]) if isinstance(value, tuple) else float(value)


def _rounds(rounds: list[list[ValueSearch]]) -> list[ValueSearch]:
    """One search per parameter from the rounds of :func:`search_all`: from the first round's value to the last value accepted.

    A parameter no round moved keeps its first search (and its reason). One
    that moved gets the value of its last accepted round, that round's
    standard deviation and error, the first round's value and error as the
    start, the union of the ranges searched and every replay.
    """
    if len(rounds) == 1:
        return rounds[0]
    out = []
    for per in zip(*rounds, strict=True):
        first, moved = per[0], [f for f in per if f.accepted]
        if not moved:
            out.append(replace(first, evaluations=sum(f.evaluations for f in per)))
            continue
        last = moved[-1]
        lo, hi = min(f.bounds[0] for f in per), max(f.bounds[1] for f in per)
        span = f"{lo:.4g} to {hi:.4g} {first.unit}".strip()
        why = (
            f"searched on the closed loop ({span}, {len(per)} rounds of the coordinate search, moved in {len(moved)}): "
            f"{first.parameter} {first.inverse:.4g} -> {last.value:.4g} {first.unit}, output error {first.error_inverse_pct:.4g} % -> {last.error_pct:.4g} %"
        ).replace(" ,", ",")
        n = sum(f.evaluations for f in per)
        out.append(replace(last, inverse=first.inverse, bounds=(lo, hi), error_inverse_pct=first.error_inverse_pct, evaluations=n, reason=why))
    return out


def with_slot(value: Any, slot: int, new: float) -> Any:
    """``value`` with slot ``slot`` set to ``new``: a scalar value (slot 0) is ``new`` itself."""
    if not isinstance(value, tuple):
        return new
    v = list(value)
    v[slot] = new
    return tuple(v)


def _search(
    steps: list[Step],
    j: int,
    slot: int,
    pname: str,
    unit: str,
    grid: np.ndarray,
    start: Point,
    profile: Callable[[list[Step], np.ndarray], Point],
    replays: list[int],
    dof: int,
    joint: str = "prismatic",
) -> tuple[ValueSearch, Point]:
    """Bounded search of slot ``slot`` of ``steps[j]``'s value on the closed-loop output error; the search and the point to go on from.

    Every value is one DIDIM step from ``start``'s estimate (the previous parameter's optimum).
    """
    from scipy.optimize import minimize_scalar  # deferred: scipy.optimize is slow to import

    st = steps[j]
    scan = st.effect.scan
    assert scan is not None
    value = st.value
    v0 = slot_value(value, slot)
    sub = slot_range(st, slot, grid)
    lo, hi = float(sub[0]), float(sub[-1])
    if slot == 0:
        fwd, inv = _scale(scan.log and lo > 0)
        step_u = (fwd(hi) - fwd(lo)) / max(len(sub) - 1, 1)
    else:
        fwd, inv = _scale(True)
        step_u = (fwd(hi) - fwd(lo)) / 20.0
    at = {"start": replays[0]}
    memo: dict[float, Point] = {}
    anchor = start.anchor
    err0 = start.error

    def with_value(v: float) -> list[Step]:
        new = list(steps)
        new[j] = Step(st.effect, with_slot(value, slot, v))
        return new

    def f(u: float) -> float:
        v = inv(u)
        if v not in memo:
            memo[v] = profile(with_value(v), anchor)
        return memo[v].error

    memo[v0] = start
    if hi <= lo:
        return ValueSearch(st.effect.id, pname, unit, v0, v0, v0, None, (lo, hi), err0, err0, 0, False, "no range to search", slot == 0), start
    with np.errstate(invalid="ignore"):  # a value with no plant is an infinite error: the parabola step through it is nan, and falls back
        res = minimize_scalar(f, bounds=(fwd(lo), fwd(hi)), method="bounded", options={"xatol": XATOL_STEPS * step_u})
    best = inv(float(res.x))
    e_best = f(float(res.x))
    if slot == 0:
        edge = at_edge(st.effect, sub, best, joint)
    else:  # the primary value is inside its grid (the inverse model's own edge rule): only the secondary can be on an edge
        edge = at_edge(st.effect, np.asarray(grid, dtype=np.float64), with_slot(value, slot, best), joint)
    span = f"{lo:.4g} to {hi:.4g} {unit}".strip()
    if not math.isfinite(e_best):
        why = "no value in the range searched gives a plant of the effect: the inverse model's value is kept"
        ok = False
    elif edge:
        why = f"the closed-loop optimum is on the edge of the range searched ({edge}): the inverse model's value is kept"
        ok = False
    elif not e_best < err0:
        why = f"the closed-loop search ({span}) does not lower the output error: the inverse model's value is kept"
        ok = False
    else:
        why = f"searched on the closed loop ({span}): {pname} {v0:.4g} -> {best:.4g} {unit}, output error {err0:.4g} % -> {e_best:.4g} %".replace(" ,", ",")
        ok = True
    std = None
    if ok:
        std = _std(f, inv, float(res.x), CURVATURE_STEPS * step_u, e_best, dof, memo[best].rho)
        if scan.of_the_whole_log and (std is None or Z95 * std > 0.5 * (hi - lo)):
            # a time of the log on a flat profile, no curvature or a 95 % interval wider than the range searched: between two
            # accelerations every change time replays alike (the inverse model's value is its profile interval's middle,
            # :meth:`~ilic_cli.diagnosis.search.Searcher.refine`)
            why = f"the closed-loop profile ({span}) is flat at its optimum ({pname} {best:.4g} {unit}): the inverse model's value is kept"
            ok = False
    n_replays = replays[0] - at["start"]
    found = ValueSearch(st.effect.id, pname, unit, v0, best, best if ok else v0, std, (lo, hi), err0, e_best, n_replays, ok, why, slot == 0)
    return found, memo[best] if ok else start


def _std(f: Callable[[float], float], inv: Callable[[float], float], u: float, h: float, e: float, dof: int, rho: float) -> float | None:
    """Standard deviation of the value at ``u`` from the curvature of the profile error, in the value's own unit.

    ``f`` is the output error in % of ``||y||``, so ``f**2`` is the residual sum of squares up to a
    constant that cancels: ``var = 2 (RSS / dof) / RSS''``, inflated for the lag-1 autocorrelation
    ``rho`` of the residual (:func:`~ilic_cli.diagnosis.stats.variance_inflation`), as
    :meth:`ilic_cli.diagnosis.search.Searcher.refine` does on the inverse model's RSS.
    """
    ep, em = f(u + h), f(u - h)
    if not (math.isfinite(ep) and math.isfinite(em)):
        return None
    dv = 0.5 * (inv(u + h) - inv(u - h))
    curv = (ep**2 - 2.0 * e**2 + em**2) / dv**2
    if not curv > 0:
        return None
    return math.sqrt(2.0 * e**2 / max(dof, 1) * variance_inflation(rho) / curv)


def slot_range(step: Step, slot: int, grid: np.ndarray) -> np.ndarray:
    """What the closed loop searches slot ``slot`` of ``step``'s value on: the part of the effect's ``grid`` around it
    (:func:`~ilic_cli.diagnosis.select.search_range`), or the secondary value's bounds."""
    scan = step.effect.scan
    assert scan is not None
    if slot == 0:
        return search_range(step.effect, np.asarray(grid, dtype=np.float64), slot_value(step.value, 0))
    assert scan.secondary is not None
    return np.array([scan.secondary[2], scan.secondary[3]])
