"""Output error of open-loop segments: the recorded force drives the model, the measured position judges it.

Where the recorded force is the force the drive applied (a held command,
:func:`ilic_cli.simulation.replay.tau_sensor` ``command``) and nothing else
pushes the axis, the measured position is the model's response to that force
plus the sensor's noise, whatever the controller did: the closed loop's answer
to the noise is in the recorded force already. Its least-squares fit is then
the maximum-likelihood estimate under white position noise. A closed-loop
replay cannot use it so: it draws noise of its own, and the creep that noise
drives at a dwell is not the recording's.

The log is cut into segments of :data:`SEGMENT_S` (multiple shooting: the
open-loop drift of a marginally stable axis stays short), each simulated from
its own initial position and velocity. Those are fitted with the model's
parameters, by Levenberg-Marquardt on sensitivities taken by finite
differences of the simulation (:func:`fit_segments`).

The fit is judged by its residual: when the model and the segments' states
explain the measured position to within :data:`NOISE_FACTOR` of the sensor's
noise (:func:`ilic_cli.diagnosis.sensor.position_noise`, quantisation
included), the recording carries nothing else, and the estimate is the
recording's (:attr:`SegmentFit.consistent`). A force disturbance in the plant
moves the axis away from any open-loop model: the residual then stays above
the noise and the fit is not used.

Measured on the corpus (``tests/corpus/__init__.py``, the diagnosis's use of it:
:func:`ilic_cli.diagnosis.core.diagnose`): on the Stribeck trapezoid with
sensor noise only, over its five recordings, ``vs`` 7.972, 7.990, 8.036,
8.079, 7.988 mm/s for 8 and ``Fs`` 2.460-2.477 N for 2.47 (the closed-loop
search's: 9.1-12.1 mm/s and 2.17-2.55 N), the residual 0.50-0.51 um RMS for a
sensor noise of 0.54-0.55 um; with a force disturbance and a current loop
(``s213``) 26-29 um, so not used there; on the ripple trapezoid of seed 3220,
where the replay had accepted Stribeck friction beside the ripple, 0.499 um
with a level of -0.002 +- 0.003 N: refuted.

Pure numerics on arrays: the simulation is passed in.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.errors import IlicError
from ilic_cli.lsq import finite_or_none
from ilic_cli.parallel import ordered_map

METHOD = "open-loop segments' output error"
"""The method the findings and the model file name when this fit is accepted."""

SEGMENT_S = 0.3
"""Length of each open-loop segment (s)."""

SUBSTEPS = 2
"""Integration steps a period in the segments' simulation (RK4, the plant's stick/slip events located). On the Stribeck
trapezoid: 10 (the corpus plant's) gives Fs 2.4724 N, vs 7.975 mm/s; 2, 2.4734 N and 7.972 mm/s (a tenth of their
standard deviations) in 60 % of the time; 1, 2.4747 N and 7.966 mm/s (a fifth)."""

MAX_ITERATIONS = 40
"""Levenberg-Marquardt iterations at most."""


NOISE_FACTOR = 1.5
"""The fit explains the recording when its residual's RMS is at most this many times the sensor's noise."""

SPREAD = "the fit's, s^2 (J'J)^-1 with the segments' states profiled out (white sensor noise)"
"""Where its standard deviations come from, as the report says it."""

LEVEL_Z = 2.0
"""An effect's level the fit explains the recording with must be at least this many standard deviations above zero to be physics."""

DQ_M = 1e-6
"""Finite-difference step of a segment's initial position (m)."""

DV_MPS = 1e-4
"""Finite-difference step of a segment's initial velocity (m/s)."""

