"""The closed loop: compiled inner loop (controller per period, fixed-step RK4) and its drivers.

One function, :func:`run_periods`, advances the closed loop over control
periods ``k0 .. k1-1``. Everything it needs is in flat float64 vectors
(``plant.dynamics.plant_vector``, ``plant.controllers`` ``vector()``), so it
compiles once with numba (``cache=True``: the machine code is cached in
``__pycache__``; the first compile takes a few seconds).

Integration
-----------
Each control period is split into ``substeps`` equal RK4 steps with the
control force held constant. The friction direction ``s`` is frozen over a
step (so each step integrates smooth dynamics) and chosen at its start:

* ``|qd| > STICK_VELOCITY``: ``s = sign(qd)`` (sliding);
* otherwise (Karnopp stick/slip): the net non-friction force ``f`` on the
  motor is compared with the static level (``Fc + Fs`` in the direction of
  ``f``): beyond it ``s = sign(f)`` (break-away), within it the axis sticks
  (``s = 0``: ``qd = 0`` and no motion of the motor side over the step).

If a sliding step ends with the velocity of the opposite sign, the step is
redone up to the zero crossing (located by linear interpolation of the
velocity), the velocity is set to exactly 0 and the rest of the step starts
with a new stick/slip decision. The result is deterministic and does not
depend on luck at zero crossings.

Rigid axis without smooth effects (no Stribeck term, ripple, spring or
flexibility; payload change, asymmetric friction, offset and the measurement
effects allowed): between direction changes the dynamics are linear with a
constant force, so the four RK4 stages sum to a closed form
(:func:`_lin`), and a period that slides in one direction throughout is
advanced in one composed step (:func:`_linear_period`). Same steps, same
stick/slip and zero-crossing logic: the results equal the general path's up to
round-off (positions within ~1e-14 relative), some 20x faster.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import njit

from ilic_cli.errors import SimulationError

from plant.controllers import (C_ALPHA, C_ASYM, C_EXACT_VEL, C_GTAU, C_KIND, C_KP, C_KV, C_PD_KP, C_PD_KV, C_PULSE_RAMP, C_VMAX, CTCSettings,
                               PDSettings, chi_vector)
from plant.dynamics import (P_DM, P_FC_NEG, P_FC_POS, P_FLEX_C, P_FLEX_K, P_FLEX_R, P_FMAX, P_FS, P_FV_NEG, P_FV_POS, P_K, P_LAG,
                            P_M, P_OFFSET, P_Q0, P_RES, P_RIP_A, P_RIP_L, P_RIP_PH, P_TCH, P_VEPS, P_VS, STICK_VELOCITY, AsymmetricFriction,
                            Effect, Effects, RigidParameters, effects_to_dict, make_effects, plant_vector)

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog

TWO_PI = 2.0 * math.pi
TWO_OVER_PI = 2.0 / math.pi


@njit(cache=True)
def _nonfriction(p, u, x0, x1, x2, x3, flex):
    """Net force on the motor side without friction, and the coupling force on the load."""
    f = u - p[P_OFFSET]
    if p[P_RIP_A] != 0.0:
        f -= p[P_RIP_A] * math.sin(TWO_PI * x0 / p[P_RIP_L] + p[P_RIP_PH])
    if p[P_K] != 0.0:
        f -= p[P_K] * (x0 - p[P_Q0])
    fc = 0.0
    if flex:
        fc = p[P_FLEX_K] * (x0 - x2) + p[P_FLEX_C] * (x1 - x3)
        f -= fc
    return f, fc


@njit(cache=True)
def _deriv(p, s, u, x0, x1, x2, x3, mm, ml, flex):
    f, fc = _nonfriction(p, u, x0, x1, x2, x3, flex)
    al = fc / ml if flex else 0.0
    if s == 0:
        return 0.0, 0.0, x3, al
    if s > 0:
        fr = p[P_FV_POS] * x1 + p[P_FC_POS]
    else:
        fr = p[P_FV_NEG] * x1 - p[P_FC_NEG]
    if p[P_FS] != 0.0:
        r = x1 / p[P_VS]
        fr += s * p[P_FS] * math.exp(-r * r)
    return x1, (f - fr) / mm, x3, al


@njit(cache=True)
def _rk4(p, s, u, x0, x1, x2, x3, h, mm, ml, flex):
    a0, a1, a2, a3 = _deriv(p, s, u, x0, x1, x2, x3, mm, ml, flex)
    hh = 0.5 * h
    b0, b1, b2, b3 = _deriv(p, s, u, x0 + hh * a0, x1 + hh * a1, x2 + hh * a2, x3 + hh * a3, mm, ml, flex)
    c0, c1, c2, c3 = _deriv(p, s, u, x0 + hh * b0, x1 + hh * b1, x2 + hh * b2, x3 + hh * b3, mm, ml, flex)
    d0, d1, d2, d3 = _deriv(p, s, u, x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3, mm, ml, flex)
    h6 = h / 6.0
    return (x0 + h6 * (a0 + 2.0 * b0 + 2.0 * c0 + d0), x1 + h6 * (a1 + 2.0 * b1 + 2.0 * c1 + d1),
            x2 + h6 * (a2 + 2.0 * b2 + 2.0 * c2 + d2), x3 + h6 * (a3 + 2.0 * b3 + 2.0 * c3 + d3))


@njit(cache=True)
def _direction(p, u, x0, x1, x2, x3, flex):
    """Friction direction for the next step (sliding sign, or the Karnopp stick/slip decision)."""
    if x1 > p[P_VEPS]:
        return 1
    if x1 < -p[P_VEPS]:
        return -1
    f, _ = _nonfriction(p, u, x0, x1, x2, x3, flex)
    if f > p[P_FC_POS] + p[P_FS]:
        return 1
    if f < -(p[P_FC_NEG] + p[P_FS]):
        return -1
    return 0


@njit(cache=True)
def _masses(p, t, flex):
    """Motor-side and load-side mass at time ``t`` (the payload change lands on the load; rigid: load mass unused)."""
    dm = p[P_DM] if t >= p[P_TCH] - 1e-12 else 0.0
    if flex:
        return (1.0 - p[P_FLEX_R]) * p[P_M], p[P_FLEX_R] * p[P_M] + dm
    return p[P_M] + dm, 1.0


@njit(cache=True)
def _acceleration(p, u, x0, x1, x2, x3, mm, ml, flex):
    """Motor-side acceleration of the state under force ``u`` (0 when the axis sticks)."""
    s = _direction(p, u, x0, x1, x2, x3, flex)
    if s == 0:
        return 0.0
    return _deriv(p, s, u, x0, x1, x2, x3, mm, ml, flex)[1]


@njit(cache=True)
def _step(p, u, x0, x1, x2, x3, h, mm, ml, flex):
    s = _direction(p, u, x0, x1, x2, x3, flex)
    if s == 0:
        x1 = 0.0
    y0, y1, y2, y3 = _rk4(p, s, u, x0, x1, x2, x3, h, mm, ml, flex)
    if s != 0 and y1 * s < 0.0:
        th = x1 / (x1 - y1)
        if th < 0.0:
            th = 0.0
        elif th > 1.0:
            th = 1.0
        y0, y1, y2, y3 = _rk4(p, s, u, x0, x1, x2, x3, th * h, mm, ml, flex)
        y1 = 0.0
        s2 = _direction(p, u, y0, y1, y2, y3, flex)
        y0, y1, y2, y3 = _rk4(p, s2, u, y0, y1, y2, y3, (1.0 - th) * h, mm, ml, flex)
        if s2 == 0 or y1 * s2 < 0.0:
            y1 = 0.0
    return y0, y1, y2, y3


@njit(cache=True)
def _lin(x0, v0, g, k, h):
    """One RK4 step of ``x' = v, v' = g - k*v``, its four stages summed in closed form.

    For this linear, autonomous system the classical RK4 update is exactly
    ``v1 = v0 + h*a*w``, ``x1 = x0 + h*v0 + h**2*b*w`` with ``w = g - k*v0``,
    ``a = 1 - kh/2 + (kh)**2/6 - (kh)**3/24`` and ``b = 1/2 - kh/6 + (kh)**2/24``:
    the same step as :func:`_rk4`, up to round-off, at a fraction of the cost.
    """
    kh = k * h
    b = 0.5 - kh * (1.0 / 6.0 - kh / 24.0)
    a = 1.0 - kh * b
    w = g - k * v0
    return x0 + h * v0 + (h * h * b) * w, v0 + (h * a) * w


L_FC, L_INVM, L_K, L_HA, L_HB, L_P1, L_P2, L_P3 = range(8)
"""Layout of the last axis of :func:`_linear_coefficients`."""


@njit(cache=True)
def _linear_coefficients(p, h, substeps):
    """Step coefficients of the linear (rigid, no smooth effect) axis, ``cf[r, d, :]``.

    ``r``: 0 before the payload change, 1 after; ``d``: 0 sliding forwards, 1
    backwards. Per substep (:func:`_lin` with ``g = (f - cf[L_FC])*cf[L_INVM]``,
    ``k = cf[L_K]``): ``w = g - k*v``, ``v += cf[L_HA]*w``, ``x += h*v + cf[L_HB]*w``.
    Over the ``substeps`` steps of a period without a change of direction
    (the acceleration ``w`` then decays geometrically, ``w_j = A**j*w_0`` with
    ``A = 1 - k*cf[L_HA]``): ``v_N = v_0 + cf[L_P1]*w_0``,
    ``x_N = x_0 + N*h*v_0 + cf[L_P2]*w_0``, ``v_(N-1) = v_0 + cf[L_P3]*w_0``.
    """
    cf = np.empty((2, 2, 8))
    for r in range(2):
        mm = p[P_M] + (p[P_DM] if r == 1 else 0.0)
        for d in range(2):
            fv = p[P_FV_POS] if d == 0 else p[P_FV_NEG]
            k = fv / mm
            kh = k * h
            bb = 0.5 - kh * (1.0 / 6.0 - kh / 24.0)
            ha = h * (1.0 - kh * bb)
            hb = h * h * bb
            A = 1.0 - k * ha
            sj, q, s_last = 0.0, 0.0, 0.0
            for _ in range(substeps):  # sj = sum_{i<j} A**i, q = sum_{j<N} sj
                q += sj
                s_last = sj
                sj = sj * A + 1.0
            cf[r, d, L_FC] = p[P_FC_POS] if d == 0 else -p[P_FC_NEG]
            cf[r, d, L_INVM] = 1.0 / mm
            cf[r, d, L_K] = k
            cf[r, d, L_HA] = ha
            cf[r, d, L_HB] = hb
            cf[r, d, L_P1] = ha * sj
            cf[r, d, L_P2] = h * ha * q + hb * sj
            cf[r, d, L_P3] = ha * s_last
            if not A > 0.0:  # not monotone (a huge step): no composed period (P1 = NaN disables it)
                cf[r, d, L_P1] = np.nan
    return cf


@njit(cache=True)
def _linear_period(x0, x1, f, s_rest, tk, h, substeps, tch, veps, cf):
    """The substeps of one period on the rigid axis without smooth effects (``_step`` specialised).

    With no Stribeck term, ripple, spring or flexibility the motion between
    friction-direction changes is linear with a constant force ``f`` (control
    minus offset), so each RK4 step is :func:`_lin`. ``s_rest`` is the
    stick/slip decision at rest (constant over the period: ``f`` is); ``cf``
    from :func:`_linear_coefficients`. A period that slides in one direction
    throughout (``|v| > veps`` at the start of every substep, no sign change
    at its end; the velocity is monotone over it) is done in one composed
    step; otherwise substep by substep, as :func:`_step`.
    """
    r0 = 1 if tk >= tch - 1e-12 else 0
    if r0 == (1 if tk + (substeps - 1) * h >= tch - 1e-12 else 0) and (x1 > veps or x1 < -veps):
        d = 0 if x1 > 0.0 else 1
        s = 1.0 if d == 0 else -1.0
        w = (f - cf[r0, d, L_FC]) * cf[r0, d, L_INVM] - cf[r0, d, L_K] * x1
        vn = x1 + cf[r0, d, L_P1] * w
        if (x1 + cf[r0, d, L_P3] * w) * s > veps and vn * s >= 0.0:
            return x0 + (substeps * h) * x1 + cf[r0, d, L_P2] * w, vn
    for j in range(substeps):
        r = 1 if tk + j * h >= tch - 1e-12 else 0
        if x1 > veps:
            s = 1
        elif x1 < -veps:
            s = -1
        else:
            s = s_rest
        if s == 0:
            x1 = 0.0
            continue
        d = 0 if s > 0 else 1
        g = (f - cf[r, d, L_FC]) * cf[r, d, L_INVM]
        k = cf[r, d, L_K]
        w = g - k * x1
        y1 = x1 + cf[r, d, L_HA] * w
        if y1 * s >= 0.0:
            x0 = x0 + h * x1 + cf[r, d, L_HB] * w
            x1 = y1
            continue
        # the velocity changes sign within the step: as _step
        th = x1 / (x1 - y1)
        if th < 0.0:
            th = 0.0
        elif th > 1.0:
            th = 1.0
        x0, y1 = _lin(x0, x1, g, k, th * h)
        x1 = 0.0
        if s_rest != 0:
            d = 0 if s_rest > 0 else 1
            x0, x1 = _lin(x0, 0.0, (f - cf[r, d, L_FC]) * cf[r, d, L_INVM], cf[r, d, L_K], (1.0 - th) * h)
            if x1 * s_rest < 0.0:
                x1 = 0.0
    return x0, x1


@njit(cache=True)
def _rest(f, static_pos, static_neg):
    """Stick/slip decision at rest under the net force ``f`` (constant over a period)."""
    return 1 if f > static_pos else (-1 if f < static_neg else 0)


@njit(cache=True)
def _linear_acceleration(p, f, x1, tk, static_pos, static_neg, veps, cf):
    """:func:`_acceleration` of the rigid axis without smooth effects (net force ``f``), from the step coefficients."""
    s = 1 if x1 > veps else (-1 if x1 < -veps else _rest(f, static_pos, static_neg))
    if s == 0:
        return 0.0
    r, d = (1 if tk >= p[P_TCH] - 1e-12 else 0), (0 if s > 0 else 1)
    return (f - cf[r, d, L_FC]) * cf[r, d, L_INVM] - cf[r, d, L_K] * x1


@njit(cache=True)
def _substeps(p, u, x0, x1, x2, x3, tk, h, nsub, flex):
    """``nsub`` steps of ``h`` from ``tk`` under the constant force ``u`` (general path, :func:`_step`)."""
    for j in range(nsub):
        mm, ml = _masses(p, tk + j * h, flex)
        x0, x1, x2, x3 = _step(p, u, x0, x1, x2, x3, h, mm, ml, flex)
    return x0, x1, x2, x3


@njit(cache=True)
def run_periods(k0, k1, x, cs, q_r, qd_r, qdd_r, pulses, noise_q, p, c, chi, substeps, T,
                out_q, out_u, out_vir, out_qtrue, out_qd, out_qdd):
    """Advance the closed loop over periods ``k0 <= k < k1``.

    ``x`` (motor q, qd, load q, qd) and ``cs`` (previous measured q, previous
    filtered q, previous PD output, initialised flag) are updated in place.
    Per period ``k`` the outputs get the measured position, the applied force
    and control signal, and the plant's (motor) position, velocity and
    acceleration at ``t_k`` (the acceleration with the new force applied,
    ``t_k+``). Returns -1, or the index of the first period whose state is
    not finite.
    """
    flex = p[P_FLEX_K] > 0.0
    h = T / substeps
    x0, x1, x2, x3 = x[0], x[1], x[2], x[3]
    pd = c[C_KIND] == 1.0
    exact_vel = c[C_EXACT_VEL] == 1.0
    res = p[P_RES]
    fmax = p[P_FMAX]
    # rigid axis without smooth effects: the closed-form RK4 step (_linear_period)
    linear = not flex and p[P_FS] == 0.0 and p[P_RIP_A] == 0.0 and p[P_K] == 0.0
    cf = _linear_coefficients(p, h, substeps)
    veps = p[P_VEPS]
    static_pos = p[P_FC_POS] + p[P_FS]
    static_neg = -(p[P_FC_NEG] + p[P_FS])
    # drive lag = lag_n periods + phi: the force switches to the (lagged) new command at tk + phi
    lag_n, phi = -1, 0.0
    n1, n2, h1, h2 = 0, 0, h, h
    cf1, cf2 = cf, cf
    if p[P_LAG] > 0.0:
        lag_n = int(math.floor(p[P_LAG] / T + 1e-9))
        phi = p[P_LAG] - lag_n * T
        if phi < 1e-9 * T:
            phi = 0.0
        else:
            n1 = min(max(1, int(round(substeps * phi / T))), max(substeps - 1, 1))
            n2 = max(substeps - n1, 1)
            h1, h2 = phi / n1, (T - phi) / n2
            cf1, cf2 = _linear_coefficients(p, h1, n1), _linear_coefficients(p, h2, n2)
    ramp = c[C_PULSE_RAMP] == 1.0
    for k in range(k0, k1):
        du = 0.0  # change of the applied force over the period (pulses ramped between control instants)
        qm = x0 + noise_q[k]
        if res > 0.0:
            qm = math.floor(qm / res + 0.5) * res
        if cs[3] == 0.0:
            cs[0] = qm
            cs[1] = qm
            cs[2] = 0.0
            cs[3] = 1.0
        if pd:
            qfm = 0.5 * qm + 0.5 * cs[0]
            qdm = (qfm - cs[1]) / T
            v = c[C_PD_KV] * (c[C_PD_KP] * (q_r[k] - qm) - qdm)
            vd = cs[2]
            if vd > c[C_VMAX]:
                vd = c[C_VMAX]
            elif vd < -c[C_VMAX]:
                vd = -c[C_VMAX]
            vir = vd + pulses[k]
            u = c[C_GTAU] * vir
            if ramp and k + 1 < len(pulses):
                du = c[C_GTAU] * (pulses[k + 1] - pulses[k])
            cs[1] = qfm
            cs[2] = v
        else:
            qd_hat = x1 if exact_vel else (qm - cs[0]) / T
            w = c[C_KP] * (q_r[k] - qm) + c[C_KV] * (qd_r[k] - qd_hat) + qdd_r[k]
            sg = TWO_OVER_PI * math.atan(c[C_ALPHA] * qd_r[k])
            if c[C_ASYM] != 0.0:
                P = 0.5 * (1.0 + sg)
                N = 0.5 * (1.0 - sg)
                u = chi[0] * w + (chi[4] * qd_r[k] + chi[5] * sg) * P + (chi[6] * qd_r[k] + chi[7] * sg) * N
            else:
                u = chi[0] * w + chi[1] * qd_r[k] + chi[2] * sg + chi[3]
            vir = u
        cs[0] = qm
        if u > fmax:
            u = fmax
        elif u < -fmax:
            u = -fmax
        out_q[k] = qm
        out_u[k] = u
        out_vir[k] = vir
        out_qtrue[k] = x0
        out_qd[k] = x1
        tk = k * T
        ua = ub = u  # force on the axis over [tk, tk + phi) and [tk + phi, tk + T)
        if lag_n >= 0:  # drive lag: the commands lag_n (+1) periods back
            ub = out_u[max(k - lag_n, 0)]
            ua = out_u[max(k - lag_n - 1, 0)] if phi > 0.0 else ub
        if du != 0.0:  # pulses ramped within the period: force changes every substep (general path; no drive lag)
            mm, ml = _masses(p, tk, flex)
            out_qdd[k] = _acceleration(p, u, x0, x1, x2, x3, mm, ml, flex)
            for j in range(substeps):
                uj = min(max(u + du * (j / substeps), -fmax), fmax)
                mm, ml = _masses(p, tk + j * h, flex)
                x0, x1, x2, x3 = _step(p, uj, x0, x1, x2, x3, h, mm, ml, flex)
            if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2) and math.isfinite(x3)):
                x[0], x[1], x[2], x[3] = x0, x1, x2, x3
                return k
            continue
        if linear:
            fa = ua - p[P_OFFSET]
            out_qdd[k] = _linear_acceleration(p, fa, x1, tk, static_pos, static_neg, veps, cf)
            if phi > 0.0:
                x0, x1 = _linear_period(x0, x1, fa, _rest(fa, static_pos, static_neg), tk, h1, n1, p[P_TCH], veps, cf1)
                fb = ub - p[P_OFFSET]
                x0, x1 = _linear_period(x0, x1, fb, _rest(fb, static_pos, static_neg), tk + phi, h2, n2, p[P_TCH], veps, cf2)
            else:
                x0, x1 = _linear_period(x0, x1, fa, _rest(fa, static_pos, static_neg), tk, h, substeps, p[P_TCH], veps, cf)
            if not (math.isfinite(x0) and math.isfinite(x1)):
                x[0], x[1], x[2], x[3] = x0, x1, x2, x3
                return k
            continue
        mm, ml = _masses(p, tk, flex)
        out_qdd[k] = _acceleration(p, ua, x0, x1, x2, x3, mm, ml, flex)
        if phi > 0.0:
            x0, x1, x2, x3 = _substeps(p, ua, x0, x1, x2, x3, tk, h1, n1, flex)
            x0, x1, x2, x3 = _substeps(p, ub, x0, x1, x2, x3, tk + phi, h2, n2, flex)
        else:
            x0, x1, x2, x3 = _substeps(p, ub, x0, x1, x2, x3, tk, h, substeps, flex)
        if not (math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2) and math.isfinite(x3)):
            x[0], x[1], x[2], x[3] = x0, x1, x2, x3
            return k
    x[0], x[1], x[2], x[3] = x0, x1, x2, x3
    return -1


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


# ---------------------------------------------------------------------------
# drivers
# ---------------------------------------------------------------------------
TAU_SENSORS = ("centred", "command")
"""How the logged force samples the held drive force: ``centred`` = mean over the
sample interval centred on ``t_k`` (an integrating sensor; removes the half-period
misalignment of a zero-order hold against the reference), ``command`` = the value
applied from ``t_k`` (``gtau*vir``, the benchmark's definition)."""


@dataclass
class LoopResult:
    """Samples of one closed-loop run (all arrays of length n)."""

    t: np.ndarray
    q: np.ndarray
    q_true: np.ndarray
    qd_true: np.ndarray
    qdd_true: np.ndarray
    u: np.ndarray
    vir: np.ndarray
    tau: np.ndarray
    chi: np.ndarray
    names: tuple[str, ...]
    windows: list[Any] = field(default_factory=list)


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


def measured_force(u: np.ndarray, T: float, n: int, effects: Effects, sensor: str, noise_tau: np.ndarray, start: int = 0) -> np.ndarray:
    """The logged force of samples ``start .. n-1``: held force seen by the sensor, delayed, plus noise."""
    delay = effects["delay"].measurement_s if "delay" in effects else 0.0  # type: ignore[attr-defined]
    width = T if sensor == "centred" else 0.0
    u = np.ascontiguousarray(u, dtype=np.float64)
    noise = np.ascontiguousarray(noise_tau, dtype=np.float64)
    if len(u) == 0 or len(noise) < n:  # degenerate input: the reference form (its errors)
        times = np.arange(start, n) * T - delay
        return held_signal(u, T, times, width) + noise_tau[start:n]
    out = np.empty(max(n - start, 0))
    _sensed(u, float(T), int(start), int(n), float(delay), float(width), noise, out)
    return out


def draw_noise(n: int, seed: int, effects: Effects) -> tuple[np.ndarray, np.ndarray]:
    """Force and position noise, drawn up front from PCG64(seed): force first, then position."""
    e = effects.get("noise")
    tau_std = e.tau_std if e is not None else 0.0  # type: ignore[attr-defined]
    q_std = e.q_std if e is not None else 0.0  # type: ignore[attr-defined]
    if tau_std == 0.0 and q_std == 0.0:  # no noise: nothing to draw
        return np.zeros(n), np.zeros(n)
    rng = np.random.Generator(np.random.PCG64(seed))
    n_tau = rng.standard_normal(n)
    if q_std == 0.0:
        return n_tau * tau_std, np.zeros(n)
    n_q = rng.standard_normal(n)
    return n_tau * tau_std, n_q * q_std


def simulate_loop(*, q_r: np.ndarray, qd_r: np.ndarray, qdd_r: np.ndarray, params: RigidParameters, effects: Effects,
                  controller: CTCSettings | PDSettings, fs_hz: float = 1000.0, substeps: int = 10, seed: int = 0,
                  qd_log: np.ndarray | None = None, qdd_log: np.ndarray | None = None, pulses: np.ndarray | None = None,
                  tau_sensor: str = "centred", chi_schedule: np.ndarray | None = None, x0: tuple[float, float] | None = None,
                  progress: Callable[[int, int], None] | None = None) -> LoopResult:
    """Run the closed loop over ``len(q_r)`` control periods.

    Parameters
    ----------
    q_r, qd_r, qdd_r : ndarray
        Reference used by the controller at each sample (PD: only ``q_r``).
    params, effects : plant parameters and effects.
    controller : CTCSettings or PDSettings
        With ``CTCSettings.ilic`` the parameters are re-estimated online every
        ``window_s`` by :func:`ilic_cli.idim_ilic.estimate_window` on the
        window's logged reference (``qd_log, qdd_log``, default ``qd_r, qdd_r``)
        and measured force, and updated by
        :func:`ilic_cli.idim_ilic.update_parameters` (essential ones only).
    chi_schedule : ndarray (n, b), optional
        CTC parameters in force at each sample (replaying a logged controller);
        disables the online update.
    tau_sensor : ``centred`` or ``command`` (see :data:`TAU_SENSORS`).
    x0 : (q, qd), optional
        Initial state; default on the reference, ``(q_r[0], qd_r[0])``, with
        the controller's memory (previous measured position) consistent with it.
    """
    from ilic_cli.idim_ilic import ILICSettings, estimate_window, update_parameters
    from ilic_cli.regressor import get_model

    n = len(q_r)
    if n < 2:
        raise SimulationError("--duration", "the simulation needs at least two control periods")
    if not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise SimulationError("--substeps", f"must be a positive integer (got {substeps})")
    if tau_sensor not in TAU_SENSORS:
        raise SimulationError("--tau-sensor", f"unknown sensor '{tau_sensor}' (choose from {', '.join(TAU_SENSORS)})")
    controller.validate()
    if isinstance(controller, PDSettings) and controller.pulse_input == "ramp" and "delay" in effects and effects["delay"].drive_lag_s > 0:  # type: ignore[attr-defined]
        raise SimulationError("--effect", "a drive lag (negative delay) cannot be combined with ramped pulses (pulse_input=\"ramp\", --published-setup)")
    T = 1.0 / fs_hz
    p = plant_vector(params, effects)
    c = controller.vector()
    q_r, qd_r, qdd_r = (np.ascontiguousarray(a, dtype=np.float64) for a in (q_r, qd_r, qdd_r))
    qd_log = qd_r if qd_log is None else np.asarray(qd_log, dtype=np.float64)
    qdd_log = qdd_r if qdd_log is None else np.asarray(qdd_log, dtype=np.float64)
    pul = np.zeros(n) if pulses is None else np.ascontiguousarray(pulses, dtype=np.float64)
    noise_tau, noise_q = draw_noise(n, seed, effects)
    if x0 is None:
        x0 = (float(q_r[0]), float(qd_r[0]))
    x = np.array([x0[0], x0[1], x0[0], x0[1]], dtype=np.float64)
    # controller memory as if the axis had been moving at qd0 before t = 0
    q_prev = x0[0] - x0[1] * T
    cs = np.array([q_prev, q_prev, 0.0, 1.0])
    out_q, out_u, out_vir, out_qt, out_qd, out_qdd = (np.zeros(n) for _ in range(6))

    if isinstance(controller, CTCSettings):
        model = get_model(controller.model)
        names = model.names
        init = controller.initial()
        chi = np.array([init[nm] for nm in names], dtype=np.float64)
    else:
        model, names, chi = None, (), np.zeros(0)
    chi_hist = np.zeros((len(names), n)).T  # (n, b), each parameter's history contiguous (the log's channels)
    windows: list[Any] = []

    def run(a: int, b: int, chi_now: np.ndarray) -> None:
        chi8 = chi_vector(names, chi_now) if len(names) else np.zeros(8)
        bad = run_periods(a, b, x, cs, q_r, qd_r, qdd_r, pul, noise_q, p, c, chi8, int(substeps), T, out_q, out_u, out_vir, out_qt, out_qd,
                           out_qdd)
        if bad >= 0:
            raise SimulationError("simulation", f"the closed loop diverged at t = {bad * T:.6g} s (non-finite state); check the parameters and gains")

    if isinstance(controller, CTCSettings) and chi_schedule is not None:
        sched = np.asarray(chi_schedule, dtype=np.float64)
        change = np.flatnonzero(np.any(np.diff(sched, axis=0) != 0, axis=1)) + 1
        bounds = [0, *change.tolist(), n]
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            run(a, b, sched[a])
        chi_hist[:] = sched
    elif isinstance(controller, CTCSettings) and controller.ilic:
        settings = ILICSettings(window_s=controller.window_s, cutoff_hz=controller.cutoff_hz, sigma_max_pct=controller.sigma_max_pct)
        nwin = int(round(controller.window_s * fs_hz))
        a, k = 0, 1
        while a < n:
            b = min(a + nwin, n)
            run(a, b, chi)
            chi_hist[a:b] = chi
            if b - a == nwin:
                tau_w = measured_force(out_u[:b], T, b, effects, tau_sensor, noise_tau[:b], start=a)
                est = estimate_window(model, qd_log[a:b], qdd_log[a:b], tau_w, fs_hz, settings,  # type: ignore[arg-type]
                                      q_ref=q_r[a:b], q=out_q[a:b], t=np.arange(a, b) * T, k=k)
                windows.append(est)
                chi = update_parameters(chi, est)
                k += 1
            if progress is not None:
                progress(b, n)
            a = b
    else:
        step = max(1, n // 50) if progress is not None else n
        for a in range(0, n, step):
            b = min(a + step, n)
            run(a, b, chi)
            if progress is not None:
                progress(b, n)
        chi_hist[:] = chi
    tau = measured_force(out_u, T, n, effects, tau_sensor, noise_tau)
    t = np.arange(n, dtype=np.float64)
    t *= T  # = np.arange(n) * T
    return LoopResult(t=t, q=out_q, q_true=out_qt, qd_true=out_qd, qdd_true=out_qdd, u=out_u, vir=out_vir, tau=tau, chi=chi_hist, names=names, windows=windows)


# ---------------------------------------------------------------------------
# logs
# ---------------------------------------------------------------------------
def loop_log(res: LoopResult, *, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray, controller: CTCSettings | PDSettings,
             params: RigidParameters, effects: Effects, fs_hz: float, substeps: int, seed: int, tau_sensor: str,
             pulses: np.ndarray | None = None, meta: dict[str, Any] | None = None) -> RunLog:
    """Build the run log of a closed-loop result.

    Channels: ``t, q`` (measured position: with the quantization and noise
    effects), ``q_ref, qd_ref, qdd_ref`` (the logged reference), ``tau`` (the
    force sensor), ``qd_plant, qdd_plant`` (the plant's own velocity and
    acceleration at the sample instants, noise-free: what a simulation is
    compared with, see ``fixtures/emps_simulation_table.json``), ``vir`` (PD),
    ``pulses`` and ``<parameter>_hat`` (CTC: the parameters in force).
    Metadata: true parameters, effects, controller, simulation settings and
    the IDIM-ILIC windows.
    """
    from ilic_cli.runlog import RunLog

    chans: dict[str, np.ndarray] = {"t": res.t, "q": res.q, "q_ref": q_ref, "qd_ref": qd_ref, "qdd_ref": qdd_ref, "tau": res.tau,
                                    "qd_plant": res.qd_true, "qdd_plant": res.qdd_true}
    units: dict[str, str] = {"qd_plant": "m/s", "qdd_plant": "m/s^2"}
    if isinstance(controller, PDSettings):
        chans["vir"] = res.vir
    if pulses is not None:
        chans["pulses"] = np.asarray(pulses, dtype=np.float64)
        units["pulses"] = "V"
    from ilic_cli.regressor import get_model

    if isinstance(controller, CTCSettings):
        model = get_model(controller.model)
        for i, name in enumerate(res.names):
            chans[f"{name}_hat"] = res.chi[:, i]
            units[f"{name}_hat"] = model.units[i]
    m: dict[str, Any] = {
        "sample_rate_hz": fs_hz,
        "true_parameters": params.to_dict(),
        "effects": effects_to_dict(effects),
        "controller": controller.to_dict(),
        "simulation": {"seed": int(seed), "substeps": int(substeps), "dt": 1.0 / fs_hz / substeps, "control_period": 1.0 / fs_hz,
                       "integrator": "RK4, fixed step, control held per period, Karnopp stick/slip with zero-crossing location",
                       "stick_velocity": STICK_VELOCITY, "tau_sensor": tau_sensor, "samples": len(res.t),
                       "duration_s": len(res.t) / fs_hz, "plant": "plant (ilic)"},
    }
    if isinstance(controller, PDSettings):
        m["drive_gain"] = controller.gtau
    if res.windows:
        m["ilic_windows"] = [w.to_dict() for w in res.windows]
    m.update(meta or {})
    return RunLog(chans, units, m)


CTC_REPLAY_KEYS = ("omega", "xi", "alpha", "model", "window_s", "sigma_max_pct", "cutoff_hz", "velocity")
"""CTC settings a replay takes over from the log (the parameters come from its ``*_hat`` channels or the model)."""


def _controller_from_log(log: RunLog) -> CTCSettings | PDSettings:
    ctl = dict(log.meta.get("controller") or {})
    kind = str(ctl.get("kind", "")).lower()
    if kind == "pd" or (not kind and "vir" in log):
        gtau = log.meta.get("drive_gain", ctl.get("gtau"))
        try:
            return PDSettings(kp=float(ctl.get("kp", log.meta.get("kp"))), kv=float(ctl.get("kv", log.meta.get("kv"))),
                              gtau=float(gtau), vmax=float(ctl.get("vmax", 10.0)), pulse_input=str(ctl.get("pulse_input", "held")))
        except (TypeError, ValueError):
            raise SimulationError(log.meta.get("source"), "the log's PD controller lacks kp, kv or drive_gain in its metadata") from None
    kw = {k: ctl[k] for k in CTC_REPLAY_KEYS if k in ctl}
    return CTCSettings(**kw, ilic=False)


def simulate_replay(log: RunLog, params: RigidParameters | dict[str, float], effects: Effects | dict[str, Any] | None = None,
                    controller: CTCSettings | PDSettings | None = None, *, substeps: int = 10, seed: int = 0,
                    tau_sensor: str | None = None, clock_s: float | None = None) -> RunLog:
    """Replay ``log``'s recorded reference (and pulses) through the plant; return the simulated log.

    Parameters
    ----------
    log : RunLog
        Needs ``t`` and ``q_ref`` (``qd_ref, qdd_ref`` are used when present,
        else central differences of ``q_ref``); ``pulses`` are added to the PD
        output as in the benchmark. A log written by ``ilic simulate`` carries
        its trajectory in ``meta["scenario"]["trajectory"]``: the controller
        then gets the exact point reference it had (the logged ``qd_ref,
        qdd_ref`` are centred averages, see ``plant.trajectories``).
    params : RigidParameters or dict
        Plant parameters ``M, Fv, Fc, offset``; with ``Fv_pos/Fc_pos/Fv_neg/Fc_neg``
        in the dict the ``asymmetric_friction`` effect is made from them.
    effects : dict
        Effect id -> parameters or :class:`~plant.dynamics.Effect`.
    controller : CTCSettings or PDSettings, optional
        Default: the log's controller (``meta["controller"]``): PD with its
        ``kp, kv`` and ``drive_gain``; otherwise CTC with the log's gains and,
        when the log has ``*_hat`` channels, the parameters in force at each
        sample (else the given plant parameters, no online update).
    substeps, seed : integration substeps per period; noise seed.
    tau_sensor : ``centred`` or ``command``; default ``command`` for PD
        (``tau = gtau*vir``), ``centred`` for CTC.
    clock_s : float, optional
        Control period of the replay; default the log's sample period. With
        another period the reference (and pulses) are interpolated linearly
        at ``k*clock_s`` and the result is on that clock, sample ``k`` for
        sample ``k`` of the log (the published benchmark simulation ran its
        controller at ``t(10) - t(9)`` of the file, see ``plant.scenarios``).

    Returns
    -------
    RunLog
        Same time base; ``q`` simulated, ``q_ref`` etc. from the log, ``tau``
        simulated (and ``vir`` for PD); metadata as ``ilic simulate`` with
        ``meta["replay_of"]`` the source.
    """
    from ilic_cli.filtering import central_difference

    eff = make_effects(effects) if not all(isinstance(v, Effect) for v in (effects or {}).values()) else dict(effects or {})
    if isinstance(params, dict):
        pd_ = {k: float(v) for k, v in params.items()}
        asym = {k: pd_.pop(k) for k in ("Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg") if k in pd_}
        if asym:
            if len(asym) != 4:
                raise SimulationError("--model", "asymmetric friction needs all of Fv_pos, Fc_pos, Fv_neg, Fc_neg")
            eff.setdefault("asymmetric_friction", AsymmetricFriction(**asym))
            pd_.setdefault("Fv", 0.0)
            pd_.setdefault("Fc", 0.0)
        if "M" not in pd_:
            raise SimulationError("--model", "the model has no mass M")
        unknown = sorted(set(pd_) - set(RigidParameters.NAMES))
        if unknown:
            raise SimulationError("--model", f"unknown plant parameter(s) {', '.join(unknown)} (known: M, Fv, Fc, offset, Fv_pos, Fc_pos, Fv_neg, Fc_neg)")
        params = RigidParameters(**pd_)
    log.require("t", "q_ref")
    ctl = controller or _controller_from_log(log)
    fs = 1.0 / log.dt_s
    q_ref = log["q_ref"]
    pulses = log["pulses"] if "pulses" in log else None
    resampled = clock_s is not None and clock_s != log.dt_s
    if resampled:
        if not (clock_s is not None and math.isfinite(clock_s) and clock_s > 0):
            raise SimulationError("--clock", f"the control period must be a positive number of seconds (got {clock_s})")
        fs = 1.0 / clock_s
        grid = np.arange(len(log), dtype=np.float64) * clock_s + float(log.t[0])
        q_ref = np.interp(grid, log.t, q_ref)
        pulses = None if pulses is None else np.interp(grid, log.t, pulses)
    dt = 1.0 / fs
    qd_ref = log["qd_ref"] if "qd_ref" in log and not resampled else central_difference(q_ref, dt)
    qdd_ref = log["qdd_ref"] if "qdd_ref" in log and not resampled else central_difference(qd_ref, dt)
    q_ctl, qd_ctl, qdd_ctl = q_ref, qd_ref, qdd_ref
    traj = None if resampled else _trajectory_from_meta(log, fs)
    if traj is not None:  # a log of ilic simulate: the controller's exact (point) reference
        _, q_ctl, qd_ctl, qdd_ctl = traj.sample(len(log), fs)
    sensor = tau_sensor or ("command" if isinstance(ctl, PDSettings) else "centred")
    sched = None
    if isinstance(ctl, CTCSettings):
        from ilic_cli.regressor import get_model

        names = get_model(ctl.model).names
        if all(f"{n}_hat" in log for n in names):
            sched = np.stack([log[f"{n}_hat"] for n in names], axis=1)
        else:
            ctl = CTCSettings(**{**{k: getattr(ctl, k) for k in CTC_REPLAY_KEYS},
                                 "ilic": False, "chi0": {n: getattr(params, n, 0.0) for n in names if n in RigidParameters.NAMES}})
    x0 = None
    if "q" in log and isinstance(ctl, PDSettings):
        # start where the recording starts: measured position, velocity of its first samples
        q_meas = log["q"]
        v0 = float((q_meas[min(2, len(q_meas) - 1)] - q_meas[0]) / (min(2, len(q_meas) - 1) * dt)) if len(q_meas) > 1 else 0.0
        x0 = (float(q_meas[0]), v0)
    res = simulate_loop(q_r=q_ctl, qd_r=qd_ctl, qdd_r=qdd_ctl, qd_log=qd_ref, qdd_log=qdd_ref, params=params, effects=eff, controller=ctl, fs_hz=fs, substeps=substeps,
                        seed=seed, pulses=pulses, tau_sensor=sensor, chi_schedule=sched, x0=x0)
    res.t = grid if resampled else np.asarray(log.t, dtype=np.float64).copy()
    meta: dict[str, Any] = {"replay_of": log.meta.get("source"), "scenario": {"name": "replay", "source": log.meta.get("source")}}
    if resampled:
        meta["replay_clock_s"] = clock_s
    return loop_log(res, q_ref=q_ref, qd_ref=qd_ref, qdd_ref=qdd_ref, controller=ctl, params=params, effects=eff, fs_hz=fs,
                    substeps=substeps, seed=seed, tau_sensor=sensor, pulses=pulses, meta=meta)


def _trajectory_from_meta(log: RunLog, fs: float) -> Any:
    """The exciting trajectory recorded by ``ilic simulate``, if it matches the log's samples."""
    from plant.trajectories import Trajectory

    doc = (log.meta.get("scenario") or {}).get("trajectory")
    if not isinstance(doc, dict) or "segments" not in doc:
        return None
    try:
        traj = Trajectory(tuple((float(d), float(a)) for d, a in doc["segments"]), q0=float(doc["q0"]), v0=float(doc.get("v0", 0.0)),
                          repeat=bool(doc.get("repeat", True)), t_offset=float(doc.get("t_offset", 0.0)))
        q = traj.evaluate(np.asarray(log.t, dtype=np.float64))[0]
    except (KeyError, TypeError, ValueError, SimulationError):
        return None
    return traj if np.allclose(q, log["q_ref"], rtol=0, atol=1e-12) else None
