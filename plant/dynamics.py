"""Rigid-body parameters, the plant's parameter vector and the inverse dynamics of the axis.

The plant is a 1-DOF prismatic axis (the EMPS)::

    tau = M*qdd + Fv*qd + Fc*sign(qd) + offset            (paper eq. 29 + offset)

plus the effects of :mod:`ilic_cli.effects` (one definition each: parameters,
ranges, force term, identification columns, words). This module packs them
into the flat vector the compiled loop reads (:func:`plant_vector`): the
built-in effects into fixed slots (:data:`SLOTS`, their compiled form, checked
against the definitions by the tests), any other effect's parameters after
them (:data:`N_PLANT`), for the loop that compiles its ``force``.

:func:`force_model` is the vectorised inverse dynamics with these effects (the
measurement effects ``quantization`` and ``noise``, the actuator limit
``saturation``, the random ``disturbance`` and the drive's ``current_loop``
are not part of it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from ilic_cli import effects as fx
from ilic_cli import parameters
from ilic_cli.effects import EffectParams, Effects, make_effects
from ilic_cli.errors import ParameterError


# ---------------------------------------------------------------------------
# rigid parameters
# ---------------------------------------------------------------------------
@dataclass
class RigidParameters:
    """Rigid-body parameters of the axis (SI, load side; :data:`ilic_cli.parameters.RIGID`).

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

    M: float = parameters.DEFAULTS["M"]
    Fv: float = parameters.DEFAULTS["Fv"]
    Fc: float = parameters.DEFAULTS["Fc"]
    offset: float = parameters.DEFAULTS["offset"]

    NAMES: ClassVar[tuple[str, ...]] = parameters.RIGID

    def to_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RigidParameters:
        return cls(**{k: float(v) for k, v in d.items() if k in cls.NAMES})

    def replace(self, **values: float) -> RigidParameters:
        d = self.to_dict()
        for k, v in values.items():
            if k not in self.NAMES:
                raise ParameterError("parameter", k, f"a rigid parameter ({', '.join(self.NAMES)})")
            d[k] = float(v)
        return RigidParameters(**d)


def plant_model(values: Mapping[str, float], effects: Mapping[str, Any] | None = None) -> tuple[RigidParameters, Effects]:
    """The plant of a model of any structure (:func:`ilic_cli.parameters.to_plant`) and its effects.

    Asymmetric parameters (``Fv_pos, ...``) become the ``asymmetric_friction``
    effect (which ``effects`` must not hold as well).
    """
    rigid, asym = parameters.to_plant(values)
    eff = make_effects(effects)
    if asym is not None:
        if "asymmetric_friction" in eff:
            raise ParameterError("asymmetric_friction", None, "given once: the asymmetric parameters (Fv_pos, ...) are that effect already")
        eff["asymmetric_friction"] = EffectParams(fx.ASYMMETRIC_FRICTION, fx.ASYMMETRIC_FRICTION.values(asym))
    return RigidParameters(**rigid), eff


# ---------------------------------------------------------------------------
# the flat parameter vector of the integrator
# ---------------------------------------------------------------------------
(
    P_M,
    P_FV_POS,
    P_FV_NEG,
    P_FC_POS,
    P_FC_NEG,
    P_OFFSET,
    P_FS,
    P_VS,
    P_RIP_A,
    P_RIP_L,
    P_RIP_PH,
    P_K,
    P_Q0,
    P_DM,
    P_TCH,
    P_FLEX_K,
    P_FLEX_C,
    P_FLEX_R,
    P_FMAX,
    P_VEPS,
    P_RES,
    P_LAG,
    P_DIST_STD,
    P_DIST_BW,
    P_CL_BW,
    P_MX,
    P_MY,
    P_DR_DFV,
    P_DR_DFC,
    P_DR_TAU,
    P_DR_RFV,
    P_DR_RFC,
) = range(32)
N_PLANT = 32

