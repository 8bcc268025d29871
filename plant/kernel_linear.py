"""The compiled step of the rigid axis without smooth effects: RK4's four stages in closed form (:mod:`plant.kernel`).

With no Stribeck term, ripple, spring, gravity, friction drift, flexibility or
an effect compiled from its definition, the motion between friction-direction
changes is linear with a constant force, so each RK4 step is
:func:`rk4_linear`, and a period that slides in one direction throughout is
advanced in one composed step (:func:`linear_period`). Same steps, same
stick/slip and zero-crossing logic as :func:`plant.kernel._step`: the results
equal the general path's up to round-off (positions within ~1e-14 relative),
some 20x faster. These functions read no effect compiled from a definition,
so they are compiled once and cached on disk.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.jit import njit
from plant.dynamics import P_DM, P_FC_NEG, P_FC_POS, P_FV_NEG, P_FV_POS, P_M, P_TCH


@njit(cache=True, nogil=True)
def rk4_linear(x0, v0, g, k, h):
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
"""Layout of the last axis of :func:`linear_coefficients`."""


@njit(cache=True, nogil=True)
def linear_coefficients(p, h, substeps):
    """Step coefficients of the linear (rigid, no smooth effect) axis, ``cf[r, d, :]``.

    ``r``: 0 before the payload change, 1 after; ``d``: 0 sliding forwards, 1
    backwards. Per substep (:func:`rk4_linear` with ``g = (f - cf[L_FC])*cf[L_INVM]``,
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


@njit(cache=True, nogil=True)
def linear_period(x0, x1, f, s_rest, tk, h, substeps, tch, veps, cf):
    """The substeps of one period on the rigid axis without smooth effects (``_step`` specialised).

    With no Stribeck term, ripple, spring or flexibility the motion between
    friction-direction changes is linear with a constant force ``f`` (control
    minus offset), so each RK4 step is :func:`rk4_linear`. ``s_rest`` is the
    stick/slip decision at rest (constant over the period: ``f`` is); ``cf``
    from :func:`linear_coefficients`. A period that slides in one direction
    throughout (``|v| > veps`` at the start of every substep, no sign change
    at its end; the velocity is monotone over it) is done in one composed
    step; otherwise substep by substep, as :func:`plant.kernel._step`.
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
        x0, y1 = rk4_linear(x0, x1, g, k, th * h)
        x1 = 0.0
        if s_rest != 0:
            d = 0 if s_rest > 0 else 1
            x0, x1 = rk4_linear(x0, 0.0, (f - cf[r, d, L_FC]) * cf[r, d, L_INVM], cf[r, d, L_K], (1.0 - th) * h)
            if x1 * s_rest < 0.0:
                x1 = 0.0
    return x0, x1


@njit(cache=True, nogil=True)
def rest_direction(f, static_pos, static_neg):
    """Stick/slip decision at rest under the net force ``f`` (constant over a period)."""
    return 1 if f > static_pos else (-1 if f < static_neg else 0)


@njit(cache=True, nogil=True)
def linear_acceleration(p, f, x1, tk, static_pos, static_neg, veps, cf):
    """:func:`plant.kernel._acceleration` of the rigid axis without smooth effects (net force ``f``), from the step coefficients."""
    s = 1 if x1 > veps else (-1 if x1 < -veps else rest_direction(f, static_pos, static_neg))
    if s == 0:
        return 0.0
    r, d = (1 if tk >= p[P_TCH] - 1e-12 else 0), (0 if s > 0 else 1)
    return (f - cf[r, d, L_FC]) * cf[r, d, L_INVM] - cf[r, d, L_K] * x1
