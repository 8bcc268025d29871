"""Catalogue of the physical effects a rigid drive model leaves out.

Each :class:`Effect` has a stable id (the same as the plant's effect ids), a
one-sentence physical explanation, the form it adds to the inverse dynamic
model, and the signature it leaves in the force residual. Effects that are
linear in their parameters add regressor columns
(:class:`ilic_cli.regressor.Column`) to the least-squares problem, which is
solved unchanged; nonlinear ones have one nonlinear parameter (a
:class:`Scan`: Stribeck velocity, spatial period, change time, delay,
resonance frequency) that is searched on a grid and refined by a 1-D
optimisation, the rest being fitted by least squares.

``delay`` adds no column: it shifts the recorded force against the
kinematics (``kind="shift"``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any
from dataclasses import dataclass

import numpy as np

from ilic_cli.regressor import Column, Kinematics

#: (name, unit, description) of one linear parameter an effect adds
ParamSpec = tuple[str, str, str]


@dataclass(frozen=True)
class Scan:
    """The nonlinear parameter of an effect and how to search it.

    Attributes
    ----------
    name, unit : str
        Parameter name (in the plant's vocabulary) and unit.
    grid : callable
        ``(kin, fs_hz) -> ndarray`` candidate values, sorted, from the data's
        own ranges (velocity, stroke, duration).
    log : bool
        Refine on a logarithmic scale (positive, scale-free parameters).
    secondary : tuple, optional
        A second nonlinear parameter refined after the first (see below).
    """

    name: str
    unit: str
    grid: Callable[[Kinematics, float], np.ndarray]
    log: bool = True
    secondary: tuple[str, str, float, float, float] | None = None
    """Optional second nonlinear parameter ``(name, unit, low, high, default)``,
    refined by a 1-D search once the first is found (the value is then the
    pair ``(first, second)``)."""


@dataclass(frozen=True)
class Effect:
    """One physical effect of the catalogue.

    Attributes
    ----------
    id : str
        Stable identifier (the plant's effect id).
    title : str
        Name in plain words.
    explanation : str
        One sentence of physics.
    form : str
        What it adds to the inverse dynamic model.
    signature : str
        How it shows in the force residual.
    params : tuple of (name, unit, description)
        Linear parameters (one regressor column each).
    build : callable or None
        ``(kin, value, base_names) -> ndarray (n, len(params))``: the full-rate
        columns for the nonlinear value (``None`` when there is no scan).
    scan : Scan or None
        The nonlinear parameter, if any.
    kind : {"columns", "shift"}
        ``shift``: no column; the force is shifted in time by the scanned value.
    impossible : callable, optional
        ``(theta of its columns, value) -> reason or None``: estimates that
        cannot be this physics (a negative mass) reject the candidate.
    """

    id: str
    title: str
    explanation: str
    form: str
    signature: str
    params: tuple[ParamSpec, ...]
    build: Callable[[Kinematics, float | None], np.ndarray] | None
    scan: Scan | None = None
    kind: str = "columns"
    impossible: Callable[[np.ndarray, Any], str | None] | None = None

    @property
    def nonlinear(self) -> bool:
        return self.scan is not None

    def columns(self, value: float | None = None) -> tuple[Column, ...]:
        """The effect's regressor columns for a fixed nonlinear ``value``."""
        if self.build is None:
            return ()
        build = self.build
        return tuple(Column(name, unit, (lambda k, i=i: build(k, value)[:, i]), desc) for i, (name, unit, desc) in enumerate(self.params))

    def matrix(self, kin: Kinematics, value: float | None = None) -> np.ndarray:
        """Full-rate columns, shape ``(n, len(params))``."""
        if self.build is None:
            return np.zeros((len(kin.qd), 0))
        return np.asarray(self.build(kin, value), dtype=np.float64).reshape(len(kin.qd), -1)

    def to_dict(self) -> dict[str, object]:
        return {
            "id": self.id,
            "title": self.title,
            "explanation": self.explanation,
            "form": self.form,
            "signature": self.signature,
            "parameters": [{"name": n, "unit": u, "description": d} for n, u, d in self.params],
            "nonlinear": None if self.scan is None else {"name": self.scan.name, "unit": self.scan.unit},
        }


# -- data-driven grids ------------------------------------------------------

def _vmax(kin: Kinematics) -> float:
    v = float(np.percentile(np.abs(kin.qd), 99.5))
    return v if v > 0 else 1.0


def _stribeck_grid(kin: Kinematics, fs: float) -> np.ndarray:
    # from 1 % (below: standstill, left out of the fit) to 40 % of the top speed
    vmax = _vmax(kin)
    return np.geomspace(0.01 * vmax, 0.4 * vmax, 32)


def _ripple_grid(kin: Kinematics, fs: float) -> np.ndarray:
    # spatial periods from what the IDIM bandwidth (40 Hz after decimation) can
    # see at the median moving speed up to half the stroke, spaced so that the
    # phase over the stroke moves by less than a tenth of a cycle per step
    q = kin.q if kin.q is not None else np.cumsum(kin.qd) / fs
    stroke = float(np.ptp(q)) or 1.0
    moving = np.abs(kin.qd) > 0.05 * _vmax(kin)
    v_typ = float(np.median(np.abs(kin.qd[moving]))) if moving.any() else _vmax(kin)
    p_min = max(v_typ / 40.0, stroke / 2000.0)
    p_max = stroke / 2.0
    if p_max <= p_min:
        return np.array([p_max])
    # d(stroke/P) = 0.1  ->  P_{k+1} = P_k / (1 - 0.1 P_k / stroke)
    out = [p_min]
    while out[-1] < p_max:
        out.append(out[-1] / max(1.0 - 0.1 * out[-1] / stroke, 0.5))
    return np.array(out)


def _change_time_grid(kin: Kinematics, fs: float) -> np.ndarray:
    t = kin.t if kin.t is not None else np.arange(len(kin.qd)) / fs
    t0, t1 = float(t[0]), float(t[-1])
    margin = 0.05 * (t1 - t0)
    return np.linspace(t0 + margin, t1 - margin, 200)


def _delay_grid(kin: Kinematics, fs: float) -> np.ndarray:
    # +-25 ms in steps of half a sample (refined afterwards)
    step = 0.5 / fs
    return np.arange(-0.025, 0.025 + step / 2, step)


def _resonance_grid(kin: Kinematics, fs: float) -> np.ndarray:
    # what survives the IDIM low-pass: up to 0.8 of the decimated Nyquist (40 Hz at 1 kHz / 10)
    return np.geomspace(2.0, 0.08 * fs / 2 * 1.0, 40)


# -- columns ---------------------------------------------------------------

def _asymmetric(kin: Kinematics, value: float | None) -> np.ndarray:
    neg = (1.0 - kin.sgn) / 2.0
    return np.c_[kin.qd * neg]


def _stribeck(kin: Kinematics, vs: float | None) -> np.ndarray:
    assert vs is not None
    return np.c_[kin.sgn * np.exp(-((kin.qd / vs) ** 2))]


def _ripple(kin: Kinematics, period: float | None) -> np.ndarray:
    assert period is not None and kin.q is not None
    phase = 2.0 * np.pi * kin.q / period
    return np.c_[np.sin(phase), np.cos(phase)]


def _spring(kin: Kinematics, value: float | None) -> np.ndarray:
    assert kin.q is not None
    return np.c_[kin.q]


def _payload(kin: Kinematics, tc: float | None) -> np.ndarray:
    assert tc is not None and kin.t is not None
    return np.c_[kin.qdd * (kin.t >= tc)]


def _offset(kin: Kinematics, value: float | None) -> np.ndarray:
    return np.ones((len(kin.qd), 1))


FLEX_DAMPING = 0.05
"""Damping ratio of the flexible mode while its frequency is searched (then refined)."""


def flexible_acceleration(qdd: np.ndarray, f_hz: float, fs_hz: float, zeta: float = FLEX_DAMPING) -> np.ndarray:
    """Acceleration of a load coupled to the measured side by a spring-damper.

    ``qdd_L = H(s) qdd`` with ``H = (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2)``,
    ``w = 2 pi f_hz``, discretised by the bilinear transform and applied
    forward only (causal, like the physics).
    """
    from scipy import signal

    w = 2.0 * math.pi * f_hz
    b, a = signal.bilinear([2.0 * zeta * w, w * w], [1.0, 2.0 * zeta * w, w * w], fs=fs_hz)
    zi = signal.lfilter_zi(b, a) * qdd[0]
    out, _ = signal.lfilter(b, a, qdd, zi=zi)
    return out


def _flexibility_builder(fs_hz: float) -> Callable[[Kinematics, Any], np.ndarray]:
    def build(kin: Kinematics, value: Any) -> np.ndarray:
        assert value is not None
        f_hz, zeta = (value, FLEX_DAMPING) if np.isscalar(value) else value
        return np.c_[flexible_acceleration(kin.qdd, float(f_hz), fs_hz, float(zeta)) - kin.qdd]

    return build


def catalogue(fs_hz: float = 1000.0) -> dict[str, Effect]:
    """The effects, by id, for data sampled at ``fs_hz``."""
    effects = [
        Effect(
            "asymmetric_friction",
            "asymmetric friction",
            "Friction differs between the two directions of motion, e.g. from wear or fatigue of the screw on one side.",
            "extra viscous coefficient for negative velocity: dFv * qd * (1 - sign(qd))/2 (Coulomb asymmetry is the constant offset)",
            "residual proportional to velocity on one side of zero only; mean residual differs between positive and negative velocity bins",
            (("dFv_neg", "N/(m/s)", "extra viscous friction at negative velocity"),),
            _asymmetric,
        ),
        Effect(
            "stribeck",
            "Stribeck friction",
            "At low sliding speed the lubricant film breaks down and friction rises above its Coulomb level before it drops with speed.",
            "Fs * sign(qd) * exp(-(qd/vs)^2), vs searched",
            "residual with the sign of the velocity, concentrated in the low-speed bins and at velocity reversals",
            (("Fs", "N", "static friction in excess of Coulomb"),),
            _stribeck,
            Scan("vs", "m/s", _stribeck_grid),
        ),
        Effect(
            "position_ripple",
            "position-dependent force ripple",
            "Cogging of the motor and the screw pitch make the force needed to move vary periodically with position.",
            "A * sin(2 pi q / P) + B * cos(2 pi q / P), spatial period P searched",
            "residual periodic in position: a peak in the residual against position, at frequency velocity/P in time",
            (("ripple_sin", "N", "ripple, sine component"), ("ripple_cos", "N", "ripple, cosine component")),
            _ripple,
            Scan("L", "m", _ripple_grid),
        ),
        Effect(
            "spring",
            "spring force",
            "A cable chain or a gravity-like preload pulls the carriage towards one end with a force proportional to position.",
            "k * q (its rest position is absorbed by the offset)",
            "residual growing linearly with position, same sign in both directions of motion",
            (("k_spring", "N/m", "stiffness"),),
            _spring,
        ),
        Effect(
            "payload_change",
            "payload change",
            "A mass is added to (or removed from) the carriage during the run, changing the inertia from that time on.",
            "dM * qdd * [t >= tc], change time tc searched",
            "residual proportional to acceleration, after a given time only",
            (("dM", "kg", "mass added at the change time"),),
            _payload,
            Scan("t_change", "s", _change_time_grid, log=False),
        ),
        Effect(
            "offset",
            "force offset",
            "The drive's amplifier or current sensor adds a constant force, or Coulomb friction is not the same in both directions.",
            "constant offset",
            "constant mean residual in every bin",
            (("offset", "N", "constant force offset"),),
            _offset,
        ),
        Effect(
            "delay",
            "actuation delay",
            "The logged force and the force acting on the axis are not simultaneous: the measurement lags (d > 0) or the drive lags the command (d < 0).",
            "IDM(t) = tau_logged(t + d): the logged force is shifted by the delay d, searched",
            "residual proportional to the rate of change of the force; cross-correlation of force and model peaks at a non-zero lag",
            (),
            None,
            Scan("delay", "s", _delay_grid, log=False),
            kind="shift",
        ),
        Effect(
            "flexibility",
            "transmission flexibility",
            "The carriage is coupled to the motor through a compliant screw and belt, so part of the mass lags the measured motion near a resonance.",
            "M_load * (H(s) - 1) qdd with H the load's spring-damper response: resonance frequency f_res searched, then its damping ratio",
            "residual proportional to acceleration at high frequency: oscillations after acceleration steps and pulses; a spectral peak",
            (("M_load", "kg", "mass behind the flexibility"),),
            _flexibility_builder(fs_hz),
            Scan("f_res", "Hz", _resonance_grid, secondary=("damping_ratio", "", 0.005, 0.5, FLEX_DAMPING)),
            impossible=lambda th, v: None if th[0] > 0 else f"negative mass behind the flexibility ({th[0]:.3g} kg)",
        ),
    ]
    return {e.id: e for e in effects}


EFFECT_IDS: tuple[str, ...] = tuple(catalogue())
"""Stable ids of the catalogue, in the order they are tried."""


def applicable(effect: Effect, base_names: tuple[str, ...]) -> bool:
    """Whether ``effect`` adds something to a model with columns ``base_names``."""
    return not any(n in base_names for n, _, _ in effect.params)
