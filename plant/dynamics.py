"""Rigid-body parameters, the plant's parameter vector and the inverse dynamics of the axis.

The plant is a 1-DOF prismatic axis (the EMPS)::

    tau = M*qdd + Fv*qd + Fc*sign(qd) + offset            (paper eq. 29 + offset)

plus the effects of :mod:`ilic_cli.effects` (one definition each: parameters,
ranges, identification columns, words; the plant force of an effect linear in
its parameters is its columns times coefficients). This module packs them
into the flat vector the compiled loop reads (:func:`plant_vector`): the
built-in effects into fixed slots (:data:`SLOTS`, their compiled form, checked
against the definitions by tests/vocabulary/test_compiled_forms.py), any other
effect's linear form after them (:data:`N_PLANT`), for the loop that compiles
its columns (:mod:`plant.generic`).

:func:`force_model` is the vectorised inverse dynamics with these effects,
``W(q, qd, qdd, t) @ theta`` from the columns of the definitions plus the
blocks (:mod:`plant.blocks`: the flexible load, the delay); the measurement
effects ``quantization`` and ``noise``, the actuator limit ``saturation``, the
random ``disturbance`` and the drive's ``current_loop`` are not part of it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from ilic_cli import effects as fx
from ilic_cli import parameters
from ilic_cli.effects import Effect, EffectParams, Effects, LinearForm, make_effects
from ilic_cli.errors import ParameterError
from ilic_cli.regressor import COLUMNS, Kinematics
from plant.blocks import load_force, shifted


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
    P_VC,
) = range(33)
N_PLANT = 33

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
    "coulomb_smoothing": {"vc": P_VC},
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
    (:data:`SLOTS`); after them, per effect without a compiled form
    (:func:`generic_effects`), in order, its linear form (:func:`generic_form`):
    the nonlinear value (NaN without one) and one coefficient per column.
    """
    parameters.check_rigid(params.to_dict())
    generic = [(e, generic_form(e)) for e in generic_effects(effects)]
    p = np.zeros(N_PLANT + sum(1 + len(e.effect.columns) for e, _ in generic))
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
    i = N_PLANT
    for e, (value, theta) in generic:
        p[i] = np.nan if value is None else float(value)
        p[i + 1 : i + 1 + len(e.effect.columns)] = [theta.get(c.name, 0.0) for c in e.effect.columns]
        for name in set(theta) - set(e.effect.column_names):  # a coefficient of a rigid column (as the spring's offset)
            for slot in RIGID_SLOTS[name]:
                p[slot] += theta[name]
        i += 1 + len(e.effect.columns)
    if "stribeck" in effects and min(p[P_FC_POS], p[P_FC_NEG]) + p[P_FS] < 0:
        raise ParameterError("stribeck.Fs", p[P_FS], f">= -{min(p[P_FC_POS], p[P_FC_NEG]):g} (the static friction level Fc + Fs below 0)")
    p[P_LAG] = drive_lag_s(effects)
    return p


RIGID_SLOTS: dict[str, tuple[int, ...]] = {
    "M": (P_M,),
    "Fv": (P_FV_POS, P_FV_NEG),
    "Fc": (P_FC_POS, P_FC_NEG),
    "offset": (P_OFFSET,),
    "Fv_pos": (P_FV_POS,),
    "Fv_neg": (P_FV_NEG,),
    "Fc_pos": (P_FC_POS,),
    "Fc_neg": (P_FC_NEG,),
}
"""The slots of each rigid column's coefficient (:data:`ilic_cli.regressor.COLUMNS`; ``Fc_neg`` is a magnitude, as its column's sign)."""


def generic_form(e: EffectParams) -> LinearForm:
    """The linear form of an effect without a compiled form; :class:`ParameterError` when it has none the loop can compile."""
    form = e.effect.linear_form(e.params)
    if form is None or not all(c.of is not None for c in e.effect.columns):
        raise ParameterError("effect", e.id, "linear in columns with pointwise forms (EffectColumn.of), or a compiled form in plant.kernel")
    if not (form[0] is None or np.isscalar(form[0])):
        raise ParameterError("effect", e.id, "a scalar nonlinear value in the compiled plant")
    return form


