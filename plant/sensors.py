"""Force and position sensors of the closed loop: the held force as logged, delayed, with noise; the random disturbance force."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ilic_cli.effects import EffectParams
from ilic_cli.errors import ParameterError
from ilic_cli.jit import njit
from plant.dynamics import measurement_lag_s


def held_signal(u: np.ndarray, T: float, times: np.ndarray, width: float) -> np.ndarray:
    """Sample the zero-order-held force ``u`` (``u[k]`` on ``[kT, (k+1)T)``, 0 before 0, last value after).

    ``width == 0``: the value at ``times`` (right-continuous); otherwise the mean
    over ``[times - width/2, times + width/2]`` (``0 < width <= T``: at most two
    held values, weighted by their share of the interval; local, so a sample's
    value does not depend on how much of the record is passed).
    """
    u = np.asarray(u, dtype=np.float64)
    n = len(u)

    def value(i: np.ndarray) -> np.ndarray:
        return np.where(i >= 0, u[np.clip(i, 0, n - 1)], 0.0)

    if width <= 0:
        return value(np.floor(times / T + 1e-9).astype(np.int64))
    if width > T * (1 + 1e-12):
        raise ValueError("sensor width above one period")
    lo = times - 0.5 * width
    i = np.floor(lo / T + 1e-9).astype(np.int64)
    edge = (i + 1) * T
    first = np.clip(edge - lo, 0.0, width)
    return (first * value(i) + (width - first) * value(i + 1)) / width


TAU_SENSORS = ("centred", "command")
"""How the logged force samples the held drive force: ``centred`` = mean over the
sample interval centred on ``t_k`` (an integrating sensor; removes the half-period
misalignment of a zero-order hold against the reference), ``command`` = the value
applied from ``t_k`` (``gtau*vir``, the benchmark's definition)."""


@njit(cache=True)
def _sensed(u, T, start, n, delay, width, noise, out):
    """:func:`held_signal` of ``u`` at ``k*T - delay`` for ``start <= k < n``, plus ``noise[k]``, into ``out``.

    The same operations, in the same order, as the vectorised form (same values), without its temporaries.
    """
    m = len(u)
    for k in range(start, n):
        tm = k * T - delay
        if width <= 0.0:
            i = math.floor(tm / T + 1e-9)
            v = 0.0 if i < 0 else u[min(i, m - 1)]
        else:
            lo = tm - 0.5 * width
            i = math.floor(lo / T + 1e-9)
            first = max((i + 1) * T - lo, 0.0)
            if first > width:
                first = width
            a = 0.0 if i < 0 else u[min(i, m - 1)]
            b = 0.0 if i + 1 < 0 else u[min(i + 1, m - 1)]
            v = (first * a + (width - first) * b) / width
        out[k - start] = v + noise[k]


def measured_force(u: np.ndarray, T: float, n: int, effects: Mapping[str, EffectParams], sensor: str, noise_tau: np.ndarray, start: int = 0) -> np.ndarray:
    """The logged force of samples ``start .. n-1``: held force seen by the sensor, delayed, plus noise."""
    delay = measurement_lag_s(effects)
    width = T if sensor == "centred" else 0.0
    u = np.ascontiguousarray(u, dtype=np.float64)
    noise = np.ascontiguousarray(noise_tau, dtype=np.float64)
    if len(u) == 0 or len(noise) < n:  # degenerate input: the reference form (its errors)
        times = np.arange(start, n) * T - delay
        return held_signal(u, T, times, width) + noise_tau[start:n]
    out = np.empty(max(n - start, 0))
    _sensed(u, float(T), int(start), int(n), float(delay), float(width), noise, out)
    return out


def draw_noise(n: int, seed: int, effects: Mapping[str, EffectParams]) -> tuple[np.ndarray, np.ndarray]:
    """Force and position noise, drawn up front from PCG64(seed): force first, then position."""
    e = effects.get("noise")
    tau_std = e["tau_std"] if e is not None else 0.0
    q_std = e["q_std"] if e is not None else 0.0
    if tau_std == 0.0 and q_std == 0.0:  # no noise: nothing to draw
        return np.zeros(n), np.zeros(n)
    rng = np.random.Generator(np.random.PCG64(seed))
    n_tau = rng.standard_normal(n)
    if q_std == 0.0:
        return n_tau * tau_std, np.zeros(n)
    n_q = rng.standard_normal(n)
    return n_tau * tau_std, n_q * q_std


DISTURBANCE_STREAM = 0xD157
"""Second word of the disturbance's PCG64 seed ``[seed, DISTURBANCE_STREAM]``: a stream of its own, so adding
the disturbance leaves the force and position noise of the same seed unchanged."""


def draw_disturbance(n: int, seed: int, effects: Mapping[str, EffectParams], fs_hz: float) -> np.ndarray:
    """The unmodelled force on the axis (N) at each of ``n`` control periods (``disturbance`` effect, else zeros).

    White noise from PCG64(``[seed, DISTURBANCE_STREAM]``) through a second-order
    Butterworth low-pass of corner ``bandwidth_hz``, started in steady state (a
    burn-in of ten corner periods is dropped) and scaled by the filter's noise
    gain, so that its stationary standard deviation is ``std``.

    Parameters
    ----------
    n : int
        Samples (one per control period, held over the period).
    seed : int
        The run's seed.
    effects : mapping
        The run's effects.
    fs_hz : float
        Control rate; ``bandwidth_hz`` must be below ``fs_hz / 2``.
    """
    e = effects.get("disturbance")
    if e is None or e["std"] == 0.0:
        return np.zeros(n)
    bw = e["bandwidth_hz"]
    if not bw < 0.5 * fs_hz:
        raise ParameterError("disturbance.bandwidth_hz", bw, f"below the Nyquist frequency ({0.5 * fs_hz:g} Hz)")
    from scipy.signal import butter, sosfilt  # deferred: scipy.signal only for runs with a disturbance

    sos = butter(2, bw, fs=fs_hz, output="sos")
    burn = int(math.ceil(10.0 * fs_hz / bw))
    impulse = np.zeros(burn * 10)
    impulse[0] = 1.0
    gain = float(np.sqrt(np.sum(sosfilt(sos, impulse) ** 2)))
    rng = np.random.Generator(np.random.PCG64([seed, DISTURBANCE_STREAM]))
    out: np.ndarray = sosfilt(sos, rng.standard_normal(n + burn))[burn:]
    return out * (e["std"] / gain)
