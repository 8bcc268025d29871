"""The compiled inner loop of the closed loop: controller per period, fixed-step RK4.

One function, :func:`run_periods`, advances the closed loop over control periods ``k0 .. k1-1``. Everything it needs is in flat
float64 vectors (``plant.dynamics.plant_vector``, ``plant.controllers`` ``vector()``), so it compiles once with numba
(``cache=True``: the machine code is cached in ``__pycache__``; the first compile takes a few seconds).

How it integrates (the Karnopp stick/slip rule and its zero crossings, the closed-form step of the rigid axis, the
smoothed Coulomb friction, the PD law inside the dynamics) and how the effects are compiled: docs/simulation.md,
"The compiled loop".
The force and the derivative are inlined at numba's level (``inline="always"``): docs/simulation.md, "Speed".
"""

from __future__ import annotations

import math

import numpy as np

from ilic_cli.jit import njit
from ilic_cli.parameters import STANDARD_GRAVITY
from plant.controllers import (
    C_ALPHA,
    C_ASYM,
    C_EXACT_VEL,
    C_GTAU,
    C_KIND,
    C_KP,
    C_KV,
    C_PD_CONTINUOUS,
    C_PD_KP,
    C_PD_KV,
    C_PD_SAME,
    C_PD_VELOCITY,
    C_PULSE_RAMP,
    C_VMAX,
)
from plant.dynamics import (
    N_PLANT,
    P_CL_BW,
    P_DM,
    P_DR_DFC,
    P_DR_DFV,
    P_DR_RFC,
    P_DR_RFV,
    P_DR_TAU,
    P_FC_NEG,
    P_FC_POS,
    P_FLEX_C,
    P_FLEX_K,
    P_FLEX_R,
    P_FMAX,
    P_FS,
    P_FV_NEG,
    P_FV_POS,
    P_K,
    P_LAG,
    P_M,
    P_MX,
    P_MY,
    P_OFFSET,
    P_Q0,
    P_RES,
    P_RIP_A,
    P_RIP_L,
    P_RIP_PH,
    P_TCH,
    P_VC,
    P_VEPS,
    P_VS,
)
from plant.kernel_linear import linear_acceleration, linear_coefficients, linear_period, rest_direction

# A copy of this module compiled for effects without a compiled form
# (plant.generic.kernel_for) finds their summed force in _GENERIC_FORCE.
_GENERIC = globals().get("_GENERIC_FORCE")
HAS_GENERIC = _GENERIC is not None
CACHE = not HAS_GENERIC  # only the built-in kernel is cached on disk


@njit(cache=CACHE, nogil=True)
def _no_generic_force(g, q, qd, t):  # pragma: no cover - compiled away (HAS_GENERIC is False)
    return 0.0


_generic_force = _GENERIC if HAS_GENERIC else _no_generic_force

TWO_PI = 2.0 * math.pi
TWO_OVER_PI = 2.0 / math.pi


@njit(cache=CACHE, nogil=True, inline="always")
def _nonfriction(p, u, x0, x1, x2, x3, t, flex):
    """Net force on the motor side at time ``t`` without friction, and the coupling force on the load."""
    f = u - p[P_OFFSET]
    if p[P_RIP_A] != 0.0:
        f -= p[P_RIP_A] * math.sin(TWO_PI * x0 / p[P_RIP_L] + p[P_RIP_PH])
    if p[P_K] != 0.0:
        f -= p[P_K] * (x0 - p[P_Q0])
    if p[P_MX] != 0.0 or p[P_MY] != 0.0:  # gravity on a revolute link (ilic_cli.effects.GRAVITY)
        f -= STANDARD_GRAVITY * (p[P_MX] * math.cos(x0) - p[P_MY] * math.sin(x0))
    if HAS_GENERIC:
        f -= _generic_force(p[N_PLANT:], x0, x1, t)
    fc = 0.0
    if flex:
        fc = p[P_FLEX_K] * (x0 - x2) + p[P_FLEX_C] * (x1 - x3)
        f -= fc
    return f, fc


