"""The built-in mechanical effects: friction (asymmetric, Stribeck, drift), forces of position (ripple, spring, gravity), payload, offset.

Each plant force is the effect's columns times coefficients (:attr:`~ilic_cli.effects.definition.Effect.coefficients`,
or the default: columns named like plant parameters); ``friction_drift`` changes the friction coefficients with time.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.effects.definition import Effect, EffectColumn, Estimate, EstimateResult, Fit, LinearForm, PlantParam, Scan, col, unit_on
from ilic_cli.effects.grids import change_time_grid, ripple_grid, stribeck_grid
from ilic_cli.parameters import STANDARD_GRAVITY
from ilic_cli.regressor import GRAVITY_COLUMNS, Kinematics, negative_side


def _asym_estimate(fit: Fit) -> EstimateResult:
    fv = fit.combination({"Fv": 1.0})
    fvn = fit.combination({"Fv": 1.0, "dFv_neg": 1.0})
    est = {"Fv_pos": Estimate(*fv, "N·s/m"), "Fv_neg": Estimate(*fvn, "N·s/m")}
    fc = fit.combination({"Fc": 1.0}) if fit.has("Fc") else (0.0, 0.0)
    note = ""
    if fit.has("offset"):
        est["Fc_pos"] = Estimate(*fit.combination({"Fc": 1.0, "offset": 1.0}), "N")
        est["Fc_neg"] = Estimate(*fit.combination({"Fc": 1.0, "offset": -1.0}), "N")
        note = (
            "Fc_pos/Fc_neg attribute the whole constant offset to Coulomb asymmetry; the two cannot be told apart "
            "(the model file keeps Fc symmetric plus the offset)"
        )
    return est, {"Fv_pos": fv[0], "Fv_neg": fvn[0], "Fc_pos": fc[0], "Fc_neg": fc[0]}, note


def _stribeck_estimate(fit: Fit) -> EstimateResult:
    level = fit.combination({"Fs": 1.0})
    est = {"Fs": Estimate(*level, "N"), "vs": Estimate(float(fit.value), fit.value_std, "m/s")}
    if fit.has("Fc_pos") and fit.has("Fc_neg"):
        fc = min(fit.get("Fc_pos"), fit.get("Fc_neg"))
    else:
        fc = fit.get("Fc")
    force = unit_on("N", fit.joint)
    if fc + level[0] < 0:
        return est, None, f"Fs = {level[0]:.3g} {force} would put the static friction level Fc + Fs below 0: not in the model file"
    note = f"negative Fs, kept in the model file: the plant's static friction level Fc + Fs is {fc + level[0]:.3g} {force}" if level[0] < 0 else ""
    return est, {"Fs": level[0], "vs": float(fit.value)}, note


def _stribeck_sentence(p: Mapping[str, Estimate]) -> str:
    what = f"extra friction Fs = {p['Fs'].value:.3g} {p['Fs'].unit} below vs = {p['vs'].value * 1e3:.3g} m{p['vs'].unit}"
    if p["Fs"].value < 0:
        what += (
            "; negative: friction is lower at low speed than the Coulomb-viscous line, the opposite of the Stribeck effect, "
            "so read it as a shape correction of the friction curve"
        )
    return what


def _ripple_estimate(fit: Fit) -> EstimateResult:
    a, b = fit.get("ripple_sin"), fit.get("ripple_cos")
    ia, ib = fit.names.index("ripple_sin"), fit.names.index("ripple_cos")
    A = math.hypot(a, b)
    J_A = np.array([a, b]) / A if A > 0 else np.zeros(2)
    J_ph = np.array([-b, a]) / (A * A) if A > 0 else np.zeros(2)
    C = fit.cov[np.ix_([ia, ib], [ia, ib])]
    est = {
        "A": Estimate(A, float(math.sqrt(max(J_A @ C @ J_A, 0.0))), "N"),
        "L": Estimate(float(fit.value), fit.value_std, "m"),
        "phase": Estimate(math.atan2(b, a), float(math.sqrt(max(J_ph @ C @ J_ph, 0.0))), "rad"),
    }
    return est, {"A": A, "L": float(fit.value), "phase": math.atan2(b, a)}, ""


def _spring_estimate(fit: Fit) -> EstimateResult:
    k = fit.combination({"k_spring": 1.0})
    note = "the rest position q0 is absorbed by the offset (q0 = 0 in the model file)" if fit.has("offset") else ""
    return {"k": Estimate(*k, "N/m")}, {"k": k[0], "q0": 0.0}, note


def _ripple_coefficients(v: Mapping[str, float]) -> LinearForm:
    """``A sin(2 pi q/L + phase) = A cos(phase) sin(2 pi q/L) + A sin(phase) cos(2 pi q/L)``: the inverse of :func:`_ripple_estimate`."""
    return v["L"], {"ripple_sin": v["A"] * math.cos(v["phase"]), "ripple_cos": v["A"] * math.sin(v["phase"])}


def _ripple_build(kin: Kinematics, period: Any, fs_hz: float) -> np.ndarray:
    if kin.q is None:
        raise ValueError("the ripple columns need the position q")
    return np.c_[np.sin(2.0 * np.pi * kin.q / period), np.cos(2.0 * np.pi * kin.q / period)]


ASYMMETRIC_FRICTION = Effect(
    "asymmetric_friction",
    "asymmetric friction",
    "Friction differs between the two directions of motion, e.g. from wear or fatigue of the screw on one side.",
    params=(
        PlantParam("Fv_pos", "N·s/m", 166.7061, "viscous friction, positive velocity"),
        PlantParam("Fv_neg", "N·s/m", 240.4236, "viscous friction, negative velocity"),
        PlantParam("Fc_pos", "N", 20.1440, "Coulomb friction, positive velocity", low=0.0),
        PlantParam("Fc_neg", "N", 20.6277, "Coulomb friction, negative velocity (a magnitude)", low=0.0),
    ),
    coefficients=lambda v: (None, {n: v[n] for n in parameters.ASYMMETRIC}),
    replaces=("Fv", "Fc"),
    form="extra viscous coefficient for negative velocity: dFv * qd * (1 - sign(qd))/2 (Coulomb asymmetry is the constant offset)",
    signature="residual proportional to velocity on one side of zero only; mean residual differs between positive and negative velocity bins",
    signature_kinds=("velocity",),
    columns=(col("dFv_neg", "extra viscous friction at negative velocity", "N·s/m"),),
    build=lambda kin, value, fs_hz: np.c_[kin.qd * negative_side(kin)],
    estimate=_asym_estimate,
    sentence=lambda p: f"viscous friction {p['Fv_pos'].value:.3g} {p['Fv_pos'].unit} forward, {p['Fv_neg'].value:.3g} backward",
)

STRIBECK = Effect(
    "stribeck",
    "Stribeck friction",
    "At low sliding speed the lubricant film breaks down and friction rises above its Coulomb level before it drops with speed.",
    params=(
        PlantParam("Fs", "N", 5.0, "static friction in excess of Coulomb (negative: lower at low speed)"),
        PlantParam("vs", "m/s", 0.01, "Stribeck velocity", low=0.0, low_open=True),
    ),
    form="Fs * sign(qd) * exp(-(qd/vs)^2), vs searched",
    signature="residual with the sign of the velocity, concentrated in the low-speed bins and at velocity reversals",
    signature_kinds=("velocity", "reversal"),
    columns=(col("Fs", "static friction in excess of Coulomb", "N"),),
    build=lambda kin, vs, fs_hz: np.c_[kin.sgn * np.exp(-((kin.qd / vs) ** 2))],
    scan=Scan("vs", "m/s", stribeck_grid),
    strategy="dwell_segments",
    estimate=_stribeck_estimate,
    sentence=_stribeck_sentence,
    # Stribeck friction rises above Coulomb at low speed; a fit that falls below it
    # is another mechanism (pre-sliding, smoothed or stuck Coulomb friction at a
    # dwell), which the catalogue does not model, and is not named Stribeck
    impossible=lambda th, v, joint: (
        None
        if th[0] > 0
        else f"static friction below Coulomb (Fs = {th[0]:.3g} {unit_on('N', joint)}) is not Stribeck friction "
        "(pre-sliding or stuck Coulomb friction: outside the catalogue)"
    ),
)

POSITION_RIPPLE = Effect(
    "position_ripple",
    "position-dependent force ripple",
    "Cogging of the motor and the screw pitch make the force needed to move vary periodically with position.",
    params=(
        PlantParam("A", "N", 2.0, "amplitude"),
        PlantParam("L", "m", 0.01, "spatial period", low=0.0, low_open=True),
        PlantParam("phase", "rad", 0.0, "phase"),
    ),
    coefficients=_ripple_coefficients,
    form="A * sin(2 pi q / P) + B * cos(2 pi q / P), spatial period P searched",
    signature="residual periodic in position: a peak in the residual against position, at frequency velocity/P in time",
    signature_kinds=("position", "frequency"),
    columns=(col("ripple_sin", "ripple, sine component", "N"), col("ripple_cos", "ripple, cosine component", "N")),
    build=_ripple_build,
    scan=Scan("L", "m", ripple_grid),
    estimate=_ripple_estimate,
    sentence=lambda p: f"amplitude {p['A'].value:.3g} {p['A'].unit}, spatial period {p['L'].value * 1e3:.4g} m{p['L'].unit}",
)

SPRING = Effect(
    "spring",
    "spring force",
    "A cable chain or a gravity-like preload pulls the carriage towards one end with a force proportional to position.",
    params=(PlantParam("k", "N/m", 100.0, "stiffness"), PlantParam("q0", "m", 0.1, "rest position")),
    coefficients=lambda v: (None, {"k_spring": v["k"], "offset": -v["k"] * v["q0"]}),
    form="k * q (its rest position is absorbed by the offset)",
    signature="residual growing linearly with position, same sign in both directions of motion",
    signature_kinds=("position",),
    columns=(col("k_spring", "stiffness", "N/m"),),
    build=lambda kin, value, fs_hz: np.c_[kin.q],
    estimate=_spring_estimate,
    sentence=lambda p: f"stiffness {p['k'].value:.4g} {p['k'].unit}",
    # a passive elastic element stores energy as it leaves its rest position: its stiffness is positive. A force that grows
    # away from rest is no spring (on a revolute joint it is what gravity about an upright position makes: corpus s530,
    # s732, gravity with MY > 0 fitted as k < 0 and stated as "spring or gravity")
    impossible=lambda th, v, joint: None if th[0] >= 0 else f"negative stiffness (k = {th[0]:.3g}) is not a spring: its force grows away from rest",
)


def _gravity_sentence(p: Mapping[str, Estimate]) -> str:
    mx, my = p["MX"].value, p["MY"].value
    peak = STANDARD_GRAVITY * math.hypot(mx, my)
    return (
        f"first moments MX = {mx:.4g} kg·m, MY = {my:.4g} kg·m: a gravity torque of up to {peak:.4g} N·m, "
        f"largest at q = {math.atan2(-my, mx):+.3g} rad from the joint's zero"
    )


GRAVITY = Effect(
    "gravity",
    "gravity",
    "The link's weight acts at its centre of mass, off the joint's axis: a torque that varies with the angle as the cosine of the arm's "
    "angle to the horizontal (paper eq. 3, the first moments MX, MY).",
    params=(
        PlantParam("MX", "kg·m", 0.05, parameters.FIRST_MOMENTS["MX"].meaning),
        PlantParam("MY", "kg·m", 0.0, parameters.FIRST_MOMENTS["MY"].meaning),
    ),
    form="g * (MX * cos q - MY * sin q), q from the joint's zero as given (revolute joint)",
    signature="residual periodic in the angle with one cycle per turn, same sign in both directions of motion",
    signature_kinds=("position",),
    columns=tuple(EffectColumn(c.name, c.unit, c.description) for c in GRAVITY_COLUMNS.values()),
    build=lambda kin, value, fs_hz: np.column_stack([c.build(kin) for c in GRAVITY_COLUMNS.values()]),
    sentence=_gravity_sentence,
    joints=("revolute",),
)

PAYLOAD_CHANGE = Effect(
    "payload_change",
    "payload change",
    "A mass is added to (or removed from) the carriage during the run, changing the inertia from that time on.",
    params=(PlantParam("dM", "kg", 10.0, "mass added"), PlantParam("t_change", "s", 60.0, "time of the change", low=0.0)),
    form="dM * qdd * [t >= tc], change time tc searched",
    signature="residual proportional to acceleration, after a given time only",
    signature_kinds=("drift", "time"),
    columns=(col("dM", "mass added at the change time", "kg"),),
    build=lambda kin, tc, fs_hz: np.c_[kin.qdd * (kin.t >= tc)],
    scan=Scan("t_change", "s", change_time_grid, log=False, of_the_whole_log=True),
    sentence=lambda p: f"{p['dM'].value:+.3g} {p['dM'].unit} from t = {p['t_change'].value:.3g} s",
)


def drift_of(t: Any, change: float, tau: float, rate: float) -> Any:
    """Change of a friction coefficient at ``t`` (s, the log's time, as ``payload_change``'s ``t_change``).

    A warm-up ``change * (1 - exp(-t/tau))`` plus a wear ``rate * t``.

    NumPy operations only (arrays or floats); the plant's compiled loop has its own form, checked against this one by the tests.
    """
    return change * (1.0 - np.exp(-t / tau)) + rate * t


def _drift_sentence(p: Mapping[str, Estimate]) -> str:
    """``Fv -33 % from 200 (exponential, time constant 6 s)`` per drifting coefficient (:mod:`ilic_cli.diagnosis.drift`'s estimates)."""
    parts = []
    for key, est in p.items():
        if not key.endswith("_relative_change"):
            continue
        name = key[: -len("_relative_change")]
        start = p.get(f"{name}_start")
        what = f"{name} {est.value * 100:+.3g} %" + ("" if start is None else f" from {start.value:.4g}")
        if f"{name}_tau" in p:
            what += f" (exponential, time constant {p[f'{name}_tau'].value:.3g} s)"
        elif f"{name}_rate" in p:
            what += f" (linear, {p[f'{name}_rate'].value:+.3g} per s)"
        parts.append(what)
    return "; ".join(parts)


FRICTION_DRIFT = Effect(
    "friction_drift",
    "friction drift",
    "Friction changes during the run: it falls as the lubricant warms up (an exponential approach to its warm level) "
    "or changes steadily with wear (a linear trend).",
    params=(
        PlantParam("dFv", "N·s/m", -50.0, "change of viscous friction at the end of the warm-up (exponential)"),
        PlantParam("dFc", "N", 0.0, "change of Coulomb friction at the end of the warm-up (exponential)"),
        PlantParam("tau", "s", 10.0, "time constant of the warm-up", low=0.0, low_open=True),
        PlantParam("Fv_rate", "N·s/m/s", 0.0, "linear change of viscous friction per second (wear)"),
        PlantParam("Fc_rate", "N/s", 0.0, "linear change of Coulomb friction per second (wear)"),
    ),
    form="Fv(t) = Fv + dFv (1 - exp(-t/tau)) + Fv_rate t, Fc(t) likewise (Coulomb level kept >= 0), t the log's time",
    signature=(
        "the friction coefficient's column times a trend in time (exponential or linear) adds significantly to the model on every row; "
        "the per-window estimates show it"
    ),
    signature_kinds=("drift", "time"),
    sentence=_drift_sentence,
)

COULOMB_SMOOTHING = Effect(
    "coulomb_smoothing",
    "smoothed Coulomb friction",
    "Near zero speed the Coulomb friction rises smoothly with the speed instead of switching to its level, and the axis never "
    "sticks: it creeps under any force, as a simulator's tanh law or a lubricated contact's pre-sliding give.",
    params=(PlantParam("vc", "m/s", 0.001, "speed over which Coulomb friction rises: Fc tanh(qd/vc)", low=0.0, low_open=True),),
    form="Fc tanh(qd/vc) in place of Fc sign(qd) (Stribeck's and an asymmetry's sides likewise), no stiction",
    signature="the force falls below the Coulomb level near zero speed, and the axis creeps where a sticking one holds",
    signature_kinds=("velocity", "reversal"),
    sentence=lambda p: f"vc = {p['vc'].value * 1e3:.3g} m{p['vc'].unit}",
)
"""A friction law, not an added force: the plant's Coulomb (and Stribeck) friction multiplies ``tanh(qd/vc)`` instead of the
direction of motion, and the Karnopp stick/slip decision is gone (:mod:`plant.kernel`; the inverse dynamics'
:attr:`~ilic_cli.regressor.Kinematics.sgn`: :func:`plant.dynamics.force_model`). No column: diagnosis does not propose it;
it reads it from the recording as the law the replays run (:mod:`ilic_cli.diagnosis.friction_law`)."""

OFFSET = Effect(
    "offset",
    "force offset",
    "The drive's amplifier or current sensor adds a constant force, or Coulomb friction is not the same in both directions.",
    plant=False,
    form="constant offset",
    signature="constant mean residual in every bin",
    signature_kinds=("velocity", "time"),
    columns=(col("offset", "constant force offset"),),
    build=lambda kin, value, fs_hz: np.ones((len(kin.qd), 1)),
    sentence=lambda p: f"{p['offset'].value:+.3g} {p['offset'].unit}",
)
