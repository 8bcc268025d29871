"""Rigid-body parameters, named physical effects and the force model of the axis.

The plant is a 1-DOF prismatic axis (the EMPS)::

    tau = M*qdd + Fv*qd + Fc*sign(qd) + offset            (paper eq. 29 + offset)

Every optional effect is a plain dataclass, off by default, JSON-able through
``to_dict``/``from_dict``, and known by an id used across the project (model
files, ``--effect ID:k=v,...``, log metadata ``meta["effects"]``):

======================= ==========================================================
id                      force added to the inverse dynamics (or what it changes)
======================= ==========================================================
``asymmetric_friction`` ``Fv_pos, Fc_pos`` for ``qd > 0`` and ``Fv_neg, Fc_neg`` for
                        ``qd < 0`` replace ``Fv, Fc`` (``Fc_neg`` is a magnitude)
``stribeck``            ``Fs*exp(-(qd/vs)**2)*sign(qd)``; static level ``Fc + Fs``
                        (``Fs < 0``, down to ``-Fc``: friction lower at low speed)
``position_ripple``     ``A*sin(2*pi*q/L + phase)``
``spring``              ``k*(q - q0)``
``payload_change``      mass ``dM`` added at ``t >= t_change``
``delay``               logged force = applied force ``delay`` seconds earlier;
                        ``delay < 0``: the drive lags, the applied force is the
                        logged command ``-delay`` seconds later
``flexibility``         load mass ``load_fraction*M`` behind a spring-damper
                        (``stiffness``, ``damping``); ``q`` is the motor side
``saturation``          applied force clipped to ``+-force_max``
``quantization``        measured ``q`` rounded to ``resolution`` (encoder)
``noise``               Gaussian noise of std ``tau_std`` on the logged force and
                        ``q_std`` on the measured position (seeded, drawn up front)
======================= ==========================================================

:func:`force_model` is the vectorised inverse dynamics with these effects (the
measurement effects ``quantization`` and ``noise`` and the actuator limit
``saturation`` are not part of it: they do not change the physics).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, ClassVar

import numpy as np

from ilic_cli.errors import SimulationError


# ---------------------------------------------------------------------------
# rigid parameters
# ---------------------------------------------------------------------------
@dataclass
class RigidParameters:
    """Rigid-body parameters of the axis (SI, load side).

    Attributes
    ----------
    M : float
        Total moving mass (kg).
    Fv : float
        Viscous friction (N/(m/s)).
    Fc : float
        Coulomb friction (N).
    offset : float
        Constant force offset (N).
    """

    M: float = 95.0
    Fv: float = 200.0
    Fc: float = 20.0
    offset: float = 0.0

    NAMES: ClassVar[tuple[str, ...]] = ("M", "Fv", "Fc", "offset")

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RigidParameters:
        return cls(**{k: float(v) for k, v in d.items() if k in cls.NAMES})

    def replace(self, **values: float) -> RigidParameters:
        d = self.to_dict()
        for k, v in values.items():
            if k not in self.NAMES:
                raise SimulationError("--param", f"unknown parameter '{k}' (rigid parameters: {', '.join(self.NAMES)})")
            d[k] = float(v)
        return RigidParameters(**d)


# ---------------------------------------------------------------------------
# effects
# ---------------------------------------------------------------------------
@dataclass
class Effect:
    """Base of the named effects: JSON round trip and validation."""

    ID: ClassVar[str] = ""
    POSITIVE: ClassVar[tuple[str, ...]] = ()
    NONNEGATIVE: ClassVar[tuple[str, ...]] = ()

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Effect:
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise SimulationError("--effect", f"effect '{cls.ID}' has no parameter {', '.join(repr(u) for u in unknown)} (parameters: {', '.join(sorted(names))})")
        try:
            obj = cls(**{k: float(v) for k, v in d.items()})
        except (TypeError, ValueError):
            raise SimulationError("--effect", f"effect '{cls.ID}': parameters must be numbers ({d})") from None
        obj.validate()
        return obj

    def validate(self) -> None:
        for name, value in asdict(self).items():
            if not math.isfinite(value):
                raise SimulationError("--effect", f"effect '{self.ID}': {name} must be finite")
        for name in self.POSITIVE:
            if not getattr(self, name) > 0:
                raise SimulationError("--effect", f"effect '{self.ID}': {name} must be > 0 (got {getattr(self, name)})")
        for name in self.NONNEGATIVE:
            if getattr(self, name) < 0:
                raise SimulationError("--effect", f"effect '{self.ID}': {name} must be >= 0 (got {getattr(self, name)})")


@dataclass
class AsymmetricFriction(Effect):
    """Direction-dependent friction: replaces ``Fv, Fc`` (benchmark asymmetric model).

    ``Fv_pos, Fc_pos`` act for ``qd > 0``; ``Fv_neg, Fc_neg`` for ``qd < 0``
    (force ``Fv_neg*qd - Fc_neg``). Defaults: the benchmark's asymmetric estimates.
    """

    ID: ClassVar[str] = "asymmetric_friction"
    NONNEGATIVE: ClassVar[tuple[str, ...]] = ("Fc_pos", "Fc_neg")
    Fv_pos: float = 166.7061
    Fv_neg: float = 240.4236
    Fc_pos: float = 20.1440
    Fc_neg: float = 20.6277


@dataclass
class Stribeck(Effect):
    """Stribeck friction: extra ``Fs*exp(-(qd/vs)^2)*sign(qd)``; static level ``Fc + Fs``.

    ``Fs < 0`` (friction lower at low speed than the Coulomb-viscous line; a
    shape correction that diagnosis can find) is allowed while the static
    level stays >= 0 (checked against ``Fc`` by :func:`plant_vector`).
    """

    ID: ClassVar[str] = "stribeck"
    POSITIVE: ClassVar[tuple[str, ...]] = ("vs",)
    Fs: float = 5.0
    vs: float = 0.01


@dataclass
class PositionRipple(Effect):
    """Position-periodic force ``A*sin(2*pi*q/L + phase)`` (cogging, screw pitch)."""

    ID: ClassVar[str] = "position_ripple"
    POSITIVE: ClassVar[tuple[str, ...]] = ("L",)
    A: float = 2.0
    L: float = 0.01
    phase: float = 0.0


@dataclass
class Spring(Effect):
    """Linear spring ``k*(q - q0)`` (cable chain, gravity compensation)."""

    ID: ClassVar[str] = "spring"
    k: float = 100.0
    q0: float = 0.1


@dataclass
class PayloadChange(Effect):
    """Mass ``dM`` (kg) added at time ``t_change`` (s) (paper section VI-G: 10 kg at 60 s)."""

    ID: ClassVar[str] = "payload_change"
    NONNEGATIVE: ClassVar[tuple[str, ...]] = ("t_change",)
    dM: float = 10.0
    t_change: float = 60.0


@dataclass
class Delay(Effect):
    """Delay (s) between the logged and the applied force.

    ``delay > 0``: the force measurement lags, the logged force is the applied
    force ``delay`` earlier. ``delay < 0``: the drive lags, the axis receives
    the logged (commanded) force ``-delay`` later. At most ``MAX_S`` either way.
    """

    ID: ClassVar[str] = "delay"
    MAX_S: ClassVar[float] = 1.0
    delay: float = 0.002

    def validate(self) -> None:
        super().validate()
        if abs(self.delay) > self.MAX_S:
            raise SimulationError("--effect", f"effect 'delay': |delay| must be <= {self.MAX_S} s (got {self.delay})")

    @property
    def measurement_s(self) -> float:
        """Lag of the force measurement (>= 0)."""
        return max(self.delay, 0.0)

    @property
    def drive_lag_s(self) -> float:
        """Lag of the applied force behind the logged command (>= 0)."""
        return max(-self.delay, 0.0)


@dataclass
class Flexibility(Effect):
    """Second mass behind a flexible transmission.

    The motor side (mass ``(1-load_fraction)*M``) receives the drive force and
    the friction; the load (``load_fraction*M``, plus any payload) is coupled
    by ``stiffness*(q - q_load) + damping*(qd - qd_load)``. ``q`` is measured
    on the motor side, as in the EMPS.
    """

    ID: ClassVar[str] = "flexibility"
    POSITIVE: ClassVar[tuple[str, ...]] = ("stiffness",)
    NONNEGATIVE: ClassVar[tuple[str, ...]] = ("damping",)
    stiffness: float = 2.0e6
    damping: float = 500.0
    load_fraction: float = 0.3

    def validate(self) -> None:
        super().validate()
        if not 0.0 < self.load_fraction < 1.0:
            raise SimulationError("--effect", f"effect 'flexibility': load_fraction must lie in (0, 1) (got {self.load_fraction})")


@dataclass
class Saturation(Effect):
    """Drive limit: the applied force is clipped to ``+-force_max`` (N)."""

    ID: ClassVar[str] = "saturation"
    POSITIVE: ClassVar[tuple[str, ...]] = ("force_max",)
    force_max: float = 350.0


@dataclass
class Quantization(Effect):
    """Encoder quantization of the measured position (m). EMPS: about 2e-7 m per count."""

    ID: ClassVar[str] = "quantization"
    POSITIVE: ClassVar[tuple[str, ...]] = ("resolution",)
    resolution: float = 2.0e-7


@dataclass
class Noise(Effect):
    """Gaussian measurement noise: ``tau_std`` (N) on the logged force, ``q_std`` (m) on ``q``."""

    ID: ClassVar[str] = "noise"
    NONNEGATIVE: ClassVar[tuple[str, ...]] = ("tau_std", "q_std")
    tau_std: float = 0.0
    q_std: float = 0.0


EFFECTS: dict[str, type[Effect]] = {
    cls.ID: cls
    for cls in (AsymmetricFriction, Stribeck, PositionRipple, Spring, PayloadChange, Delay, Flexibility, Saturation, Quantization, Noise)
}
"""Effect id -> dataclass."""

Effects = dict[str, Effect]


def make_effects(spec: dict[str, Any] | None) -> Effects:
    """Build effects from ``{id: {param: value}}`` (model files, metadata).

    An effect whose value is ``None``/``False`` is left out; ``True`` or ``{}`` uses
    the documented defaults. Unknown ids raise :class:`SimulationError`.
    """
    out: Effects = {}
    for eid, params in (spec or {}).items():
        if isinstance(params, Effect):
            out[eid] = params
            continue
        if eid not in EFFECTS:
            raise SimulationError("--effect", f"unknown effect '{eid}' (known: {', '.join(EFFECTS)})")
        if params is None or params is False:
            continue
        if params is True:
            params = {}
        if not isinstance(params, dict):
            raise SimulationError("--effect", f"effect '{eid}': parameters must be an object")
        out[eid] = EFFECTS[eid].from_dict(params)
    return out


def effects_to_dict(effects: Effects) -> dict[str, dict[str, float]]:
    """JSON form ``{id: {param: value}}`` in a stable order."""
    return {eid: effects[eid].to_dict() for eid in EFFECTS if eid in effects}


def parse_effect_option(text: str) -> tuple[str, dict[str, float]]:
    """Parse ``ID`` or ``ID:k=v,k=v`` (the ``--effect`` option)."""
    eid, _, rest = text.partition(":")
    eid = eid.strip()
    if eid not in EFFECTS:
        raise SimulationError("--effect", f"unknown effect '{eid}' (known: {', '.join(EFFECTS)})")
    params: dict[str, float] = {}
    if rest.strip():
        for item in rest.split(","):
            key, eq, value = item.partition("=")
            if not eq or not key.strip():
                raise SimulationError("--effect", f"'{text}': expected ID:name=value,name=value")
            try:
                params[key.strip()] = float(value)
            except ValueError:
                raise SimulationError("--effect", f"'{text}': '{value}' is not a number") from None
    return eid, params


def parse_assignment(text: str, option: str = "--param") -> tuple[str, float]:
    """Parse ``NAME=VALUE`` with a float value."""
    key, eq, value = text.partition("=")
    if not eq or not key.strip():
        raise SimulationError(option, f"'{text}': expected NAME=VALUE")
    try:
        v = float(value)
    except ValueError:
        raise SimulationError(option, f"'{text}': '{value}' is not a number") from None
    if not math.isfinite(v):
        raise SimulationError(option, f"'{text}': value must be finite")
    return key.strip(), v


# ---------------------------------------------------------------------------
# the flat parameter vector of the integrator
# ---------------------------------------------------------------------------
(P_M, P_FV_POS, P_FV_NEG, P_FC_POS, P_FC_NEG, P_OFFSET, P_FS, P_VS, P_RIP_A, P_RIP_L, P_RIP_PH,
 P_K, P_Q0, P_DM, P_TCH, P_FLEX_K, P_FLEX_C, P_FLEX_R, P_FMAX, P_VEPS, P_RES, P_LAG) = range(22)
N_PLANT = 22

STICK_VELOCITY = 1e-9
"""|qd| (m/s) at or below which the stick/slip decision is taken (see closed_loop)."""


def plant_vector(params: RigidParameters, effects: Effects) -> np.ndarray:
    """The parameters and effects as the flat float64 vector read by the integrator."""
    p = np.zeros(N_PLANT)
    if not params.M > 0 or not math.isfinite(params.M):
        raise SimulationError("--param", f"mass M must be > 0 (got {params.M})")
    for name in ("Fv", "Fc", "offset"):
        if not math.isfinite(getattr(params, name)):
            raise SimulationError("--param", f"{name} must be finite")
    if params.Fc < 0:
        raise SimulationError("--param", f"Coulomb friction Fc must be >= 0 (got {params.Fc})")
    p[P_M] = params.M
    p[P_FV_POS] = p[P_FV_NEG] = params.Fv
    p[P_FC_POS] = p[P_FC_NEG] = params.Fc
    p[P_OFFSET] = params.offset
    if (e := effects.get("asymmetric_friction")) is not None:
        p[P_FV_POS], p[P_FV_NEG], p[P_FC_POS], p[P_FC_NEG] = e.Fv_pos, e.Fv_neg, e.Fc_pos, e.Fc_neg
    p[P_VS] = 1.0
    if (e := effects.get("stribeck")) is not None:
        p[P_FS], p[P_VS] = e.Fs, e.vs
        if min(p[P_FC_POS], p[P_FC_NEG]) + e.Fs < 0:
            raise SimulationError("--effect", f"effect 'stribeck': Fs = {e.Fs} puts the static friction level Fc + Fs below 0")
    p[P_RIP_L] = 1.0
    if (e := effects.get("position_ripple")) is not None:
        p[P_RIP_A], p[P_RIP_L], p[P_RIP_PH] = e.A, e.L, e.phase
    if (e := effects.get("spring")) is not None:
        p[P_K], p[P_Q0] = e.k, e.q0
    p[P_TCH] = np.inf
    if (e := effects.get("payload_change")) is not None:
        p[P_DM], p[P_TCH] = e.dM, e.t_change
    if (e := effects.get("flexibility")) is not None:
        p[P_FLEX_K], p[P_FLEX_C], p[P_FLEX_R] = e.stiffness, e.damping, e.load_fraction
    p[P_FMAX] = np.inf
    if (e := effects.get("saturation")) is not None:
        p[P_FMAX] = e.force_max
    p[P_VEPS] = STICK_VELOCITY
    if (e := effects.get("quantization")) is not None:
        p[P_RES] = e.resolution
    if (e := effects.get("delay")) is not None:
        p[P_LAG] = e.drive_lag_s
    return p


# ---------------------------------------------------------------------------
# inverse dynamics
# ---------------------------------------------------------------------------
def force_model(params: RigidParameters | dict[str, float], effects: Effects | dict[str, Any] | None,
                q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Inverse dynamics with effects, vectorised: the force that produces ``q, qd, qdd``.

    ``tau = M(t)*qdd + friction(qd) + offset + ripple(q) + spring(q)`` with
    ``sign(0) = 0``; ``payload_change`` raises the mass from ``t_change``;
    ``flexibility`` adds the force that accelerates the load mass, obtained by
    simulating the linear load dynamics driven by the given motor motion
    (load at rest relative to the motor at ``t[0]``; uniform ``t`` expected);
    ``delay`` returns the force ``delay`` seconds earlier (later for a
    negative delay; linear interpolation, the end values held). ``saturation``,
    ``quantization`` and ``noise`` are measurement/actuator effects and are
    ignored here.

    Parameters
    ----------
    params : RigidParameters or dict
        ``M, Fv, Fc, offset`` (missing names default to 0 except ``M``).
    effects : dict
        Effect id -> :class:`Effect` or its parameter dict.
    q, qd, qdd, t : ndarray
        Motion and time, equally long.
    """
    if isinstance(params, dict):
        params = RigidParameters(**{"M": params["M"], "Fv": params.get("Fv", 0.0), "Fc": params.get("Fc", 0.0), "offset": params.get("offset", 0.0)})
    eff = make_effects(effects) if not all(isinstance(v, Effect) for v in (effects or {}).values()) else dict(effects or {})
    p = plant_vector(params, eff)  # type: ignore[arg-type]
    q, qd, qdd, t = (np.asarray(a, dtype=np.float64) for a in (q, qd, qdd, t))
    sg = np.sign(qd)
    pos, neg = qd > 0, qd < 0
    fric = np.where(pos, p[P_FV_POS] * qd + p[P_FC_POS], 0.0) + np.where(neg, p[P_FV_NEG] * qd - p[P_FC_NEG], 0.0)
    if p[P_FS] != 0.0:
        fric = fric + p[P_FS] * np.exp(-((qd / p[P_VS]) ** 2)) * sg
    dm = np.where(t >= p[P_TCH], p[P_DM], 0.0)
    if p[P_FLEX_K] > 0.0:
        m_motor = (1.0 - p[P_FLEX_R]) * p[P_M]
        m_load = p[P_FLEX_R] * p[P_M] + dm
        coupling = _load_force(p, q, qd, t, m_load)
        tau = m_motor * qdd + coupling
    else:
        tau = (p[P_M] + dm) * qdd
    tau = tau + fric + p[P_OFFSET]
    if p[P_RIP_A] != 0.0:
        tau = tau + p[P_RIP_A] * np.sin(2.0 * np.pi * q / p[P_RIP_L] + p[P_RIP_PH])
    if p[P_K] != 0.0:
        tau = tau + p[P_K] * (q - p[P_Q0])
    if (d := eff.get("delay")) is not None and d.delay != 0:  # type: ignore[union-attr]
        tau = np.interp(t - d.delay, t, tau)  # type: ignore[union-attr]
    return tau


def _load_force(p: np.ndarray, q: np.ndarray, qd: np.ndarray, t: np.ndarray, m_load: np.ndarray) -> np.ndarray:
    """Spring-damper force on the load when the motor follows ``q, qd`` (exact discretisation per step)."""
    k, c = p[P_FLEX_K], p[P_FLEX_C]
    n = len(q)
    out = np.empty(n)
    ql, vl = float(q[0]), float(qd[0]) if n else 0.0
    for i in range(n):
        f = k * (q[i] - ql) + c * (qd[i] - vl)
        out[i] = f
        if i + 1 < n:
            h = float(t[i + 1] - t[i])
            m = float(m_load[i])
            # semi-implicit, 20 sub-steps: the load dynamics are linear and fast
            sub = 20
            hs = h / sub
            for j in range(sub):
                a = j / sub
                qm = q[i] + a * (q[i + 1] - q[i])
                vm = qd[i] + a * (qd[i + 1] - qd[i])
                vl += hs * (k * (qm - ql) + c * (vm - vl)) / m
                ql += hs * vl
    return out