@njit(cache=CACHE, nogil=True, inline="always")
def _deriv(p, s, u, x0, x1, x2, x3, t, mm, ml, flex):
    f, fc = _nonfriction(p, u, x0, x1, x2, x3, t, flex)
    al = fc / ml if flex else 0.0
    if s == 0:
        return 0.0, 0.0, x3, al
    if p[P_VC] > 0.0:  # coulomb_smoothing: tanh(qd/vc) for the sign in every friction column, the sides weighted by it too
        th = math.tanh(x1 / p[P_VC])
        wp, wn = 0.5 * (1.0 + th), 0.5 * (1.0 - th)
        fr = (p[P_FV_POS] * wp + p[P_FV_NEG] * wn) * x1 + th * (p[P_FC_POS] * wp + p[P_FC_NEG] * wn)
        sgn = th
    elif s > 0:
        fr = p[P_FV_POS] * x1 + p[P_FC_POS]
        sgn = 1.0
    else:
        fr = p[P_FV_NEG] * x1 - p[P_FC_NEG]
        sgn = -1.0
    if p[P_FS] != 0.0:
        r = x1 / p[P_VS]
        fr += sgn * p[P_FS] * math.exp(-r * r)
    return x1, (f - fr) / mm, x3, al


@njit(cache=CACHE, nogil=True)
def _rk4(p, s, u, x0, x1, x2, x3, t, h, mm, ml, flex):
    a0, a1, a2, a3 = _deriv(p, s, u, x0, x1, x2, x3, t, mm, ml, flex)
    hh = 0.5 * h
    b0, b1, b2, b3 = _deriv(p, s, u, x0 + hh * a0, x1 + hh * a1, x2 + hh * a2, x3 + hh * a3, t + hh, mm, ml, flex)
    c0, c1, c2, c3 = _deriv(p, s, u, x0 + hh * b0, x1 + hh * b1, x2 + hh * b2, x3 + hh * b3, t + hh, mm, ml, flex)
    d0, d1, d2, d3 = _deriv(p, s, u, x0 + h * c0, x1 + h * c1, x2 + h * c2, x3 + h * c3, t + h, mm, ml, flex)
    h6 = h / 6.0
    return (
        x0 + h6 * (a0 + 2.0 * b0 + 2.0 * c0 + d0),
        x1 + h6 * (a1 + 2.0 * b1 + 2.0 * c1 + d1),
        x2 + h6 * (a2 + 2.0 * b2 + 2.0 * c2 + d2),
        x3 + h6 * (a3 + 2.0 * b3 + 2.0 * c3 + d3),
    )


@njit(cache=CACHE, nogil=True)
def _direction(p, u, x0, x1, x2, x3, t, flex):
    """Friction direction for the next step (sliding sign, or the Karnopp stick/slip decision; with ``coulomb_smoothing`` the
    axis never sticks: the velocity's sign, 1 at rest, the friction then smooth in the velocity across zero)."""
    if p[P_VC] > 0.0:
        return 1 if x1 >= 0.0 else -1
    if x1 > p[P_VEPS]:
        return 1
    if x1 < -p[P_VEPS]:
        return -1
    f, _ = _nonfriction(p, u, x0, x1, x2, x3, t, flex)
    if f > p[P_FC_POS] + p[P_FS]:
        return 1
    if f < -(p[P_FC_NEG] + p[P_FS]):
        return -1
    return 0


@njit(cache=CACHE, nogil=True)
def _masses(p, t, flex):
    """Motor-side and load-side mass at time ``t`` (the payload change lands on the load; rigid: load mass unused)."""
    dm = p[P_DM] if t >= p[P_TCH] - 1e-12 else 0.0
    if flex:
        return (1.0 - p[P_FLEX_R]) * p[P_M], p[P_FLEX_R] * p[P_M] + dm
    return p[P_M] + dm, 1.0


@njit(cache=CACHE, nogil=True)
def _acceleration(p, u, x0, x1, x2, x3, t, mm, ml, flex):
    """Motor-side acceleration of the state under force ``u`` (0 when the axis sticks)."""
    s = _direction(p, u, x0, x1, x2, x3, t, flex)
    if s == 0:
        return 0.0
    return _deriv(p, s, u, x0, x1, x2, x3, t, mm, ml, flex)[1]