# ---------------------------------------------------------------------------
# inverse dynamics
# ---------------------------------------------------------------------------
def force_model(
    params: RigidParameters | dict[str, float], effects: Effects | dict[str, Any] | None, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, t: np.ndarray
) -> np.ndarray:
    """Inverse dynamics with effects, vectorised: the force that produces ``q, qd, qdd``.

    ``tau = W(q, qd, qdd, t) @ theta``: the rigid columns (:data:`ilic_cli.regressor.COLUMNS`, ``sign(0) = 0``) and
    every effect linear in its parameters as its own columns times coefficients
    (:meth:`ilic_cli.effects.Effect.linear_form`: ``asymmetric_friction`` in place of ``Fv, Fc``, ``stribeck``,
    ``position_ripple``, ``spring``, ``gravity``, ``payload_change``, an effect added by a definition alone);
    ``friction_drift`` changes the friction coefficients with ``t`` (:func:`ilic_cli.effects.drift_of`, Coulomb
    levels kept >= 0); ``coulomb_smoothing`` puts ``tanh(qd/vc)`` for ``sign(qd)`` in every column of the sign (Coulomb,
    Stribeck, an asymmetry's sides); the blocks (:mod:`plant.blocks`): ``flexibility`` adds the force that accelerates the load
    mass, the acceleration terms of the effects (``payload_change``) landing on the load, obtained by simulating the
    linear load dynamics driven by the given motor motion (load at rest relative to the motor at ``t[0]``; uniform
    ``t`` expected); ``delay`` returns the force ``delay`` seconds earlier (:func:`plant.blocks.shifted`).
    ``saturation``, ``quantization``, ``noise``, ``disturbance`` and ``current_loop`` are measurement/actuator
    effects and are ignored here.

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
    plant_vector(params, eff)  # the plant's rules (rigid ranges, the static friction level)
    q, qd, qdd, t = (np.asarray(a, dtype=np.float64) for a in (q, qd, qdd, t))
    kin = Kinematics(qd, qdd, q, t, sign_qd=np.tanh(qd / eff["coulomb_smoothing"]["vc"]) if "coulomb_smoothing" in eff else None)
    rigid, own = linear_terms(params, eff)
    if "friction_drift" in eff:
        rigid = _drifted(rigid, eff["friction_drift"], t)
    if "flexibility" not in eff:
        tau = _columns_force(rigid, own, kin)
    else:
        flex = eff["flexibility"]
        still = Kinematics(qd, np.zeros_like(qdd), q, t, sign_qd=kin.sign_qd)
        moved = Kinematics(qd, np.ones_like(qdd), q, t, sign_qd=kin.sign_qd)
        m_rigid = rigid.pop("M")
        rest = _columns_force(rigid, own, still)
        m_load = flex["load_fraction"] * m_rigid + (_columns_force(rigid, own, moved) - rest)  # the acceleration terms: mass on the load
        tau = (1.0 - flex["load_fraction"]) * m_rigid * qdd + load_force(flex["stiffness"], flex["damping"], q, qd, t, m_load) + rest
    return shifted(tau, t, eff["delay"]["delay"] if "delay" in eff else 0.0)


OwnTerms = list[tuple[Effect, Any, dict[str, Any]]]
"""Per effect with columns of its own in the force: ``(definition, nonlinear value, {its column: coefficient})``."""


def linear_terms(params: RigidParameters, effects: Mapping[str, EffectParams]) -> tuple[dict[str, Any], OwnTerms]:
    """The plant force as columns times coefficients: ``({rigid column: coefficient}, own terms)``.

    The rigid parameters, less those an effect replaces (:attr:`ilic_cli.effects.Effect.replaces`), plus the
    coefficients the effects' linear forms give to rigid columns; and each effect's coefficients of its own columns.
    """
    eff = [effects[i] for i in fx.EFFECTS if i in effects]
    replaced = {n for e in eff for n in e.effect.replaces}
    rigid: dict[str, Any] = {n: v for n, v in params.to_dict().items() if n not in replaced}
    own: OwnTerms = []
    for e in eff:
        form = e.effect.linear_form(e.params)
        if form is None:
            continue
        value, theta = form
        mine = {n: c for n, c in theta.items() if n in e.effect.column_names}
        for n, c in theta.items():
            if n not in mine:
                rigid[n] = rigid.get(n, 0.0) + c
        if mine:
            own.append((e.effect, value, mine))
    return rigid, own


def _columns_force(rigid: Mapping[str, Any], own: OwnTerms, kin: Kinematics) -> np.ndarray:
    tau = np.zeros(len(kin.qd))
    for name, coef in rigid.items():
        tau = tau + coef * COLUMNS[name].build(kin)
    for effect, value, theta in own:
        W = effect.matrix(kin, value)
        for name, coef in theta.items():
            tau = tau + coef * W[:, effect.column_names.index(name)]
    return tau


def _drifted(rigid: Mapping[str, Any], drift: EffectParams, t: np.ndarray) -> dict[str, Any]:
    """The friction coefficients at ``t`` under ``friction_drift`` (viscous ``Fv*`` and Coulomb ``Fc*`` columns; Coulomb kept >= 0)."""
    dfv = fx.drift_of(t, drift["dFv"], drift["tau"], drift["Fv_rate"])
    dfc = fx.drift_of(t, drift["dFc"], drift["tau"], drift["Fc_rate"])
    out = dict(rigid)
    for name, coef in rigid.items():
        if name.startswith("Fv"):
            out[name] = coef + dfv
        elif name.startswith("Fc"):
            out[name] = np.maximum(coef + dfc, 0.0)
    return out
