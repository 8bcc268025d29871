"""Exciting reference trajectories: concatenated trapezoidal velocity profiles, and multisines.

Shapes (:data:`TRAJECTORIES`, ``ilic simulate --trajectory``): ``paper``, the
paper's exciting cycle (:func:`exciting_cycle`); ``trapezoid``, back-and-forth
trapezoidal moves with a dwell at rest (:func:`trapezoid_moves`); ``multisine``,
a band-limited sum of harmonics with random phases (:class:`Multisine`).

A :class:`Trajectory` is a sequence of constant-acceleration segments, so the
reference position, velocity and acceleration are exact piecewise
polynomials (no noise, no numerical differentiation). It can repeat with a
period (the paper's ``T_cycle = 6.2 s``); the position then advances by the
cycle's net displacement each period (zero for the default cycle, which
returns to its start).

At an acceleration jump the point value is right-continuous (the
acceleration about to be applied, what the controller uses). The *logged*
reference derivatives are the one-sample centred averages
(:meth:`Trajectory.sample_centred`), equal to the point values everywhere
except at the jumps, where the acceleration is the mean of both sides; they
match the centred force sensor of the closed loop (see ``closed_loop``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.errors import ParameterError, SimulationError

T_CYCLE = 6.2
"""Paper's cycle time T_cycle = T_obs (s)."""


@dataclass(frozen=True)
class Move:
    """One trapezoidal move: ramp to ``v`` in ``t_acc``, cruise ``t_const``, ramp down in ``t_acc``, dwell.

    Displacement ``v*(t_acc + t_const)``; duration ``2*t_acc + t_const + dwell``.
    """

    v: float
    t_acc: float
    t_const: float
    dwell: float

    @property
    def displacement(self) -> float:
        return self.v * (self.t_acc + self.t_const)

    @property
    def duration(self) -> float:
        return 2 * self.t_acc + self.t_const + self.dwell

    def segments(self) -> list[tuple[float, float]]:
        a = self.v / self.t_acc if self.t_acc > 0 else 0.0
        segs = [(self.t_acc, a), (self.t_const, 0.0), (self.t_acc, -a), (self.dwell, 0.0)]
        return [(d, acc) for d, acc in segs if d > 0]


DEFAULT_MOVES: tuple[Move, ...] = (
    Move(+0.210, 0.14, 0.50, 0.0),  # +0.1344 m
    Move(-0.120, 0.08, 0.70, 0.0),  # -0.0936 m
    Move(+0.150, 0.10, 0.45, 0.0),  # +0.0825 m
    Move(-0.240, 0.16, 0.40, 0.0),  # -0.1344 m
    Move(+0.090, 0.06, 0.70, 0.0),  # +0.0684 m
    Move(-0.135, 0.09, 0.30, 0.0),  # -0.05265 m
    Move(+0.180, 0.12, 0.49, 0.0),  # +0.1098 m
    Move(-0.105, 0.07, 1.02, 0.0),  # -0.11445 m
)
"""Default exciting cycle: eight back-to-back trapezoids alternating in direction,
0.09-0.24 m/s, all ramps at 1.5 m/s^2 (so the acceleration is continuous through
each reversal and across the cycle boundary: the only acceleration jumps are the
ramp/cruise transitions), breakpoints on the 1 ms grid, 6.2 s in all, back to the
start (excursion -0.011..+0.134 m from it). No dwell: the velocity reverses under acceleration, so
the axis never rests in stiction, whose position error (the ramp-tracking lead of
the backward-difference velocity, paper eq. 27) the Coulomb static level would
otherwise hold during a dwell."""

DEFAULT_Q0 = 0.05
"""Start position (m): keeps the default cycle within 0.039-0.185 m of the EMPS stroke."""