@njit(cache=CACHE, nogil=True)
def _step(p, u, x0, x1, x2, x3, t, h, mm, ml, flex):
    s = _direction(p, u, x0, x1, x2, x3, t, flex)
    if s == 0:
        x1 = 0.0
    y0, y1, y2, y3 = _rk4(p, s, u, x0, x1, x2, x3, t, h, mm, ml, flex)
    if s != 0 and y1 * s < 0.0 and p[P_VC] == 0.0:  # a smoothed friction crosses zero smoothly
        th = x1 / (x1 - y1)
        if th < 0.0:
            th = 0.0
        elif th > 1.0:
            th = 1.0
        y0, y1, y2, y3 = _rk4(p, s, u, x0, x1, x2, x3, t, th * h, mm, ml, flex)
        y1 = 0.0
        s2 = _direction(p, u, y0, y1, y2, y3, t + th * h, flex)
        y0, y1, y2, y3 = _rk4(p, s2, u, y0, y1, y2, y3, t + th * h, (1.0 - th) * h, mm, ml, flex)
        if s2 == 0 or y1 * s2 < 0.0:
            y1 = 0.0
    return y0, y1, y2, y3


@njit(cache=CACHE, nogil=True)
def _substeps(p, u, x0, x1, x2, x3, tk, h, nsub, flex):
    """``nsub`` steps of ``h`` from ``tk`` under the constant force ``u`` (general path, :func:`_step`)."""
    for j in range(nsub):
        t = tk + j * h
        mm, ml = _masses(p, t, flex)
        x0, x1, x2, x3 = _step(p, u, x0, x1, x2, x3, t, h, mm, ml, flex)
    return x0, x1, x2, x3


@njit(cache=CACHE, nogil=True)
def _current_loop_substeps(p, c, y, d, x0, x1, x2, x3, tk, h, nsub, flex, tau_i):
    """``nsub`` steps of ``h`` from ``tk`` with the applied force ``y`` following the command ``c`` as a first-order lag.

    Per step the force on the axis is the exact mean of ``c + (y - c) exp(-t/tau_i)``
    over the step, plus the disturbance ``d``; ``y`` is advanced exactly (:class:`plant.blocks.CurrentLoop`).
    Returns the state and the applied force at the end.
    """
    e = math.exp(-h / tau_i)
    g = tau_i / h * (1.0 - e)
    for j in range(nsub):
        t = tk + j * h
        mm, ml = _masses(p, t, flex)
        x0, x1, x2, x3 = _step(p, c + (y - c) * g + d, x0, x1, x2, x3, t, h, mm, ml, flex)
        y = c + (y - c) * e
    return x0, x1, x2, x3, y


@njit(cache=CACHE, nogil=True)
def _drift(change, tau, rate, t):
    """:func:`ilic_cli.effects.drift_of` compiled: a friction coefficient's change at ``t``."""
    return change * (1.0 - math.exp(-t / tau)) + rate * t


@njit(cache=CACHE, nogil=True)
def _drifted(p, base, t):
    """Write the friction of the plant at ``t`` into ``p`` (``friction_drift``; ``base``: the friction slots at t = 0)."""
    dfv = _drift(p[P_DR_DFV], p[P_DR_TAU], p[P_DR_RFV], t)
    dfc = _drift(p[P_DR_DFC], p[P_DR_TAU], p[P_DR_RFC], t)
    p[P_FV_POS] = base[0] + dfv
    p[P_FV_NEG] = base[1] + dfv
    p[P_FC_POS] = max(base[2] + dfc, 0.0)
    p[P_FC_NEG] = max(base[3] + dfc, 0.0)


@njit(cache=CACHE, nogil=True)
def _lag_split(p, T, h, substeps):
    """The drive lag (``delay`` < 0) as ``lag_n`` whole periods plus ``phi``: the force switches to the lagged command at ``tk + phi``.

    Returns ``lag_n`` (-1: no lag), ``phi`` and the substeps ``n1, n2`` of ``h1, h2`` before and after the switch.
    """
    lag_n, phi = -1, 0.0
    n1, n2, h1, h2 = 0, 0, h, h
    if p[P_LAG] > 0.0:
        lag_n = int(math.floor(p[P_LAG] / T + 1e-9))
        phi = p[P_LAG] - lag_n * T
        if phi < 1e-9 * T:
            phi = 0.0
        else:
            n1 = min(max(1, int(round(substeps * phi / T))), max(substeps - 1, 1))
            n2 = max(substeps - n1, 1)
            h1, h2 = phi / n1, (T - phi) / n2
    return lag_n, phi, n1, n2, h1, h2