SLOTS: dict[str, dict[str, int]] = {
    "asymmetric_friction": {"Fv_pos": P_FV_POS, "Fv_neg": P_FV_NEG, "Fc_pos": P_FC_POS, "Fc_neg": P_FC_NEG},
    "stribeck": {"Fs": P_FS, "vs": P_VS},
    "position_ripple": {"A": P_RIP_A, "L": P_RIP_L, "phase": P_RIP_PH},
    "spring": {"k": P_K, "q0": P_Q0},
    "payload_change": {"dM": P_DM, "t_change": P_TCH},
    "flexibility": {"stiffness": P_FLEX_K, "damping": P_FLEX_C, "load_fraction": P_FLEX_R},
    "saturation": {"force_max": P_FMAX},
    "quantization": {"resolution": P_RES},
    "delay": {},  # the drive lag (a negative delay) goes to P_LAG; the measurement lag is the force sensor's
    "noise": {},  # drawn up front (plant.sensors.draw_noise)
    "disturbance": {"std": P_DIST_STD, "bandwidth_hz": P_DIST_BW},  # recorded; the force is drawn up front (plant.sensors.draw_disturbance)
    "current_loop": {"bandwidth_hz": P_CL_BW},
    "gravity": {"MX": P_MX, "MY": P_MY},
    "friction_drift": {"dFv": P_DR_DFV, "dFc": P_DR_DFC, "tau": P_DR_TAU, "Fv_rate": P_DR_RFV, "Fc_rate": P_DR_RFC},
}
"""Compiled form of the built-in effects: parameter -> slot of the plant vector."""

STICK_VELOCITY = 1e-9
"""|qd| (m/s) at or below which the stick/slip decision is taken (see closed_loop)."""


def generic_effects(effects: Mapping[str, EffectParams]) -> list[EffectParams]:
    """The effects without a compiled form, in the order of :data:`ilic_cli.effects.EFFECTS`."""
    return [effects[i] for i in fx.EFFECTS if i in effects and i not in SLOTS]


def drive_lag_s(effects: Mapping[str, EffectParams]) -> float:
    """Lag (s, >= 0) of the applied force behind the logged command (a negative ``delay``)."""
    return max(-effects["delay"]["delay"], 0.0) if "delay" in effects else 0.0


def measurement_lag_s(effects: Mapping[str, EffectParams]) -> float:
    """Lag (s, >= 0) of the force measurement (a positive ``delay``)."""
    return max(effects["delay"]["delay"], 0.0) if "delay" in effects else 0.0


def plant_vector(params: RigidParameters, effects: Mapping[str, EffectParams]) -> np.ndarray:
    """The parameters and effects as the flat float64 vector read by the integrator.

    Slots ``0 .. N_PLANT-1``: the rigid parameters and the built-in effects
    (:data:`SLOTS`); after them, the parameters of every effect without a
    compiled form (:func:`generic_effects`), in order.
    """
    parameters.check_rigid(params.to_dict())
    generic = generic_effects(effects)
    p = np.zeros(N_PLANT + sum(len(e.effect.params) for e in generic))
    p[P_M] = params.M
    p[P_FV_POS] = p[P_FV_NEG] = params.Fv
    p[P_FC_POS] = p[P_FC_NEG] = params.Fc
    p[P_OFFSET] = params.offset
    p[P_VS] = p[P_RIP_L] = p[P_DR_TAU] = 1.0
    p[P_TCH] = p[P_FMAX] = np.inf
    p[P_VEPS] = STICK_VELOCITY
    for eid, slots in SLOTS.items():
        if eid in effects:
            for name, slot in slots.items():
                p[slot] = effects[eid][name]
    if "stribeck" in effects and min(p[P_FC_POS], p[P_FC_NEG]) + p[P_FS] < 0:
        raise ParameterError("stribeck.Fs", p[P_FS], f">= -{min(p[P_FC_POS], p[P_FC_NEG]):g} (the static friction level Fc + Fs below 0)")
    p[P_LAG] = drive_lag_s(effects)
    i = N_PLANT
    for e in generic:
        p[i : i + len(e.effect.params)] = e.vector()
        i += len(e.effect.params)
    return p


