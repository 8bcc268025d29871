"""The plant's stateful effects as blocks: a state and a step, outside the linear-in-parameters force.

A block holds what an effect remembers between samples (:class:`FlexibleLoad`: the load's position and velocity;
:class:`CurrentLoop`: the applied force) and advances it by one step; :func:`shifted` is the ``delay``'s pure time
shift. The vectorised inverse dynamics (:func:`plant.dynamics.force_model`) runs them over a motion; the compiled
loop (:mod:`plant.kernel`) has their compiled forms (the load in its state ``x2, x3``, the current loop in
``_current_loop_substeps``, the drive lag as the command of earlier periods).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FLEX_SUBSTEPS = 20
"""Semi-implicit sub-steps of the load per sample of :meth:`FlexibleLoad.step` (its dynamics are linear and fast)."""


@dataclass
class FlexibleLoad:
    """The load behind the spring-damper coupling of ``flexibility``: ``state = (q_load, v_load)``.

    :meth:`step` gives the coupling force at the start of a sample and advances the load while the motor follows
    ``q, qd`` linearly over the sample.
    """

    stiffness: float
    damping: float
    q_load: float
    v_load: float

    @property
    def state(self) -> tuple[float, float]:
        return self.q_load, self.v_load

    def force(self, q: float, qd: float) -> float:
        """Coupling force on the load when the motor is at ``q, qd``."""
        return self.stiffness * (q - self.q_load) + self.damping * (qd - self.v_load)

    def step(self, q0: float, qd0: float, q1: float, qd1: float, h: float, m_load: float) -> None:
        """Advance the load over ``h`` with the motor moving from ``(q0, qd0)`` to ``(q1, qd1)`` (semi-implicit sub-steps)."""
        k, c = self.stiffness, self.damping
        ql, vl = self.q_load, self.v_load
        hs = h / FLEX_SUBSTEPS
        for j in range(FLEX_SUBSTEPS):
            a = j / FLEX_SUBSTEPS
            qm = q0 + a * (q1 - q0)
            vm = qd0 + a * (qd1 - qd0)
            vl += hs * (k * (qm - ql) + c * (vm - vl)) / m_load
            ql += hs * vl
        self.q_load, self.v_load = ql, vl


def load_force(stiffness: float, damping: float, q: np.ndarray, qd: np.ndarray, t: np.ndarray, m_load: np.ndarray) -> np.ndarray:
    """Coupling force on the load when the motor follows ``q, qd`` (load at rest relative to the motor at ``t[0]``)."""
    n = len(q)
    out = np.empty(n)
    if n == 0:
        return out
    load = FlexibleLoad(stiffness, damping, float(q[0]), float(qd[0]))
    for i in range(n):
        out[i] = load.force(q[i], qd[i])
        if i + 1 < n:
            load.step(q[i], qd[i], q[i + 1], qd[i + 1], float(t[i + 1] - t[i]), float(m_load[i]))
    return out


@dataclass
class CurrentLoop:
    """The drive's current loop (``current_loop``): the applied force follows the command as a first-order lag, ``state = y``.

    The compiled loop's ``_current_loop_substeps`` is this step over each substep.
    """

    bandwidth_hz: float
    y: float = math.nan

    @property
    def state(self) -> float:
        return self.y

    def step(self, command: float, h: float) -> float:
        """Mean applied force over a step of ``h`` under a held ``command``; the state advances exactly."""
        if math.isnan(self.y):
            self.y = command
        tau_i = 1.0 / (2.0 * math.pi * self.bandwidth_hz)
        e = math.exp(-h / tau_i)
        mean = command + (self.y - command) * (tau_i / h * (1.0 - e))
        self.y = command + (self.y - command) * e
        return mean


def shifted(tau: np.ndarray, t: np.ndarray, delay: float) -> np.ndarray:
    """``delay``: the force ``delay`` seconds earlier (later for a negative delay; linear interpolation, the end values held)."""
    return tau if delay == 0 else np.interp(t - delay, t, tau)