@njit(cache=CACHE, nogil=True)
def _command(k, x0, x1, cs, q_r, qd_r, qdd_r, pulses, noise_q, c, chi, T, res, fmax):
    """The controller of period ``k``: measured position, applied force (clipped), control signal, pulse ramp.

    PD (the benchmark's loop, ``c[C_KIND] == 1``) or CTC (the paper's eqs. 11-16); ``cs`` is updated in place.
    """
    du = 0.0  # change of the applied force over the period (pulses ramped between control instants)
    qm = x0 + noise_q[k]
    if res > 0.0:
        qm = math.floor(qm / res + 0.5) * res
    if cs[3] == 0.0:
        cs[0] = qm
        cs[1] = qm
        cs[2] = 0.0
        cs[3] = 1.0
    if c[C_KIND] == 1.0:
        qfm = qm if c[C_PD_VELOCITY] == 1.0 else 0.5 * qm + 0.5 * cs[0]  # backward, or the benchmark's averaged position
        qdm = x1 if c[C_PD_VELOCITY] == 2.0 else (qfm - cs[1]) / T  # exact: the plant's own velocity
        v = c[C_PD_KV] * (c[C_PD_KP] * (q_r[k] - (x0 if c[C_PD_CONTINUOUS] == 1.0 else qm)) - qdm)  # continuous: on the state
        vd = v if c[C_PD_SAME] == 1.0 else cs[2]  # same: computed from this sample, delayed by the drive lag (plant.controllers)
        if vd > c[C_VMAX]:
            vd = c[C_VMAX]
        elif vd < -c[C_VMAX]:
            vd = -c[C_VMAX]
        vir = vd + pulses[k]
        u = c[C_GTAU] * vir
        if c[C_PULSE_RAMP] == 1.0 and k + 1 < len(pulses):
            du = c[C_GTAU] * (pulses[k + 1] - pulses[k])
        cs[1] = qfm
        cs[2] = v
    else:
        qd_hat = x1 if c[C_EXACT_VEL] == 1.0 else (qm - cs[0]) / T
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
    return qm, u, vir, du


@njit(cache=CACHE, nogil=True)
def _current_loop_period(p, ua, ub, y, dk, x0, x1, x2, x3, tk, h, substeps, lag, flex, tau_i):
    """One period with the current loop (block state ``y``, the applied force): acceleration at ``tk+``, state, ``y``."""
    phi, n1, n2, h1, h2 = lag
    if math.isnan(y):
        y = ua
    mm, ml = _masses(p, tk, flex)
    qdd = _acceleration(p, y + dk, x0, x1, x2, x3, tk, mm, ml, flex)
    if phi > 0.0:
        x0, x1, x2, x3, y = _current_loop_substeps(p, ua, y, dk, x0, x1, x2, x3, tk, h1, n1, flex, tau_i)
        x0, x1, x2, x3, y = _current_loop_substeps(p, ub, y, dk, x0, x1, x2, x3, tk + phi, h2, n2, flex, tau_i)
    else:
        x0, x1, x2, x3, y = _current_loop_substeps(p, ub, y, dk, x0, x1, x2, x3, tk, h, substeps, flex, tau_i)
    return qdd, x0, x1, x2, x3, y


@njit(cache=CACHE, nogil=True)
def _ramped_period(p, u, du, x0, x1, x2, x3, tk, h, substeps, fmax, flex):
    """One period with the pulses ramped within it: the force changes every substep (general path; no drive lag)."""
    mm, ml = _masses(p, tk, flex)
    qdd = _acceleration(p, u, x0, x1, x2, x3, tk, mm, ml, flex)
    for j in range(substeps):
        uj = min(max(u + du * (j / substeps), -fmax), fmax)
        t = tk + j * h
        mm, ml = _masses(p, t, flex)
        x0, x1, x2, x3 = _step(p, uj, x0, x1, x2, x3, t, h, mm, ml, flex)
    return qdd, x0, x1, x2, x3