class Sampled:
    """Sampling of a reference given by its point values (:meth:`evaluate`), shared by every shape."""

    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Point values ``q, qd, qdd`` at times ``t``."""
        raise NotImplementedError

    def _cycle_samples(self, n: int, fs_hz: float) -> int:
        """Samples per cycle when ``n`` samples repeat it exactly, else 0 (never, unless a shape says so)."""
        return 0

    def sample(self, n: int, fs_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``t, q, qd, qdd`` point values at ``t = k/fs`` for ``k < n``."""
        t = _grid(n, fs_hz)
        return (t, *self._tiled(t, fs_hz, 0.0))

    @staticmethod
    def _tile(one: tuple[np.ndarray, ...], n: int) -> tuple[np.ndarray, ...]:
        """Each array of ``one`` repeated to length ``n`` (the values of ``np.tile``, one copy each)."""
        out = []
        for a in one:
            full = np.empty(n, dtype=a.dtype)
            k = len(a)
            full[:k] = a
            m = k
            while m < n:
                c = min(m, n - m)
                full[m : m + c] = full[:c]
                m += c
            out.append(full)
        return tuple(out)

    def _tiled(self, t: np.ndarray, fs_hz: float, shift: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``evaluate(t + shift)``; a returning cycle on the sample grid is evaluated once and tiled."""
        k = self._cycle_samples(len(t), fs_hz)
        if not k:
            return self.evaluate(t + shift)
        q, qd, qdd = self._tile(self.evaluate(t[:k] + shift), len(t))
        return q, qd, qdd

    def sample_centred(self, n: int, fs_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``t, q, qd, qdd`` with ``qd, qdd`` averaged over ``[t - T/2, t + T/2]`` (exact).

        Equal to the point values except at acceleration jumps (mean of both
        sides there). These are the logged reference channels.
        """
        t, q, _, _, qd, qdd = self.sample_both(n, fs_hz)
        return t, q, qd, qdd

    def sample_both(self, n: int, fs_hz: float) -> tuple[np.ndarray, ...]:
        """``t, q, qd, qdd, qd_centred, qdd_centred``: :meth:`sample` and :meth:`sample_centred` at once
        (the same values; ``t`` and ``q`` shared)."""
        t = _grid(n, fs_hz)
        k = self._cycle_samples(n, fs_hz)
        tc = t[:k] if k else t  # a returning cycle: one cycle, then tiled (same values)
        h = 0.5 / fs_hz
        q, vp, ap = self.evaluate(tc)
        qa, va, _ = self.evaluate(tc - h)
        qb, vb, _ = self.evaluate(tc + h)
        qd = (qb - qa) * fs_hz
        qdd = (vb - va) * fs_hz
        # round-off: exact constants where the point value is already exact
        qd = np.where(np.abs(qd - vp) < 1e-9, vp, qd)
        qdd = np.where(np.abs(qdd - ap) < 1e-7, ap, qdd)
        if k:
            q, vp, ap, qd, qdd = self._tile((q, vp, ap, qd, qdd), n)
        return t, q, vp, ap, qd, qdd


@dataclass(frozen=True)
class Trajectory(Sampled):
    """Constant-acceleration segments ``(duration_s, acceleration)`` starting at velocity ``v0``.

    ``repeat``: repeat the segments every :attr:`period` seconds (the sum of
    the durations); otherwise play once and continue at the final velocity.
    ``t_offset``: start the (repeating) pattern ``t_offset`` seconds into it;
    positions are shifted so that ``q(0) = q0``.
    """

    segments: tuple[tuple[float, float], ...]
    q0: float = DEFAULT_Q0
    v0: float = 0.0
    repeat: bool = True
    t_offset: float = 0.0
    description: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if not self.segments:
            raise SimulationError("trajectory", "no segments")
        d = np.array([s[0] for s in self.segments], dtype=float)
        if (d <= 0).any() or not np.isfinite(d).all():
            raise SimulationError("trajectory", "segment durations must be positive")

    # knots ---------------------------------------------------------------
    def _knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        d = np.array([s[0] for s in self.segments], dtype=float)
        a = np.array([s[1] for s in self.segments], dtype=float)
        tk = np.concatenate([[0.0], np.cumsum(d)])
        v = np.empty(len(d) + 1)
        q = np.empty(len(d) + 1)
        v[0], q[0] = self.v0, 0.0
        for i in range(len(d)):
            v[i + 1] = v[i] + a[i] * d[i]
            if abs(v[i + 1]) < 1e-12:  # a move ends at rest: exactly, not by round-off
                v[i + 1] = 0.0
            q[i + 1] = q[i] + v[i] * d[i] + 0.5 * a[i] * d[i] ** 2
        return tk, a, v, q

    @property
    def period(self) -> float:
        return float(sum(s[0] for s in self.segments))

    def to_dict(self) -> dict[str, Any]:
        return {
            "q0": self.q0,
            "v0": self.v0,
            "repeat": self.repeat,
            "t_offset": self.t_offset,
            "period_s": self.period,
            "segments": [[float(d), float(a)] for d, a in self.segments],
            **self.description,
        }

    # evaluation ----------------------------------------------------------
    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Point values ``q, qd, qdd`` at times ``t`` (acceleration right-continuous)."""
        t = np.asarray(t, dtype=np.float64)
        if self.t_offset:
            shifted = Trajectory(self.segments, self.q0, self.v0, self.repeat, 0.0)
            q_at0 = shifted._raw(np.array([self.t_offset]))[0][0]
            q, v, a = shifted._raw(t + self.t_offset)
            return q - q_at0 + self.q0, v, a
        return self._raw(t)

    def _cycle_samples(self, n: int, fs_hz: float) -> int:
        """Samples per cycle when ``n`` samples at ``fs_hz`` repeat it exactly (a returning cycle on the
        sample grid, more than two cycles long), else 0."""
        m = self.period * fs_hz
        k = int(round(m))
        if not (self.repeat and abs(m - k) < 1e-9 and k > 0 and n > 2 * k):
            return 0
        _, _, _, qk = self._knots()
        return k if abs(qk[-1]) < 1e-15 else 0

    def _raw(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tk, a, v, q = self._knots()
        T = tk[-1]
        if self.repeat:
            if v[-1] != self.v0 and abs(v[-1] - self.v0) > 1e-12:
                raise SimulationError("trajectory", "a repeating cycle must end at its start velocity")
            n = np.floor(t / T + 1e-12)
            tc = t - n * T
            tc = np.where(tc < 0, 0.0, tc)
            base = self.q0 + n * q[-1]
        else:
            tc = np.clip(t, 0.0, T)
            base = np.full_like(t, self.q0)
        i = np.clip(np.searchsorted(tk, tc + 1e-12, side="right") - 1, 0, len(a) - 1)
        h = tc - tk[i]
        h = np.where(np.abs(h) < 1e-9, 0.0, h)  # samples on a knot: exactly on it (reversals give qd = 0, sign 0)
        acc = a[i]
        vel = v[i] + acc * h
        pos = base + q[i] + v[i] * h + 0.5 * acc * h * h
        if not self.repeat:
            after = t > T
            pos = np.where(after, base + q[-1] + v[-1] * (t - T), pos)
            vel = np.where(after, v[-1], vel)
            acc = np.where(after, 0.0, acc)
        return pos, vel, acc


def _grid(n: int, fs_hz: float) -> np.ndarray:
    """``np.arange(n) / fs_hz`` (the same values, without the integer temporary)."""
    t = np.arange(n, dtype=np.float64)
    t /= fs_hz
    return t


DEFAULT_OFFSET = 5.62
"""Start of the default cycle (s into it): the middle of the last move's 1.02 s cruise,
so that every window boundary (a multiple of T_cycle) falls in a steady cruise,
away from the tracking transients of acceleration jumps and velocity reversals,
which the window-edge effects of the IDIM-ILIC filter would otherwise turn into a
bias. The axis starts there on the reference (position and velocity)."""


def exciting_cycle(
    moves: tuple[Move, ...] = DEFAULT_MOVES, *, q0: float = DEFAULT_Q0, seed: int | None = None, spread: float = 0.3, t_offset: float = DEFAULT_OFFSET
) -> Trajectory:
    """The repeating exciting cycle (paper section VI-D), started ``t_offset`` into it.

    ``seed``: scale each move's velocity by a factor drawn uniformly in
    ``[1 - spread, 1]`` (numpy PCG64); the last move is rescaled so the cycle
    still returns to its start.
    """
    moves_list = list(moves)
    desc: dict[str, Any] = {"kind": "exciting_cycle", "moves": [[m.v, m.t_acc, m.t_const, m.dwell] for m in moves_list]}
    if seed is not None:
        rng = np.random.Generator(np.random.PCG64(seed))
        f = rng.uniform(1.0 - spread, 1.0, size=len(moves_list))
        moves_list = [Move(m.v * fi, m.t_acc, m.t_const, m.dwell) for m, fi in zip(moves_list, f, strict=True)]
        rest = sum(m.displacement for m in moves_list[:-1])
        last = moves_list[-1]
        moves_list[-1] = Move(-rest / (last.t_acc + last.t_const), last.t_acc, last.t_const, last.dwell)
        desc.update(seed=seed, spread=spread, moves=[[m.v, m.t_acc, m.t_const, m.dwell] for m in moves_list])
    segs = tuple(s for m in moves_list for s in m.segments())
    return Trajectory(segs, q0=q0, repeat=True, t_offset=t_offset, description=desc)


def with_constant_velocity(
    cycle: Trajectory, *, cycles_before: int, v: float, hold_s: float, window_s: float = T_CYCLE, t_ramp: float = 0.05, cycles_after: int = 2
) -> Trajectory:
    """Exciting cycles, then a stretch at constant velocity ``v``, then exciting cycles again.

    Layout: a rest of ``window_s - t_ramp``, ``cycles_before`` cycles, a ramp to
    ``v`` in ``t_ramp``, ``hold_s`` at ``v``, a ramp back to rest, ``cycles_after``
    cycles. The initial rest puts the end of the ramp on a window boundary
    (``(cycles_before + 1)*window_s`` when the cycle lasts ``window_s``), so
    with ``hold_s >= window_s`` the next window sees constant velocity only
    (loss of excitation, paper section V-E).
    """
    segs = list(cycle.segments)
    out = [(window_s - t_ramp, 0.0)] + segs * cycles_before + [(t_ramp, v / t_ramp), (hold_s, 0.0), (t_ramp, -v / t_ramp)] + segs * cycles_after
    desc = {
        "kind": "constant_velocity_window",
        "cycles_before": cycles_before,
        "v": v,
        "hold_s": hold_s,
        "t_ramp": t_ramp,
        "cycles_after": cycles_after,
        "cycle": cycle.to_dict(),
    }
    return Trajectory(tuple(out), q0=cycle.q0, repeat=False, description=desc)


TRAPEZOID_ACCEL = 1.5
"""Ramp acceleration of :func:`trapezoid_moves` (m/s^2), that of the paper's cycle."""


def _ms(x: float) -> float:
    """``x`` seconds on the 1 ms grid (at least 1 ms)."""
    return max(round(x * 1000.0), 1) / 1000.0


def trapezoid_moves(
    seed: int | None = None,
    *,
    pairs: int = 4,
    v_range: tuple[float, float] = (0.06, 0.22),
    top: float = 0.14,
    min_move: float = 0.03,
    dwell: float = 0.1,
    q0: float = DEFAULT_Q0,
) -> Trajectory:
    """Back-and-forth trapezoidal velocity moves with a dwell at rest after each, repeating.

    ``pairs`` pairs of a forward move to a level drawn in ``[min_move, top]``
    above ``q0`` and a backward move to a level drawn between ``0`` and
    ``min_move`` below it (the last pair returns to ``q0``), so the turning
    points vary from move to move; speeds drawn uniformly in ``v_range``
    (numpy PCG64(``seed``), default seed 0), adjusted so that the move ends on
    its level; ramps of about :data:`TRAPEZOID_ACCEL`, breakpoints on the 1 ms
    grid. Each move reverses the direction of motion, through a dwell of
    ``dwell`` s at rest (stiction, then break-away).
    """
    rng = np.random.Generator(np.random.PCG64(0 if seed is None else seed))
    moves: list[Move] = []
    here = 0.0
    for i in range(pairs):
        up = float(rng.uniform(max(here + min_move, min_move), top))
        down = 0.0 if i == pairs - 1 else float(rng.uniform(0.0, up - min_move))
        for target in (up, down):
            d = target - here
            v = float(rng.uniform(*v_range))
            ta = _ms(v / TRAPEZOID_ACCEL)
            tc = _ms(max(abs(d) / v - ta, 0.02))
            moves.append(Move(d / (ta + tc), ta, tc, dwell))
            here = target
    desc = {"kind": "trapezoid", "seed": seed, "dwell": dwell, "moves": [[m.v, m.t_acc, m.t_const, m.dwell] for m in moves]}
    return Trajectory(tuple(s for m in moves for s in m.segments()), q0=q0, repeat=True, description=desc)


@dataclass(frozen=True)
class Multisine(Sampled):
    """A band-limited multisine position reference: harmonics ``k*f0`` of equal velocity amplitude.

    ``q(t) = q0 + sum_k A_k (sin(w_k t + phi_k) - sin(phi_k))`` with
    ``w_k = 2 pi k f0`` and ``A_k = v_amp / w_k`` (a flat velocity spectrum), so
    ``q, qd, qdd`` are exact and consistent; the velocity crosses zero several
    times per period ``1/f0`` (Coulomb friction is excited).
    """

    f0: float
    harmonics: tuple[int, ...]
    v_amp: float
    phases: tuple[float, ...]
    q0: float = DEFAULT_Q0
    seed: int | None = None

    def __post_init__(self) -> None:
        if not (self.f0 > 0 and self.harmonics and len(self.phases) == len(self.harmonics) and min(self.harmonics) > 0):
            raise SimulationError("trajectory", "a multisine needs f0 > 0 and one phase per positive harmonic")

    def evaluate(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Point values ``q, qd, qdd`` at times ``t``."""
        t = np.asarray(t, dtype=np.float64)
        q = np.full_like(t, self.q0)
        qd = np.zeros_like(t)
        qdd = np.zeros_like(t)
        for k, ph in zip(self.harmonics, self.phases, strict=True):
            w = 2.0 * np.pi * k * self.f0
            arg = w * t + ph
            q += self.v_amp / w * (np.sin(arg) - np.sin(ph))
            qd += self.v_amp * np.cos(arg)
            qdd -= self.v_amp * w * np.sin(arg)
        return q, qd, qdd

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": "multisine",
            "q0": self.q0,
            "f0": self.f0,
            "harmonics": list(self.harmonics),
            "v_amp": self.v_amp,
            "phases": list(self.phases),
            "seed": self.seed,
        }


def multisine(seed: int | None = None, *, f0: float = 0.1, harmonics: tuple[int, int] = (1, 12), v_rms: float = 0.1, q0: float = DEFAULT_Q0) -> Multisine:
    """A multisine of harmonics ``harmonics[0]..harmonics[1]`` of ``f0`` (default 0.1-1.2 Hz), velocity RMS ``v_rms``.

    Phases uniform in ``[0, 2 pi)`` from numpy PCG64(``seed``) (default seed 0).
    """
    ks = tuple(range(harmonics[0], harmonics[1] + 1))
    rng = np.random.Generator(np.random.PCG64(0 if seed is None else seed))
    phases = tuple(float(x) for x in rng.uniform(0.0, 2.0 * np.pi, size=len(ks)))
    return Multisine(f0, ks, v_rms * float(np.sqrt(2.0 / len(ks))), phases, q0, seed)


TRAJECTORIES = ("paper", "trapezoid", "multisine")
"""Shapes of the simulated reference (``ilic simulate --trajectory``)."""


def make_trajectory(kind: str, seed: int | None = None) -> Trajectory | Multisine:
    """The reference of shape ``kind`` (:data:`TRAJECTORIES`), varied by ``seed``.

    ``paper``: :func:`exciting_cycle` (``seed`` scales its moves; none: the
    paper's cycle); ``trapezoid``: :func:`trapezoid_moves`; ``multisine``:
    :func:`multisine`.
    """
    if kind == "paper":
        return exciting_cycle(seed=seed)
    if kind == "trapezoid":
        return trapezoid_moves(seed)
    if kind == "multisine":
        return multisine(seed)
    raise ParameterError("trajectory", kind, f"one of {', '.join(TRAJECTORIES)}")
