"""Data-driven search grids of the effects' nonlinear parameters, and the flexible load's response."""

from __future__ import annotations

import math

import numpy as np

from ilic_cli.filtering import ROWS_BAND_HZ, bilinear_lfilter, rows_band_hz
from ilic_cli.regressor import Kinematics


def top_speed(kin: Kinematics) -> float:
    """The log's top speed (:func:`speed_scale` of its velocity), the scale of the speed grids."""
    return speed_scale(kin.qd)


def speed_scale(qd: np.ndarray) -> float:
    """The top speed of the velocity ``qd``: the 99.5th percentile of ``|qd|`` (1 when the axis does not move)."""
    v = float(np.percentile(np.abs(qd), 99.5))
    return v if v > 0 else 1.0


def smoothing_speeds(top: float) -> np.ndarray:
    """Smoothing speeds ``vc`` of a Coulomb law ``tanh(qd / vc)`` searched: 32 log-spaced from 0.2 % to 20 % of the top speed ``top``
    (:func:`top_speed`), the diagnosis's friction law and ``identify``'s friction shape alike."""
    return np.geomspace(0.002 * top, 0.2 * top, 32)


SMOOTHING_PROBES = slice(4, None, 8)
"""The points of :func:`smoothing_speeds` tried first where nothing proposes a speed (the 5th, 13th, 21st and 29th: 0.36 %, 1.1 %,
3.6 % and 12 % of the top speed, a factor 3.3 apart). One probe at the grid's middle (1.4 %) missed a chirp's law at 2.5 mm/s on
the 12 kg axis with a Stribeck friction beside it: at 5.8 mm/s the replay's position error rose 1.23 times, at 1.4 mm/s it fell
to 0.30 of stick/slip's."""


def stribeck_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    """Stribeck speeds ``vs`` searched: 32 log-spaced from 1 % to 40 % of the log's top speed (99.5th percentile)."""
    # from 1 % (below: standstill, left out of the fit) to 40 % of the top speed
    vmax = top_speed(kin)
    return np.geomspace(0.01 * vmax, 0.4 * vmax, 32)


def ripple_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    """Spatial periods of a position ripple searched: from what the IDIM band sees at the median moving speed to the stroke.

    The longest is one cycle over the range the log visits: a period the range shows whole, its sine and cosine
    distinct from the offset and a spring's line. A longer period shows less than a cycle, a bend that gravity or a
    spring makes too; an estimate there is on the grid's edge and said, not guessed. (The grid ended at half the
    stroke: the robot corpus's chirps visit 1.06 to 1.47 periods of their ripple, L = 0.68 to 0.94 of the stroke, and
    were all "at the edge", though the ripple at its true period lowered the rigid fit's RSS by 17 to 93 %.)
    """
    # spatial periods from what the IDIM bandwidth (40 Hz after decimation) can
    # see at the median moving speed up to the stroke, spaced so that the
    # phase over the stroke moves by less than a tenth of a cycle per step
    q = kin.q if kin.q is not None else np.cumsum(kin.qd) / fs_hz
    stroke = float(np.ptp(q)) or 1.0
    moving = np.abs(kin.qd) > 0.05 * top_speed(kin)
    v_typ = float(np.median(np.abs(kin.qd[moving]))) if moving.any() else top_speed(kin)
    p_min = max(v_typ / 40.0, stroke / 2000.0)
    p_max = stroke
    if p_max <= p_min:
        return np.array([p_max])
    # d(stroke/P) = 0.1  ->  P_{k+1} = P_k / (1 - 0.1 P_k / stroke)
    out = [p_min]
    while out[-1] < p_max:
        out.append(out[-1] / max(1.0 - 0.1 * out[-1] / stroke, 0.5))
    return np.array(out)


def change_time_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    """Times of a payload change searched: 200 evenly over the log, 5 % of its length kept clear at each end."""
    t = kin.t if kin.t is not None else np.arange(len(kin.qd)) / fs_hz
    t0, t1 = float(t[0]), float(t[-1])
    margin = 0.05 * (t1 - t0)
    return np.linspace(t0 + margin, t1 - margin, 200)


def delay_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    """Drive lags searched: -25 ms to +25 ms in steps of half a sample (refined afterwards)."""
    # +-25 ms in steps of half a sample (refined afterwards)
    step = 0.5 / fs_hz
    return np.arange(-0.025, 0.025 + step / 2, step)


RESONANCE_OF_FS = 0.1
"""The highest resonance searched is at most this share of the log's rate: below it the bilinear discretisation of the
mode (:func:`flexible_acceleration`) keeps its frequency within 3 %, and the derivatives of the position lose less than
1 % of its acceleration (five points below 1 kHz: :func:`ilic_cli.filtering.rows_stencil`)."""


def resonance_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    """Resonance frequencies searched: 40 log-spaced from 2 Hz to the band a full-rate log's rows keep
    (:data:`ilic_cli.filtering.ROWS_BAND_HZ`, 40 Hz), at most :data:`RESONANCE_OF_FS` of the log's rate.

    The same modes at every rate that sees them: not bounded by the band of the log's own rows
    (:func:`ilic_cli.filtering.rows_band_hz`, 33 Hz at 500 Hz), which then do not reach the grid's top, and the resonance is
    searched at the log's rate (:func:`resonance_at_log_rate`), where a 500 Hz log sees a 36 Hz mode; below the mode the rows
    still see its mass (``M_load (H - 1) qdd ~ -M_load qdd'' / w^2``) and fit it. From 1 kHz up the rows keep the grid's
    range and the search is on them, as before.
    """
    return np.geomspace(2.0, min(ROWS_BAND_HZ, RESONANCE_OF_FS * fs_hz), 40)


def resonance_at_log_rate(kin: Kinematics, fs_hz: float) -> bool:
    """Whether the resonance is searched at the log's rate: the rows' band (:func:`ilic_cli.filtering.rows_band_hz`) ends below
    the top of :func:`resonance_grid` (below 1 kHz)."""
    return rows_band_hz(fs_hz) < float(resonance_grid(kin, fs_hz)[-1]) * (1.0 - 1e-9)


FLEX_DAMPING = 0.05
"""Damping ratio of the flexible mode while its frequency is searched (then refined)."""


def flexible_acceleration(qdd: np.ndarray, f_hz: float, fs_hz: float, zeta: float = FLEX_DAMPING) -> np.ndarray:
    """Acceleration of a load coupled to the measured side by a spring-damper.

    ``qdd_L = H(s) qdd`` with ``H = (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2)``,
    ``w = 2 pi f_hz``, discretised by the bilinear transform and applied
    forward only (causal, like the physics).
    """
    w = 2.0 * math.pi * f_hz
    return bilinear_lfilter([2.0 * zeta * w, w * w], [1.0, 2.0 * zeta * w, w * w], fs_hz, qdd)