@njit(cache=CACHE, nogil=True)
def _linear_period_of(p, ua, ub, x0, x1, tk, h, substeps, lag, static, veps, cfs):
    """One period of the rigid axis without smooth effects (:mod:`plant.kernel_linear`): acceleration at ``tk+`` and ``x0, x1``."""
    phi, n1, n2, h1, h2 = lag
    static_pos, static_neg = static
    cf, cf1, cf2 = cfs
    fa = ua - p[P_OFFSET]
    qdd = linear_acceleration(p, fa, x1, tk, static_pos, static_neg, veps, cf)
    if phi > 0.0:
        x0, x1 = linear_period(x0, x1, fa, rest_direction(fa, static_pos, static_neg), tk, h1, n1, p[P_TCH], veps, cf1)
        fb = ub - p[P_OFFSET]
        x0, x1 = linear_period(x0, x1, fb, rest_direction(fb, static_pos, static_neg), tk + phi, h2, n2, p[P_TCH], veps, cf2)
    else:
        x0, x1 = linear_period(x0, x1, fa, rest_direction(fa, static_pos, static_neg), tk, h, substeps, p[P_TCH], veps, cf)
    return qdd, x0, x1


@njit(cache=CACHE, nogil=True)
def _general_period(p, ua, ub, x0, x1, x2, x3, tk, h, substeps, lag, flex):
    """One period of the general path (:func:`_step`): acceleration at ``tk+`` and the state."""
    phi, n1, n2, h1, h2 = lag
    mm, ml = _masses(p, tk, flex)
    qdd = _acceleration(p, ua, x0, x1, x2, x3, tk, mm, ml, flex)
    if phi > 0.0:
        x0, x1, x2, x3 = _substeps(p, ua, x0, x1, x2, x3, tk, h1, n1, flex)
        x0, x1, x2, x3 = _substeps(p, ub, x0, x1, x2, x3, tk + phi, h2, n2, flex)
    else:
        x0, x1, x2, x3 = _substeps(p, ub, x0, x1, x2, x3, tk, h, substeps, flex)
    return qdd, x0, x1, x2, x3


@njit(cache=CACHE, nogil=True)
def _continuous_period(p, c, u0, r0, r1, dk, x0, x1, x2, x3, tk, h, substeps, flex, fmax, hist, n, tau_i, y):
    """One period of the PD law on the state at every step (``continuous``; ``u0`` at ``tk``, logged; the reference ``r0 -> r1``): a drive
    lag of ``len(hist) - 1`` steps (``hist``: the last commands, ``n`` so far), the current loop (``tau_i``, its force ``y``)."""
    m = len(hist)
    e = math.exp(-h / tau_i) if tau_i > 0.0 else 0.0
    g = tau_i / h * (1.0 - e) if tau_i > 0.0 else 0.0
    qdd = 0.0
    for j in range(substeps):
        u = u0
        if j:
            v = c[C_PD_KV] * (c[C_PD_KP] * (r0 + (r1 - r0) * j / substeps - x0) - x1)
            u = c[C_GTAU] * min(max(v, -c[C_VMAX]), c[C_VMAX])
            u = min(max(u, -fmax), fmax)
        hist[n % m] = u
        a = hist[(n - m + 1) % m] if n >= m - 1 else hist[0]  # the command m - 1 steps back (the first before it)
        n += 1
        if tau_i > 0.0:
            if math.isnan(y):
                y = a
            f = a + (y - a) * g
            y = a + (y - a) * e
        else:
            f = a
        t = tk + j * h
        mm, ml = _masses(p, t, flex)
        if j == 0:
            qdd = _acceleration(p, f + dk, x0, x1, x2, x3, t, mm, ml, flex)
        x0, x1, x2, x3 = _step(p, f + dk, x0, x1, x2, x3, t, h, mm, ml, flex)
    return qdd, x0, x1, x2, x3, n, y


@njit(cache=CACHE, nogil=True)
def _finite(x0, x1, x2, x3):
    return math.isfinite(x0) and math.isfinite(x1) and math.isfinite(x2) and math.isfinite(x3)