Simulate = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(parameters, states) -> position (m)``: the model over every segment, each from its state ``(q0, qd0)`` (a row of
``states``), one segment after another (:func:`plant.closed_loop.simulate_segments`); raises
:class:`~ilic_cli.errors.IlicError` for parameters that give no plant."""


@dataclass
class SegmentFit:
    """The open-loop segments' fit (:func:`fit_segments`).

    Attributes
    ----------
    names : tuple of str
        The parameters fitted (the segments' states aside).
    values, cov : ndarray
        Their estimate, and its covariance (``s^2 (J'J)^-1``, the states profiled out).
    rms_m, noise_m : float
        RMS of the position residual, and the sensor's noise it is judged against (m).
    rms_start_m : float
        The residual's RMS at the starting estimate (m).
    segments, samples, iterations : int
        Segments and samples fitted, Levenberg-Marquardt iterations made.
    converged : bool
        An iteration lowered the squared error by less than ``k s^2`` (``k`` parameters, ``s^2`` the residual's
        variance: what a move of every parameter by one standard deviation would change it by), or none could lower it.
    """

    names: tuple[str, ...]
    values: np.ndarray
    cov: np.ndarray
    rms_m: float
    noise_m: float
    rms_start_m: float
    segments: int
    samples: int
    iterations: int
    converged: bool

    @property
    def consistent(self) -> bool:
        """The residual is the sensor's noise: RMS at most :data:`NOISE_FACTOR` times it."""
        return self.converged and self.rms_m <= NOISE_FACTOR * self.noise_m

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    def to_dict(self) -> dict[str, Any]:
        return {
            "parameters": {n: finite_or_none(float(v)) for n, v in zip(self.names, self.values, strict=True)},
            "std": {n: finite_or_none(float(s)) for n, s in zip(self.names, self.std, strict=True)},
            "residual_rms_um": finite_or_none(1e6 * self.rms_m),
            "residual_rms_start_um": finite_or_none(1e6 * self.rms_start_m),
            "sensor_noise_um": finite_or_none(1e6 * self.noise_m),
            "segments": self.segments,
            "samples": self.samples,
            "iterations": self.iterations,
            "converged": self.converged,
            "consistent": self.consistent,
        }


def segment_starts(n: int, length: int, edge: int) -> list[int]:
    """First samples of the whole segments of ``length`` samples between ``edge`` samples at either end of ``n``."""
    return list(range(edge, n - edge - length + 1, length))


def fit_segments(
    q_m: np.ndarray,
    x0: np.ndarray,
    simulate: Simulate,
    p0: np.ndarray,
    steps: np.ndarray,
    names: Sequence[str],
    noise_m: float,
    *,
    starts: Sequence[int],
    length: int,
    max_step: np.ndarray | None = None,
) -> SegmentFit:
    """Fit the parameters ``p`` and each segment's initial state to the measured position, by Levenberg-Marquardt.

    Parameters
    ----------
    q_m : ndarray
        Measured position (m).
    x0 : ndarray (n, 2)
        A first guess of the position and velocity at every sample (e.g. :func:`plant.replay.measured_state`).
    simulate : callable
        The model over the segments (:data:`Simulate`).
    p0, steps : ndarray
        Starting parameters, and their finite-difference steps.
    names : sequence of str
        The parameters' names.
    noise_m : float
        The sensor's position noise (m), that the residual is judged against.
    starts, length : sequence of int, int
        The segments (:func:`segment_starts`).
    max_step : ndarray, optional
        Largest change of each parameter in one iteration (``inf``: unbounded).
    """
    q_m = np.asarray(q_m, dtype=np.float64)
    ns, ng = len(starts), len(p0)
    y = np.concatenate([q_m[i : i + length] for i in starts])
    states = np.array([x0[i] for i in starts], dtype=np.float64)
    bound = np.full(ng, np.inf) if max_step is None else np.asarray(max_step, dtype=np.float64)

    def sse(p: np.ndarray, xs: np.ndarray) -> float:
        try:
            r = simulate(p, xs) - y
        except IlicError:
            return np.inf
        return float(r @ r)

    def jacobian(p: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The residual and its sensitivities (forward differences): the parameters', then each segment's ``q0, qd0``."""
        jobs: list[Callable[[], np.ndarray]] = [lambda: simulate(p, xs)]

        def probe_parameter(k: int) -> np.ndarray:
            return simulate(p + steps[k] * np.eye(ng)[k], xs)

        def probe_state(c: int, d: float) -> np.ndarray:
            return simulate(p, xs + d * np.eye(2)[c])

        jobs += [functools.partial(probe_parameter, k) for k in range(ng)]
        jobs += [functools.partial(probe_state, c, d) for c, d in ((0, DQ_M), (1, DV_MPS))]
        out = ordered_map(lambda job: job(), jobs)
        base = out[0]
        J = np.zeros((len(y), ng + 2 * ns))
        for k in range(ng):
            J[:, k] = (out[1 + k] - base) / steps[k]
        for c, d in ((0, DQ_M), (1, DV_MPS)):
            col = (out[1 + ng + c] - base) / d
            for j in range(ns):
                J[j * length : (j + 1) * length, ng + 2 * j + c] = col[j * length : (j + 1) * length]
        return base - y, J

    dof = max(len(y) - ng - 2 * ns, 1)
    p, xs = np.asarray(p0, dtype=np.float64).copy(), states
    lam, converged, it = 1e-3, False, 0
    r, J = jacobian(p, xs)
    e = e0 = float(r @ r)
    while it < MAX_ITERATIONS and not converged:
        it += 1
        scale = np.linalg.norm(J, axis=0)
        scale[scale == 0] = 1.0
        Js = J / scale
        A, g = Js.T @ Js, Js.T @ r
        D = np.diag(np.where(np.diag(A) > 0, np.diag(A), 1.0))  # a parameter the position does not see stays where it is
        while True:
            d = -np.linalg.solve(A + lam * D, g) / scale
            d[:ng] = np.clip(d[:ng], -bound, bound)
            p1, x1 = p + d[:ng], xs + d[ng:].reshape(ns, 2)
            e1 = sse(p1, x1)
            if e1 < e:
                converged = e - e1 < ng * e / dof
                p, xs, e, lam = p1, x1, e1, max(lam / 10, 1e-9)
                break
            lam *= 4
            if lam > 1e8:  # no step lowers the error: at its least
                converged = True
                break
        if not converged:
            r, J = jacobian(p, xs)
    cov = (e / dof) * np.linalg.pinv(J.T @ J)[:ng, :ng]
    return SegmentFit(tuple(names), p, cov, float(np.sqrt(e / len(y))), float(noise_m), float(np.sqrt(e0 / len(y))), ns, len(y), it, converged)
