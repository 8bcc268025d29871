"""The log's measurement noise: white position noise and the encoder's quantisation, estimated from the recorded position.

In closed loop the controller acts on the measured position, so its noise
moves the axis: at low speed and at rest it dithers the friction (stick-slip
creep at a dwell, where the force is the controller's answer to the noise).
A noise-free replay of such a log cannot reproduce that force, whatever the
model (clean CTC trapezoid, seed 1: held-out-band force error 1.91 % noise-free,
0.90 % with an independent realisation of the estimated noise). The replay
that decides (:func:`ilic_cli.diagnosis.decide.replay_decide`) therefore runs
with the noise estimated here (:func:`recorded_sensor`), corrected for what the
loop adds to it (:func:`loop_corrected`); the Monte-Carlo null
(:mod:`ilic_cli.diagnosis.null`) builds its noise model on it the same way.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ilic_cli.idim_ls import LSSettings, filtered_position
from ilic_cli.runlog import RunLog

GRID_TOLERANCE = 0.01
"""A position lies on a grid of step ``d`` when every ``(q - q[0]) / d`` is within this many steps of an integer."""


def grid_step(q: np.ndarray) -> float | None:
    """The step of the grid ``q`` lies on (an encoder's count), else ``None``.

    Rule: ``d`` is the smallest difference between two distinct values of
    ``q``; ``q`` is on the grid when every ``(q - q[0]) / d`` is within
    :data:`GRID_TOLERANCE` of an integer (DATA_EMPS.mat: 5e-8 m, within 0.003
    steps; the corpus logs: their 2e-7 m, within 5e-5).

    Parameters
    ----------
    q : ndarray
        Measured position.
    """
    q = np.asarray(q, dtype=np.float64)
    values = np.unique(q)
    if len(values) < 3:
        return None
    d = float(np.min(np.diff(values)))
    if not d > 0:
        return None
    r = (q - q[0]) / d
    return d if float(np.max(np.abs(r - np.round(r)))) <= GRID_TOLERANCE else None


def highpass_gain(fs_hz: float, ls: LSSettings, n: int = 4001) -> float:
    """Variance gain of ``x - lowpass(x)`` for white ``x`` (the zero-phase low-pass of the IDIM position filter).

    Exact for the linear operator away from the record's edges: the energy of
    its response to a unit impulse in the middle of a record of ``n`` samples.

    Parameters
    ----------
    fs_hz : float
        Sample rate.
    ls : LSSettings
        The IDIM position filter (cut-off, order, MATLAB padding).
    n : int
        Length of the impulse record (odd).
    """
    x = np.zeros(n)
    x[n // 2] = 1.0
    h = x - filtered_position(x, fs_hz, ls)
    return float(h @ h)


def position_noise(q: np.ndarray, fs_hz: float, ls: LSSettings) -> tuple[float, float | None]:
    """White position-noise std and quantisation step of a measured position.

    ``r = q - lowpass(q)`` (the IDIM position filter, zero phase) holds the
    noise above the cut-off; the motion of a drive below it is left out. With
    the variance gain ``g`` of that high-pass (:func:`highpass_gain`) and a grid
    step ``d`` (:func:`grid_step`, quantisation error ``d^2/12``):
    ``std^2 = var(r)/g - d^2/12`` (at least 0). The first and last ``ls.trim``
    samples (filter edges) are left out.

    Parameters
    ----------
    q : ndarray
        Measured position.
    fs_hz : float
        Sample rate.
    ls : LSSettings
        The IDIM position filter.

    Returns
    -------
    (float, float or None)
        Noise std (m) and grid step (m, ``None`` off a grid).
    """
    q = np.asarray(q, dtype=np.float64)
    r = q - filtered_position(q, fs_hz, ls)
    edge = max(ls.trim, 1)
    r = r[edge:-edge]
    var = float(np.mean((r - r.mean()) ** 2)) / highpass_gain(fs_hz, ls)
    d = grid_step(q)
    var -= quantization_var(d)
    return math.sqrt(max(var, 0.0)), d


def quantization_var(resolution: float | None) -> float:
    """Variance of the rounding error on a grid of step ``resolution`` (m^2): ``d^2/12``; 0 off a grid (``None``)."""
    return 0.0 if resolution is None else resolution * resolution / 12.0


def measurement_std(q_std: float, resolution: float | None) -> float:
    """The whole error of a measured position (m): white noise ``q_std`` and the rounding of a grid of step ``resolution``."""
    return math.sqrt(q_std * q_std + quantization_var(resolution))


def sensor_effects(q_std: float, resolution: float | None) -> dict[str, dict[str, float]]:
    """The plant's sensor effects (:mod:`plant.sensors`: ``noise``, ``quantization``) of a noise estimate (those that are not zero).

    Parameters
    ----------
    q_std : float
        White position noise (m).
    resolution : float or None
        Quantisation step (m), ``None`` off a grid.
    """
    out: dict[str, dict[str, float]] = {}
    if q_std > 0:
        out["noise"] = {"q_std": q_std, "tau_std": 0.0}
    if resolution is not None:
        out["quantization"] = {"resolution": resolution}
    return out


Replay = Callable[[dict[str, Any]], "RunLog | None"]
"""A replay of a model on a recording with the given sensor effects (``None`` when it fails)."""


def loop_corrected(q_std: float, resolution: float | None, fs_hz: float, ls: LSSettings, replay_with: Replay) -> float:
    """``q_std`` corrected once for the loop: so that :func:`position_noise` of a replay that carries it gives ``q_std``.

    In closed loop the controller feeds the noise back into the motion above the
    IDIM cut-off, so the estimate on a recording is high by what the loop adds:
    9-10 % on CTC corpus logs (within 2 % after the correction), 1 % on our PD
    logs of the EMPS reference, 11 % on DATA_EMPS (21.2 -> 19.1 nm). The
    correction is ``q_std**2 / seen``, ``seen`` the estimate on
    ``replay_with(sensor_effects(q_std, resolution))``; ``q_std`` is unchanged
    when it is 0, the replay fails or it shows no noise.
    """
    if q_std <= 0:
        return q_std
    sim = replay_with(sensor_effects(q_std, resolution))
    if sim is None:
        return q_std
    seen, _ = position_noise(np.asarray(sim["q"]), fs_hz, ls)
    return q_std * q_std / seen if seen > 0 else q_std


def recorded_sensor(log: RunLog, ls: LSSettings, replay_with: Replay | None = None) -> dict[str, Any]:
    """:func:`sensor_effects` of :func:`position_noise` on ``log``'s measured position.

    Parameters
    ----------
    log : RunLog
        The recording (``q``).
    ls : LSSettings
        The IDIM position filter.
    replay_with : callable, optional
        A replay of the model on ``log`` with given sensor effects: the noise is then :func:`loop_corrected`.
    """
    q_std, resolution = position_noise(np.asarray(log["q"]), log.fs_hz, ls)
    if replay_with is not None:
        q_std = loop_corrected(q_std, resolution, log.fs_hz, ls, replay_with)
    return sensor_effects(q_std, resolution)