# ---------------------------------------------------------------------------
# inverse dynamics
# ---------------------------------------------------------------------------
def force_model(
    params: RigidParameters | dict[str, float], effects: Effects | dict[str, Any] | None, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """Inverse dynamics with effects, vectorised: the force that produces ``q, qd, qdd``.

    ``tau = M(t)*qdd + friction(qd) + offset + ripple(q) + spring(q)`` with
    ``sign(0) = 0``; ``payload_change`` raises the mass from ``t_change``;
    ``friction_drift`` changes ``Fv`` and ``Fc`` with ``t`` (:func:`ilic_cli.effects.drift_of`);
    ``gravity`` adds ``g·(MX cos q - MY sin q)``;
    ``flexibility`` adds the force that accelerates the load mass, obtained by
    simulating the linear load dynamics driven by the given motor motion
    (load at rest relative to the motor at ``t[0]``; uniform ``t`` expected);
    ``delay`` returns the force ``delay`` seconds earlier (later for a
    negative delay; linear interpolation, the end values held). ``saturation``,
    ``quantization``, ``noise``, ``disturbance`` and ``current_loop`` are
    measurement/actuator effects and are ignored here.

    The built-in structural effects (asymmetric friction, payload, flexibility,
    delay) come from the plant vector; every effect with a ``force`` term
    (:mod:`ilic_cli.effects`) adds it.

    Parameters
    ----------
    params : RigidParameters or dict
        ``M, Fv, Fc, offset`` or the parameters of any structure
        (:func:`plant_model`; missing names default to 0 except ``M``).
    effects : dict
        Effect id -> :class:`~ilic_cli.effects.EffectParams` or its parameter dict.
    q, qd, qdd, t : ndarray
        Motion and time, equally long.
    """
    if isinstance(params, Mapping):
        params, eff = plant_model(params, effects)
    else:
        eff = make_effects(effects)
    p = plant_vector(params, eff)
    q, qd, qdd, t = (np.asarray(a, dtype=np.float64) for a in (q, qd, qdd, t))
    pos, neg = qd > 0, qd < 0
    fv_pos, fv_neg, fc_pos, fc_neg = p[P_FV_POS], p[P_FV_NEG], p[P_FC_POS], p[P_FC_NEG]
    if "friction_drift" in eff:  # friction that changes over time (t: the plant's time, as payload_change's)
        dfv = fx.drift_of(t, p[P_DR_DFV], p[P_DR_TAU], p[P_DR_RFV])
        dfc = fx.drift_of(t, p[P_DR_DFC], p[P_DR_TAU], p[P_DR_RFC])
        fv_pos, fv_neg = fv_pos + dfv, fv_neg + dfv
        fc_pos, fc_neg = np.maximum(fc_pos + dfc, 0.0), np.maximum(fc_neg + dfc, 0.0)
    fric = np.where(pos, fv_pos * qd + fc_pos, 0.0) + np.where(neg, fv_neg * qd - fc_neg, 0.0)
    dm = np.where(t >= p[P_TCH], p[P_DM], 0.0)
    if p[P_FLEX_K] > 0.0:
        m_motor = (1.0 - p[P_FLEX_R]) * p[P_M]
        m_load = p[P_FLEX_R] * p[P_M] + dm
        coupling = _load_force(p, q, qd, t, m_load)
        tau = m_motor * qdd + coupling
    else:
        tau = (p[P_M] + dm) * qdd
    tau = tau + fric + p[P_OFFSET]
    for e in (eff[i] for i in fx.EFFECTS if i in eff):
        if e.effect.force is not None:
            tau = tau + e.effect.force(q, qd, e.vector())
    d = eff["delay"]["delay"] if "delay" in eff else 0.0
    if d != 0:
        tau = np.interp(t - d, t, tau)
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
