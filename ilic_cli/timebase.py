"""The time base of a log: its nominal rate, gaps, stamp jitter and the unit of its stamps.

One definition of the sample rate for every layer: the run-log model, the readers (a CSV's time unit, a ROS bag's rate), the
preparation of a log and the quality report all take it from here. Pure functions of the stamps.

Rules (each documented at its function)
---------------------------------------
* **nominal rate** -- the simplest round rate within 0.05 % of ``1/mean(step)``, gaps left out (:func:`nominal_rate_hz`);
* **gaps** -- steps longer than 1.5 nominal periods; each gap of ``k`` periods is counted as ``k - 1`` dropped samples
  (:func:`sampling_stats`);
* **jitter** -- standard deviation of the steps, gaps excluded, relative to the nominal period (:func:`sampling_stats`);
* **fixed-rate or irregular** -- :data:`SAMPLING_RULE` (:func:`sampling_kind`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

GAP_FACTOR = 1.5
"""A step longer than this many nominal periods is a gap."""

IRREGULAR_JITTER = 0.01
"""Relative step jitter above which the quality report calls the steps irregular (a warning; see :func:`sampling_kind` for the rule that acts)."""

STAMP_JITTER = 0.5
"""A fixed-rate loop's stamps: every step between gaps within this share of a period of the mean step (:func:`sampling_kind`)."""

CLOCK_JITTER = 0.4
"""Stamps within this share of a period of one straight clock are a fixed-rate loop whatever their steps (:func:`jittered_clock`):
a margin below the half period beyond which a stamp could be the next tick's (a sample dropped in the middle of a jitter-free log
leaves its stamps within 0.4999 periods of a slightly faster clock)."""

FREQUENT_GAPS = 0.01
"""Gaps on more than this share of the steps are the sampling pattern, not dropped messages (:func:`sampling_kind`)."""

IRREGULAR_GAP_FACTOR = 5.0
"""In an irregularly sampled log, a step longer than this many mean steps is a gap (:func:`irregular_grid`)."""

_RATE_TOLERANCE = 5e-4


def nominal_rate_hz(t: np.ndarray) -> float | None:
    """Return the nominal sample rate of time stamps ``t`` (Hz).

    The measured rate is the inverse of the mean step over the whole log, gaps
    left out (steps above :data:`GAP_FACTOR` median steps): stamp jitter of a
    fixed-rate loop averages out (a median step does not). The nominal rate is
    the first of these candidates within 0.05 % of it: the measured rate
    rounded to an integer (1000.016 Hz -> 1000 Hz), the inverse of the mean
    step rounded to three significant digits (3.0001 ms -> 333.33 Hz), else
    the measured rate rounded to six significant digits.

    Parameters
    ----------
    t : ndarray
        Increasing time stamps (s).

    Returns
    -------
    float or None
        The nominal rate, or None with fewer than two samples or a non-positive
        median step.
    """
    found = _steps_between_gaps(t)
    return None if found is None else _round_rate(float(np.mean(found[0][found[1]])))


