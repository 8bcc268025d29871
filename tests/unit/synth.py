"""Noise-free synthetic drive logs with a known answer, for the unit tests of the numerics."""

from __future__ import annotations

import numpy as np

FS = 1000.0
"""Sampling frequency of the synthetic logs (Hz), as the EMPS recordings."""


def motion(n: int = 10_000, fs: float = FS) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A smooth back-and-forth motion that starts and ends at rest, with its exact derivatives.

    ``q = 0.1 sin^3(w t) + 0.04 sin^3(2 w t)``, ``w = pi`` rad/s: velocity and
    acceleration vanish at every multiple of 1 s, so a record of whole
    seconds has none of the edge errors of the one-sided differences (as a
    real run that starts and ends at standstill).

    Parameters
    ----------
    n : int
        Number of samples (a multiple of ``fs`` for a record of whole seconds).
    fs : float
        Sampling frequency (Hz).

    Returns
    -------
    t, q, qd, qdd : ndarray
        Time (s), position (m), velocity (m/s), acceleration (m/s^2).
    """
    t = np.arange(n) / fs
    q = np.zeros(n)
    qd = np.zeros(n)
    qdd = np.zeros(n)
    for a, w in ((0.1, np.pi), (0.04, 2 * np.pi)):
        s, c = np.sin(w * t), np.cos(w * t)
        q += a * s**3
        qd += 3 * a * w * s**2 * c
        qdd += 3 * a * w**2 * (2 * s * c**2 - s**3)
    return t, q, qd, qdd


def rigid_force(qd: np.ndarray, qdd: np.ndarray, M: float = 95.0, Fv: float = 200.0, Fc: float = 20.0, offset: float = -3.0) -> np.ndarray:
    """``M*qdd + Fv*qd + Fc*sign(qd) + offset`` (N)."""
    return M * qdd + Fv * qd + Fc * np.sign(qd) + offset


def asymmetric_force(qd: np.ndarray, qdd: np.ndarray, M: float, Fv_pos: float, Fc_pos: float, Fv_neg: float, Fc_neg: float) -> np.ndarray:
    """The benchmark's asymmetric model: ``Fv_pos, Fc_pos`` for ``qd > 0``, ``Fv_neg, Fc_neg`` for ``qd < 0``.

    The regressor's ``Fc_neg`` column is ``sign(qd)`` on the negative side, so
    the force there is ``Fv_neg*qd - Fc_neg``.
    """
    pos = qd > 0
    return M * qdd + np.where(pos, Fv_pos * qd + Fc_pos, Fv_neg * qd - Fc_neg)
