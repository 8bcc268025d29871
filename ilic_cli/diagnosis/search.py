"""The search of an effect's nonlinear parameter on the IDIM least squares: the grid scan, its refinement, and its edges.

:class:`Searcher` scans a grid with cached columns and refines between its points; :func:`at_edge` says when an
estimate is on the edge of the range searched (never a finding); :data:`SEARCH_STEPS` and :func:`search_range`
give the part of the grid the closed loop searches again (the replay per fold, the refit).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from ilic_cli.diagnosis.stats import batched_rss, contiguous_runs, lag1_autocorrelation, shifted_rss, variance_inflation
from ilic_cli.diagnosis.system import Step, effect_columns, shift_value, shifted_force
from ilic_cli.effects import Effect
from ilic_cli.effects.definition import Z95
from ilic_cli.filtering import decimated_band_hz, kept_indices
from ilic_cli.idim_ls import IDIMData
from ilic_cli.lm import minimise
from ilic_cli.lsq import lstsq
from ilic_cli.regressor import Kinematics, Model, evaluated_later

EXACT_GRID_MAX = 64
"""Grids up to this size are scanned with exactly decimated columns; larger
ones are screened on columns built from the decimated kinematics, and their
best minima re-evaluated exactly."""


def searched_at_log_rate(effect: Effect, data: IDIMData) -> bool:
    """Whether ``effect``'s value is searched at the log's rate on ``data`` (:attr:`ilic_cli.effects.Scan.at_log_rate`)."""
    return effect.scan is not None and effect.scan.at_log_rate is not None and effect.scan.at_log_rate(data.kin, data.fs_hz)


@dataclass(frozen=True)
class LogRate:
    """A model's system at the log's rate (:meth:`Searcher.log_rate`): for each decimated row used, the samples of its
    decimation span, decimated only by ``factor`` (:func:`log_rate_factor`: the band of the value's grid kept).

    ``W`` is ``(rows, per_row, columns)``, ``y`` ``(rows, per_row)``; ``at`` the index of each in the log decimated by ``factor``.
    """

    W: np.ndarray
    y: np.ndarray
    at: np.ndarray
    factor: int

    def rows(self, rows: np.ndarray | slice, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(W, y)`` on the samples of ``rows`` (of the decimated rows used), ``x`` (``(rows, per_row, m)``) beside ``W``."""
        W = self.W if x is None else np.concatenate([self.W, x], axis=2)
        W, y = W[rows], self.y[rows]
        return W.reshape(-1, W.shape[2]), y.reshape(-1)


def log_rate_factor(fs_hz: float, decimation: int, top_hz: float) -> int:
    """The decimation of a search at the log's rate: the coarsest that divides the rows' ``decimation`` and keeps ``top_hz`` (the top
    of the value's grid) in its band (:func:`ilic_cli.filtering.decimated_band_hz`): 5 at 500 Hz for a 40 Hz top.

    The band the search needs and no more: above it the log's rate holds the position noise differentiated twice, which a
    resonance's column carries into the fit (the corpus's 500 Hz flexibility logs, searched on every sample: damping ratios
    0.16-0.39 for 0.10-0.15; in the 40 Hz band 0.09-0.17).
    """
    r = max(int(decimation), 1)
    return max(d for d in range(1, r + 1) if r % d == 0 and decimated_band_hz(fs_hz, d) >= top_hz * (1.0 - 1e-9))


class Searcher:
    """Scans the nonlinear parameter of effects on one IDIM data set, with cached grid columns.

    An effect whose value is searched at the log's rate (:attr:`ilic_cli.effects.Scan.at_log_rate`) is scanned and refined
    on the model's :class:`LogRate` system (``at``); every other on the decimated rows ``(W0, y)``.
    """

    def __init__(self, data: IDIMData, fs_hz: float, rows: np.ndarray, held: np.ndarray | None = None) -> None:
        self.data = data
        self.fs = fs_hz
        self.keep = rows
        self.held = held
        """The force of held levels on the rows (:func:`~ilic_cli.diagnosis.system.system` takes it off the force): taken off every
        shifted force too; ``None``: none."""
        k = data.kin
        dec = data.decimate
        sign = None if k.sign_qd is None else dec(k.sign_qd)  # a friction law's sign (diagnosis.propose.prepare_system), decimated
        self.kin_dec = Kinematics(qd=dec(k.qd), qdd=dec(k.qdd), q=None if k.q is None else dec(k.q), t=data.t_dec, sign_qd=sign, speed_noise=k.speed_noise)
        self._cache: dict[str, tuple[np.ndarray, np.ndarray, bool]] = {}
        self._rate_cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def at_log_rate(self, effect: Effect) -> bool:
        """Whether ``effect``'s value is searched at the log's rate on this log (:attr:`ilic_cli.effects.Scan.at_log_rate`)."""
        return searched_at_log_rate(effect, self.data)

    def rate_factor(self, effect: Effect) -> int:
        """The decimation of ``effect``'s search at the log's rate (:func:`log_rate_factor` of its grid's top)."""
        assert effect.scan is not None
        return log_rate_factor(self.fs, self.data.settings.decimation, float(effect.scan.grid(self.data.kin, self.fs)[-1]))

    def spans(self, factor: int) -> np.ndarray:
        """For each decimated row used, its decimation span in the log decimated by ``factor`` (indices, ``(rows, r / factor)``), centred on it."""
        n, r = len(self.data.kin.qd), max(self.data.settings.decimation, 1)
        kept = kept_indices(n, r)
        kept = (kept if self.data.rows is None else kept[self.data.rows])[self.keep]
        fine = kept_indices(n, factor)
        m = r // factor
        pos = (kept - fine[0]) // factor
        return np.clip(pos[:, None] + np.arange(m)[None, :] - m // 2, 0, len(fine) - 1)

    def decimated(self, x: np.ndarray, factor: int) -> np.ndarray:
        """Full-rate column(s) ``x`` decimated by ``factor`` as the rows are by theirs (the same filter)."""
        return replace(self.data, settings=replace(self.data.settings, decimation=factor), rows=None, memo={}).decimate(x)

    def log_rate(self, base: Model, steps: list[Step] | tuple[Step, ...], given: np.ndarray | None = None, factor: int = 1) -> LogRate:
        """The system of ``base + steps`` at the log's rate, decimated by ``factor``, on the rows' spans (:class:`LogRate`), as
        :func:`ilic_cli.diagnosis.system.system` builds it on the rows: a shift moves the force, a held level is taken off it;
        ``given`` columns (on the rows) are interpolated in time onto their spans (a friction drift's slow trends)."""
        data, k = self.data, self.data.kin
        t = k.t
        assert t is not None
        y = np.asarray(data.tau, dtype=np.float64)
        cols = [np.asarray(base.matrix(k))]
        if any(s.effect.shift for s in steps):
            y = evaluated_later(t, data.tau, shift_value(steps))
        for s in steps:
            if s.level is not None:
                y = y - s.effect.matrix(k, s.value, self.fs) @ np.asarray(s.level, dtype=np.float64)
            elif not s.effect.shift:
                cols.append(s.effect.matrix(k, s.value, self.fs))
        at = self.spans(factor)
        W = self.decimated(np.hstack(cols), factor)[at]
        if given is not None and given.shape[1]:
            t_rows, t_at = data.t_dec[self.keep], t[kept_indices(len(t), factor)][at]
            W = np.concatenate([W, np.stack([np.interp(t_at, t_rows, g) for g in given.T], axis=2)], axis=2)
        return LogRate(W, self.decimated(y, factor)[at], at, factor)

    def rate_grid(self, effect: Effect) -> tuple[np.ndarray, np.ndarray]:
        """``(values, X)`` of an effect searched at the log's rate: X is ``(rows, per_row, G, m)``, its columns on the rows' spans."""
        if effect.id not in self._rate_cache:
            assert effect.scan is not None
            values = effect.scan.grid(self.data.kin, self.fs)
            factor = self.rate_factor(effect)
            at = self.spans(factor)
            full = np.concatenate([effect.matrix(self.data.kin, v, self.fs) for v in values], axis=1)
            X = self.decimated(full, factor)[at]
            self._rate_cache[effect.id] = (values, X.reshape(*at.shape, len(values), -1))
        return self._rate_cache[effect.id]

    def grid(self, effect: Effect) -> tuple[np.ndarray, np.ndarray, bool]:
        """``(values, X, exact)``: X is ``(n, G, m)`` columns or, for a shift, ``(n, G)`` forces."""
        if effect.id in self._cache:
            return self._cache[effect.id]
        assert effect.scan is not None
        values = effect.scan.grid(self.data.kin, self.fs)
        if effect.shift:
            t = self.data.kin.t
            assert t is not None
            Y = np.stack([evaluated_later(t, self.data.tau, v) for v in values], axis=1)
            Y = self.data.decimate(Y)[self.keep]
            out = (values, Y if self.held is None else Y - self.held[:, None], True)
        elif len(values) <= EXACT_GRID_MAX:
            full = np.concatenate([effect.matrix(self.data.kin, v, self.fs) for v in values], axis=1)
            m = full.shape[1] // len(values)
            out = (values, self.data.decimate(full)[self.keep].reshape(-1, len(values), m), True)
        else:
            X = np.stack([effect.matrix(self.kin_dec, v, self.fs)[self.keep] for v in values], axis=1)
            out = (values, X, False)
        self._cache[effect.id] = out
        return out

    def exact(self, effect: Effect, value: Any) -> np.ndarray:
        """Exactly decimated columns (or shifted force) for one value."""
        if effect.shift:
            y = shifted_force(self.data, value, remember=False)[self.keep]
            return y if self.held is None else y - self.held
        return effect_columns(self.data, effect, value, remember=False)[self.keep]

    def exact_linear(self, effect: Effect) -> np.ndarray:
        """Decimated columns of an effect without a nonlinear parameter."""
        return effect_columns(self.data, effect)[self.keep]

    def fitted(
        self, effect: Effect, W0: np.ndarray, y: np.ndarray, value: Any, rows: np.ndarray | slice = slice(None), at: LogRate | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The system ``(W, y)`` with ``effect`` at ``value`` on ``rows``: at the log's rate on ``at`` for an effect searched there, else decimated."""
        rate = self.at_log_rate(effect)
        assert not rate or at is not None, f"{effect.id} is searched at the log's rate: give its LogRate"
        if rate and at is not None:
            assert at.factor == self.rate_factor(effect)
            return at.rows(rows, self.decimated(effect.matrix(self.data.kin, value, self.fs), at.factor)[at.at])
        x = self.exact(effect, value)
        if effect.shift:
            return W0[rows], x[rows]
        return np.hstack([W0, x])[rows], y[rows]

    def rss(self, effect: Effect, W0: np.ndarray, y: np.ndarray, value: Any, rows: np.ndarray | slice = slice(None), at: LogRate | None = None) -> float:
        return lstsq(*self.fitted(effect, W0, y, value, rows, at))[1]

    def scan(self, effect: Effect, W0: np.ndarray, y: np.ndarray, rows: np.ndarray | slice = slice(None), n_best: int = 3, at: LogRate | None = None) -> float:
        """Best grid value of ``effect`` added to ``(W0, y)`` on ``rows`` (to ``at``, on their spans, for an effect searched at the log's rate)."""
        if self.at_log_rate(effect):
            assert at is not None, f"{effect.id} is searched at the log's rate: give its LogRate"
            values, X = self.rate_grid(effect)
            Xr = X[rows]
            W_at, y_at = at.rows(rows)
            return float(values[int(np.argmin(batched_rss(W_at, y_at, Xr.reshape(-1, *Xr.shape[2:]))))])
        values, X, exact = self.grid(effect)
        if effect.shift:
            r = shifted_rss(W0[rows], X[rows])
        else:
            r = batched_rss(W0[rows], y[rows], X[rows])
        if exact:
            return float(values[int(np.argmin(r))])
        # local minima, best first, re-evaluated with exact columns; the lowest is always among them: it can lie on a plateau
        # (values whose columns coincide on these rows: a payload's change time anywhere in a dwell), which no strict local
        # minimum marks, and the noise's minima elsewhere were taken instead (corpus s492: 2.74 s for a change at 4.0 s,
        # whose dwell's plateau was the lowest)
        interior = np.r_[True, r[1:] < r[:-1]] & np.r_[r[:-1] < r[1:], True]
        interior[int(np.argmin(r))] = True
        idx = np.flatnonzero(interior)
        idx = idx[np.argsort(r[idx])][:n_best]
        exact_rss = [self.rss(effect, W0, y, float(values[i]), rows) for i in idx]
        return float(values[idx[int(np.argmin(exact_rss))]])

    def grid_values(self, effect: Effect) -> np.ndarray:
        """The grid of ``effect``'s value."""
        return self.rate_grid(effect)[0] if self.at_log_rate(effect) else self.grid(effect)[0]

    def refine(
        self, effect: Effect, W0: np.ndarray, y: np.ndarray, value: float, rows: np.ndarray | None = None, at: LogRate | None = None
    ) -> tuple[Any, float | None]:
        """1-D refinement between the neighbouring grid points; ``(value, std)`` from the RSS curvature.

        An effect with a secondary parameter gets it refined next (within its
        bounds), then the first again; its value is the pair. With ``rows``
        (a training set) only the value is refined (std ``None``). An effect
        searched at the log's rate is refined, and its std taken, there (``at``).
        A time of the log (a payload's change) is its profile's 95 % interval
        instead (:meth:`profile_interval`): its middle, and half its width over
        ``Z95``, which on a quadratic profile are the optimum and the curvature's.
        """
        assert effect.scan is not None
        sec = effect.scan.secondary
        sel = slice(None) if rows is None else rows
        values = self.grid_values(effect)
        i = int(np.argmin(np.abs(values - value)))
        lo, hi = float(values[max(i - 1, 0)]), float(values[min(i + 1, len(values) - 1)])
        if lo == hi:
            return value, None
        use_log = effect.scan.log and lo > 0
        other = None if sec is None else sec[4]
        pack = (lambda v: v) if sec is None else (lambda v: (v, other))  # noqa: E731
        best = minimise(lambda v: self.rss(effect, W0, y, pack(v), sel, at), lo, hi, use_log)
        if sec is not None:
            other = minimise(lambda z: self.rss(effect, W0, y, (best, z), sel, at), sec[2], sec[3], True)
            best = minimise(lambda v: self.rss(effect, W0, y, (v, other), sel, at), lo, hi, use_log)
        if rows is not None:
            return pack(best), None
        W1, y1 = self.fitted(effect, W0, y, pack(best), at=at)
        n = len(y1)
        k = W1.shape[1] + 1
        theta, _ = lstsq(W1, y1)
        rho = lag1_autocorrelation(y1 - W1 @ theta)
        inflation = variance_inflation(rho)
        if effect.scan.of_the_whole_log and sec is None and not self.at_log_rate(effect):
            # a time of the log: the profile's 95 % interval, its middle and half-width / Z95 (a plateau where nothing shows it)
            lo_t, hi_t = self.profile_interval(effect, W0, y, float(best), Z95**2 * inflation / max(n - k, 1))
            # between two accelerations of the reference the change shows in no row but through the noise, which the force and
            # the measured acceleration share in closed loop (the PD's answer to the sensor noise) and which tilts the profile to
            # one end: every time of such a span is as likely as any other, and an interval that reaches one holds it whole
            # (corpus --reseed 2 rev0.5 s6492: the profile fell 3 % steadily from 3.68 s to 4.83 s, where the reference rests from
            # 3.66 s to 4.84 s; 4.47 to 4.85 s stated, the truth 4.0 s)
            lo_t, hi_t = spans_reached(self.data.unaccelerated, lo_t, hi_t)
            return 0.5 * (lo_t + hi_t), (hi_t - lo_t) / (2.0 * Z95)
        # curvature of the profile RSS at the optimum, in the parameter's own unit
        h = 1e-3 * abs(best) if best != 0 else 1e-3 * (hi - lo)
        if effect.shift:
            h = max(h, 0.05 / self.fs)
        r0 = self.rss(effect, W0, y, pack(best), at=at)
        rp, rm = self.rss(effect, W0, y, pack(best + h), at=at), self.rss(effect, W0, y, pack(best - h), at=at)
        curv = (rp - 2 * r0 + rm) / h**2
        std = math.sqrt(2.0 * r0 / max(n - k, 1) * inflation / curv) if curv > 0 else None
        return pack(best), std

    def profile_interval(self, effect: Effect, W0: np.ndarray, y: np.ndarray, best: float, share: float) -> tuple[float, float]:
        """The values about ``best`` whose RSS stays within ``1 + share`` of the least on the grid: the grid's profile (the scan's
        batched RSS) walked out from ``best`` each way to the first value beyond, the crossing interpolated linearly (an end of the
        grid ends the walk there).

        With ``share = Z95^2 c / (n - k)`` (``c`` the residual's autocorrelation, :meth:`refine`'s) it is the likelihood-ratio
        95 % interval: on a quadratic profile ``best +- Z95 std``, the curvature's. A payload's change time has no quadratic
        profile: the force shows the mass only while the axis accelerates, so every time between two accelerations fits alike,
        and the least RSS lies on the plateau's edge by the noise (corpus s12240, a change at 4.0 s during the S-curves' cruise
        and dwell from 3.74 s to 4.74 s: 4.728 +- 0.046 s from the curvature at that edge)."""
        values, X, _ = self.grid(effect)
        r = batched_rss(W0, y, X)
        threshold = float(np.min(r)) * (1.0 + share)
        i0 = int(np.argmin(np.abs(values - best)))
        ends = []
        for direction in (-1, 1):
            i, end = i0, float(values[i0])
            while 0 <= i + direction < len(values):
                j = i + direction
                if r[j] > threshold:
                    frac = (threshold - r[i]) / (r[j] - r[i]) if r[j] > r[i] else 0.0
                    end = float(values[i] + (values[j] - values[i]) * min(max(frac, 0.0), 1.0))
                    break
                i, end = j, float(values[j])
            ends.append(end)
        return min(ends[0], best), max(ends[1], best)


EDGE_STEPS = 0.5
"""A nonlinear estimate within this many grid steps of either end of its grid is on the edge of the search."""

SECONDARY_EDGE = 0.02
"""A secondary parameter within this share (on a log scale) of either bound is on the edge (e.g. damping 0.4998 of 0.5)."""


def at_edge(effect: Effect, grid: np.ndarray, value: Any, joint: str = "prismatic") -> str | None:
    """Why ``value`` lies on the edge of ``effect``'s search (the grid's ends, the secondary parameter's bounds), else ``None``;
    the value in its units on a ``joint`` (:meth:`ilic_cli.effects.Effect.unit_on`).

    The optimum of a search is only an estimate when the search brackets it:
    on an edge, the data would have gone on beyond the range searched.
    """
    assert effect.scan is not None
    scan = effect.scan
    first = float(value[0]) if isinstance(value, tuple) else float(value)
    if len(grid) >= 2:
        f = np.log if scan.log and grid[0] > 0 else (lambda x: x)  # noqa: E731
        lo_step, hi_step = f(grid[1]) - f(grid[0]), f(grid[-1]) - f(grid[-2])
        end = "lower" if f(first) <= f(grid[0]) + EDGE_STEPS * lo_step else "upper" if f(first) >= f(grid[-1]) - EDGE_STEPS * hi_step else None
        if end is not None:
            unit = effect.unit_on(scan.unit, joint)
            return f"{scan.name} = {first:.4g} {unit} at the {end} end of the range searched ({grid[0]:.4g} to {grid[-1]:.4g})".replace("  ", " ")
    if scan.secondary is not None and isinstance(value, tuple):
        name, _, low, high, _ = scan.secondary
        span = np.log(high) - np.log(low)
        second = float(value[1])
        if np.log(second) <= np.log(low) + SECONDARY_EDGE * span or np.log(second) >= np.log(high) - SECONDARY_EDGE * span:
            return f"{name} = {second:.4g} at a bound of the range searched ({low:g} to {high:g})"
    return None


SEARCH_STEPS: dict[str, int] = {"stribeck": 10, "delay": 4, "flexibility": 6}
"""The effects whose nonlinear value the inverse model biases on closed-loop data, and the half-width of its closed-loop search.

In steps of the effect's own grid around the inverse model's value (default :data:`DEFAULT_STEPS`); used by
:mod:`ilic_cli.diagnosis.decide` (per fold) and :mod:`ilic_cli.diagnosis.refit`.

Origin (corpus, inverse model against truth): Stribeck ``vs`` off by a factor up to 2.6
(0.0211 for 0.008 m/s; the grid steps by a factor 1.126, so 10 steps reach a factor 3.3);
drive lags 0.3-0.7 ms too long (grid step 0.5 ms). A resonance near the top of the rows' band
(40 Hz) under the current loop at 1 kHz up to 3.3 steps low (the grid steps by a factor 1.08):
27.2-29.8 Hz for 35 Hz on the 0.01 kg·m² joint's trapezoids, 25.2-27.2 Hz for 31 Hz on the 200 kg
axis's S-curves, over six seeds each; with 3 steps the closed-loop fit ended on the range's edge
(36.8 Hz of 21.6-34.3 Hz) and the inverse model's stiffness, 72 % low, was kept. 6 steps reach a
factor 1.59. Elsewhere resonances are within two steps (the 0.5 kg·m² joint's chirps at 1 kHz 7-12 % low; at
500 Hz and 2 kHz 1-3 % low). Ripple periods
were within about a grid step; a payload's change time up to 4 steps off (11.64 s for 11.18 s),
which 3 steps bring to 11.32 s. A wider range lets the search wander into the aliases of a
periodic ripple."""

DEFAULT_STEPS = 3
"""Half-width of the search for the effects not in :data:`SEARCH_STEPS` (grid steps)."""

SEARCH_SPAN: dict[str, float] = {"delay": 2e-3}
"""The least half-width of the closed-loop search where the inverse model's bias is a quantity, not a number of grid
steps (the effect's unit: s). A drive lag's bias is a time (0.3-0.7 ms, above); its grid steps by half a sample, so four
steps were 2 ms at 1 kHz but 0.5 ms at 4 kHz, and the search ended on its edge and kept the inverse model's value
(a 1.41 ms lag at 4 kHz on a 3 kg·m² joint: 1.71 ms in every fold, rejected, and Stribeck friction named in its place;
searched over 2 ms, 0.82-1.22 ms and named). At 1 kHz and below :data:`SEARCH_STEPS` reach it already."""


def search_range(effect: Effect, grid: np.ndarray, value: float) -> np.ndarray:
    """The part of ``effect``'s grid the closed loop searches: :data:`SEARCH_STEPS` steps either side of ``value``, and at
    least :data:`SEARCH_SPAN` (a grid of even steps)."""
    k = SEARCH_STEPS.get(effect.id, DEFAULT_STEPS)
    span = SEARCH_SPAN.get(effect.id)
    if span is not None and len(grid) > 1:
        k = max(k, math.ceil(span / abs(float(grid[1] - grid[0])) - 1e-9))
    i = int(np.argmin(np.abs(grid - value)))
    return grid[max(i - k, 0) : i + k + 1]


FOLD_XATOL_STEPS = 0.1
"""Tolerance of :func:`fold_value`'s search, in steps of the effect's grid (a drive lag: 0.05 ms on its 0.5 ms grid)."""


class FoldValue(NamedTuple):
    """One fold's closed-loop search of a value (:func:`fold_value`): the step it replays, and the search's optimum when that
    lay on the edge of the range searched (``None`` otherwise): the step is then the inverse model's."""

    step: Step
    edge: float | None = None


def fold_value(
    prefix: list[Step], step: Step, grid: np.ndarray, training_error: Callable[[list[Step]], float], xatol_steps: float = FOLD_XATOL_STEPS
) -> FoldValue:
    """``step`` with its nonlinear value searched on one fold's closed-loop training error (``prefix`` kept before it).

    The inverse model's estimate of some effects is off by several steps of
    its grid on closed-loop data (:data:`ilic_cli.diagnosis.select.SEARCH_STEPS`:
    a drive lag 30-66 % too long), which can hide a real effect from the
    replay. Within that range of ``grid`` around the inverse value, the value
    is searched on the simulated force error of the fold's training blocks
    (the linear parameters refitted by the inverse model at each value), so
    the held-out block still judges a model it did not shape. An optimum on
    the edge of the range, or one that does not lower the training error,
    keeps the inverse value; the edge's optimum is returned beside it, for the
    report (the error falling on beyond the range is no estimate of the value:
    corpus s3460, a 0.227 ms current loop's lag judged before the Stribeck
    friction beside it, the training error falling on to -4 ms in every fold
    and the inverse model's -0.42 ms replayed).
    """
    scan = step.effect.scan
    assert scan is not None
    v0 = float(step.value)
    sub = search_range(step.effect, grid, v0)
    lo, hi = float(sub[0]), float(sub[-1])
    if not hi > lo:
        return FoldValue(step)
    memo: dict[float, float] = {}

    def err(v: float) -> float:
        if v not in memo:
            memo[v] = training_error([*prefix, Step(step.effect, v)])
        return memo[v]

    best = minimise(err, lo, hi, scan.log and lo > 0, rel_tol=xatol_steps / max(len(sub) - 1, 1))
    if at_edge(step.effect, sub, best):
        return FoldValue(step, best)
    return FoldValue(Step(step.effect, best) if err(best) < err(v0) else step)


STILL_ACCELERATION = 1e-6
"""The reference does not accelerate where its second difference over a row's period is at most this share of its largest:
zero but for the rounding of a log's double-precision positions (4e-16 on a 1 m stroke, against 1e-4 for a 1 m/s² ramp over
the rows' 10 ms). A reference written with fewer digits (6: 1e-6) keeps the spans whose positions difference to zero exactly,
its dwells; over a single sample an 8 kHz ramp's 1.6e-8 would round to zero too."""


def unaccelerated_spans(t: np.ndarray, q_ref: np.ndarray, stride: int = 1) -> tuple[tuple[float, float], ...]:
    """The spans ``(first, last)`` of times ``t`` (s) over which the reference ``q_ref`` does not accelerate: its centred second
    difference over ``stride`` samples (the rows' decimation) at most :data:`STILL_ACCELERATION` of its largest. Its cruises
    and dwells, each edge within ``stride`` samples; none on a reference that accelerates throughout (a chirp, a multisine)."""
    q = np.asarray(q_ref, dtype=np.float64)
    k = max(int(stride), 1)
    if len(q) <= 2 * k:
        return ()
    d2 = np.abs(q[2 * k :] - 2.0 * q[k:-k] + q[: -2 * k])
    if not np.max(d2) > 0.0:
        return ()
    still = k + np.flatnonzero(d2 <= STILL_ACCELERATION * np.max(d2))  # sample i: the difference centred on it
    return tuple((float(t[r[0]]), float(t[r[-1]])) for r in contiguous_runs(still) if len(r) > 1)


def spans_reached(spans: tuple[tuple[float, float], ...], lo: float, hi: float) -> tuple[float, float]:
    """The interval ``lo`` to ``hi`` widened to hold every span of ``spans`` it reaches."""
    for a, b in spans:
        if a <= hi and b >= lo:
            lo, hi = min(lo, a), max(hi, b)
    return lo, hi