def _steps_between_gaps(t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The steps of ``t`` and which are not gaps (at most :data:`GAP_FACTOR` median steps; on a :func:`jittered_clock`, the
    steps between its parts); None without a positive median step."""
    steps = np.diff(np.asarray(t, dtype=np.float64).reshape(-1))
    if len(steps) == 0:
        return None
    median = float(np.median(steps))
    if not (median > 0 and math.isfinite(median)):
        return None
    inside = steps <= GAP_FACTOR * median
    if inside.all() or (cuts := _clock_cuts(t)) is None:
        return steps, inside
    inside = np.ones_like(inside)
    inside[cuts] = False
    return steps, inside


def jittered_clock(t: np.ndarray) -> bool:
    """Whether stamps ``t`` are, between gaps, every tick of a fixed-rate clock, each stamp within :data:`CLOCK_JITTER` periods of its tick.

    The clock of each part between gaps longer than :data:`IRREGULAR_GAP_FACTOR`
    median steps is the straight line fitted to its stamps against the sample
    index. Such stamps read each sample's tick unambiguously however their
    steps scatter: a stamp jitter of +-0.3 periods makes steps of 0.4 to 1.6
    periods, which the steps' own rule (:func:`sampling_kind`) and
    :data:`GAP_FACTOR` would read as irregular sampling with gaps. A dropped
    sample is no such clock: it shifts the stamps after it by a period.
    """
    return _clock_cuts(t) is not None


def _clock_cuts(t: np.ndarray) -> np.ndarray | None:
    """The gaps (step indices) between the parts of a :func:`jittered_clock`, ``None`` when ``t`` is not one."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if len(t) < 3:
        return None
    steps = np.diff(t)
    median = float(np.median(steps))
    if not median > 0:
        return None
    cuts = np.flatnonzero(steps > IRREGULAR_GAP_FACTOR * median)
    for a, b in zip([0, *(cuts + 1)], [*(cuts + 1), len(t)], strict=True):
        if b - a < 3 or not clock_deviation(t[a:b]) < CLOCK_JITTER:
            return None
    return cuts


def clock_deviation(t: np.ndarray) -> float:
    """The largest deviation of stamps ``t`` (two or more) from the straight line fitted to them against the sample index, in
    periods of that line (``inf`` when it does not rise)."""
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    part = t - t[0]  # epoch stamps: the fit on the part's own time
    k = np.arange(len(t), dtype=np.float64)
    start, slope = np.polynomial.polynomial.polyfit(k, part, 1)
    if not (slope > 0 and math.isfinite(slope)):
        return math.inf
    return float(np.max(np.abs(part - start - slope * k))) / slope


def _round_rate(step: float) -> float:
    """The nominal rate of a mean ``step``: see :func:`nominal_rate_hz`."""
    rate = 1.0 / step
    candidates = [float(round(rate)), 1.0 / float(f"{step:.3g}")]
    for cand in candidates:
        if cand > 0 and abs(cand - rate) <= _RATE_TOLERANCE * rate:
            return float(f"{cand:.12g}")
    return float(f"{rate:.6g}")


TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
"""Time units a log may use, with their size in seconds."""


def time_unit(t: np.ndarray, declared: str | None = None) -> tuple[str, str]:
    """The unit of time stamps ``t`` and the rule that chose it: ``(unit, rule)``.

    A declared unit (a units line, a column name such as ``t_ns``) is taken
    as it is. Otherwise the unit is the one among s, ms, µs and ns whose
    sample rate, from the median step, lies closest to 1 kHz in decades: the
    units are three decades apart, so a rate between 32 Hz and 32 kHz is never
    mistaken (nanosecond stamps of a 1 kHz loop step by 1e6, read as seconds
    they would be a 1 µHz log).
    """
    if declared:
        unit = declared.strip().replace("usec", "us").replace("sec", "s")
        if unit not in TIME_UNITS:
            raise ValueError(f"unknown time unit '{declared}' (known: {', '.join(TIME_UNITS)})")
        return unit, "declared"
    steps = np.diff(np.asarray(t, dtype=np.float64))
    step = float(np.median(steps)) if len(steps) else 0.0
    if not (step > 0 and math.isfinite(step)):
        return "s", "default (no positive step)"
    best = min(("s", "ms", "us", "ns"), key=lambda u: abs(math.log10(1.0 / (step * TIME_UNITS[u])) - 3.0))
    return best, "the sample rate closest to 1 kHz in decades"


SAMPLING_RULE = (
    "stamps whose steps between gaps all lie within half a period of the mean step, with gaps on at most 1 % of the steps, or that lie "
    "within 0.4 periods of one straight clock between gaps longer than 5 median steps, are a fixed-rate "
    "loop with stamp jitter: the samples are kept and the rate is the mean step's; any other log is irregularly sampled: it is interpolated "
    "linearly onto a uniform grid at its mean rate, within each part between gaps longer than 5 mean steps"
)
"""The rule of :func:`sampling_kind` and :func:`irregular_grid`, in words (reports and README)."""


def sampling_kind(t: np.ndarray) -> str:
    """Tell stamp jitter of a fixed-rate loop from truly irregular sampling (:data:`SAMPLING_RULE`).

    Parameters
    ----------
    t : ndarray
        Increasing time stamps (s).

    Returns
    -------
    str
        ``"fixed-rate"``: every step between gaps (steps above
        :data:`GAP_FACTOR` median steps) is within :data:`STAMP_JITTER`
        periods of the mean step and gaps are at most :data:`FREQUENT_GAPS`
        of the steps, or the stamps are a :func:`jittered_clock` (keep the
        samples); ``"irregular"`` otherwise
        (interpolate them, :func:`irregular_grid`).
    """
    found = _steps_between_gaps(t)
    if found is None or len(found[0]) < 2:
        return "fixed-rate"
    steps, inside = found
    mean = float(np.mean(steps[inside]))
    if np.mean(~inside) > FREQUENT_GAPS or bool((np.abs(steps[inside] / mean - 1.0) > STAMP_JITTER).any()):
        return "fixed-rate" if jittered_clock(t) else "irregular"
    return "fixed-rate"


def irregular_grid(t: np.ndarray) -> tuple[float, tuple[tuple[int, int], ...]]:
    """The uniform grid for an irregularly sampled log: ``(rate_hz, parts)``.

    ``rate_hz`` is the inverse of the mean step, steps longer than
    :data:`IRREGULAR_GAP_FACTOR` mean steps (gaps) left out, rounded as by
    :func:`nominal_rate_hz`; ``parts`` are the ``(start, stop)`` index ranges
    between those gaps.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    steps = np.diff(t)
    gap = steps > IRREGULAR_GAP_FACTOR * float(np.mean(steps))
    rate = _round_rate(float(np.mean(steps[~gap])))
    cuts = [0, *(np.flatnonzero(gap) + 1).tolist(), len(t)]
    return rate, tuple((a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a)


def gap_starts(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices ``i`` where the step ``t[i+1] - t[i]`` is a gap (above :data:`GAP_FACTOR` periods; on a :func:`jittered_clock`, between its parts)."""
    found = np.flatnonzero(np.diff(np.asarray(t, dtype=np.float64)) > GAP_FACTOR / rate_hz)
    return found if len(found) == 0 or (cuts := _clock_cuts(t)) is None else cuts


def segments(t: np.ndarray, rate_hz: float) -> tuple[tuple[int, int], ...]:
    """The contiguous runs of samples between gaps, as ``(start, stop)`` index ranges."""
    cuts = [0, *(gap_starts(t, rate_hz) + 1).tolist(), len(t)]
    return tuple((a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a)


def sampling_stats(t: np.ndarray, rate_hz: float | None = None) -> dict[str, Any]:
    """Return the sampling figures of time stamps ``t``.

    Parameters
    ----------
    t : ndarray
        Increasing time stamps (s).
    rate_hz : float, optional
        Nominal rate; default :func:`nominal_rate_hz`.

    Returns
    -------
    dict
        ``nominal_rate_hz``, ``median_step_s``, ``max_step_s``, ``jitter``,
        ``gaps``, ``dropped_samples`` and ``irregular`` (see :class:`QualityReport`).
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    rate = rate_hz if rate_hz else nominal_rate_hz(t)
    if len(t) < 2 or not rate:
        return {"nominal_rate_hz": rate, "median_step_s": None, "max_step_s": None, "jitter": 0.0, "gaps": 0, "dropped_samples": 0, "irregular": False}
    period = 1.0 / rate
    step = np.diff(t)
    is_gap = np.zeros(len(step), dtype=bool)
    is_gap[gap_starts(t, rate)] = True
    gaps = int(is_gap.sum())
    dropped = int(np.maximum(np.rint(step[is_gap] / period) - 1, 1).sum()) if gaps else 0
    regular = step[~is_gap]
    jitter = float(np.std(regular) / period) if len(regular) > 1 else 0.0
    return {
        "nominal_rate_hz": float(rate),
        "median_step_s": float(np.median(step)),
        "max_step_s": float(step.max()),
        "jitter": jitter,
        "gaps": gaps,
        "dropped_samples": dropped,
        "irregular": bool(gaps > 0 or jitter > IRREGULAR_JITTER),
    }