@njit(cache=CACHE, nogil=True)
def run_periods(k0, k1, x, cs, q_r, qd_r, qdd_r, pulses, noise_q, p, c, chi, substeps, T, out_q, out_u, out_vir, out_qtrue, out_qd, out_qdd, dist):
    """Advance the closed loop over periods ``k0 <= k < k1``.

    ``dist`` is the disturbance force on the axis per period (zeros: none): always an array, so that numba compiles
    one signature (one for each way of calling it: ``None``, an array, left out; some 3 s of CPU each).
    ``current_loop``: the applied force lags the command
    (:func:`_current_loop_period`); ``x`` then has a fifth entry, that force
    (NaN before the first period: the first command).
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
    # friction drift: a copy of the plant vector whose friction follows the time, piecewise constant over each
    # period at its middle (the drift is slow: seconds against the period's milliseconds)
    drift = p[P_DR_DFV] != 0.0 or p[P_DR_DFC] != 0.0 or p[P_DR_RFV] != 0.0 or p[P_DR_RFC] != 0.0
    base = np.array([p[P_FV_POS], p[P_FV_NEG], p[P_FC_POS], p[P_FC_NEG]])
    if drift:
        p = p.copy()
    fmax = p[P_FMAX]
    # rigid axis without smooth effects: the closed-form RK4 step (plant.kernel_linear)
    linear = (
        not flex
        and p[P_FS] == 0.0
        and p[P_RIP_A] == 0.0
        and p[P_K] == 0.0
        and p[P_MX] == 0.0
        and p[P_MY] == 0.0
        and p[P_VC] == 0.0
        and not drift
        and not HAS_GENERIC
    )
    cf = linear_coefficients(p, h, substeps)
    static = (p[P_FC_POS] + p[P_FS], -(p[P_FC_NEG] + p[P_FS]))
    lag_n, phi, n1, n2, h1, h2 = _lag_split(p, T, h, substeps)
    lag = (phi, n1, n2, h1, h2)
    cfs = (cf, linear_coefficients(p, h1, n1), linear_coefficients(p, h2, n2)) if phi > 0.0 else (cf, cf, cf)
    tau_i = 1.0 / (TWO_PI * p[P_CL_BW]) if p[P_CL_BW] > 0.0 else 0.0
    y = x[4] if len(x) > 4 else math.nan
    continuous = c[C_KIND] == 1.0 and c[C_PD_CONTINUOUS] == 1.0
    hist = np.zeros(int(round(p[P_LAG] / h)) + 1)  # continuous: the commands of the drive lag's steps
    n_steps = np.int64(0)  # not the literal 0: _continuous_period would compile a second time for it (0.4 s of CPU)
    for k in range(k0, k1):
        if drift:
            _drifted(p, base, (k + 0.5) * T)
        qm, u, vir, du = _command(k, x0, x1, cs, q_r, qd_r, qdd_r, pulses, noise_q, c, chi, T, p[P_RES], fmax)
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
        dk = dist[k]
        if continuous:  # the law inside the dynamics, on the state at every step
            r1 = q_r[k + 1] if k + 1 < len(q_r) else q_r[k]
            out_qdd[k], x0, x1, x2, x3, n_steps, y = _continuous_period(
                p, c, u, q_r[k], r1, dk, x0, x1, x2, x3, tk, h, substeps, flex, fmax, hist, n_steps, tau_i, y
            )
        elif tau_i > 0.0:  # current loop: the applied force y lags the (lagged) command
            out_qdd[k], x0, x1, x2, x3, y = _current_loop_period(p, ua, ub, y, dk, x0, x1, x2, x3, tk, h, substeps, lag, flex, tau_i)
        elif du != 0.0:  # the ramped pulses' path: the disturbance with the command (out_u keeps the command)
            out_qdd[k], x0, x1, x2, x3 = _ramped_period(p, u + dk, du, x0, x1, x2, x3, tk, h, substeps, fmax, flex)
        elif linear:
            out_qdd[k], x0, x1 = _linear_period_of(p, ua + dk, ub + dk, x0, x1, tk, h, substeps, lag, static, p[P_VEPS], cfs)
        else:
            out_qdd[k], x0, x1, x2, x3 = _general_period(p, ua + dk, ub + dk, x0, x1, x2, x3, tk, h, substeps, lag, flex)
        if not _finite(x0, x1, x2, x3):
            x[0], x[1], x[2], x[3] = x0, x1, x2, x3
            return k
    x[0], x[1], x[2], x[3] = x0, x1, x2, x3
    if len(x) > 4:
        x[4] = y
    return -1
