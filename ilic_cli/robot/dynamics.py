"""Rigid-body dynamics of an arm, compiled (numba): inverse dynamics, mass matrix, forward dynamics.

The same conventions as :mod:`ilic_cli.robot.kernel` (pinocchio's): motion
vectors ``(linear, angular)`` in each link's frame, the base accelerating at
``-gravity``, and each link's 10 standard inertial parameters
``m, h = m c, I_O`` (``Ixx, Ixy, Iyy, Ixz, Iyz, Izz`` about the joint frame's
origin). The functions are linear in the standard parameters and need no
physical consistency: a vector holding base parameters at their kept standard
columns (zeros elsewhere, :func:`kept_vector`) gives the same torques as any
standard vector with those base parameters.

- :func:`rnea`: ``tau = M(q) qdd + C(q, qd) qd + g(q) + Ia qdd`` (recursive Newton-Euler);
- :func:`crba`: ``M(q)`` with the rotor inertias on its diagonal (composite rigid bodies);
- :func:`forward`: ``qdd = M^-1 (tau - h)``, with joints held at rest (``locked``) by rows of the identity.

Friction (``Fv, Fc, offset``) is not theirs: the plant (:mod:`ilic_cli.robot.plant`) adds it.
The tests check :func:`forward` against pinocchio's ``aba`` and :func:`rnea` against ``rnea`` to 1e-10.

An edit here does not renew the cached closed loop that compiles these functions into itself
(:mod:`ilic_cli.robot.loop`: numba keys a cache on the function's own file): touch that file too, or remove its cache.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.jit import njit
from ilic_cli.robot.kernel import placement
from ilic_cli.robot.model import INERTIAL, PER_JOINT, RobotModel

STRIDE = len(PER_JOINT)
IA = len(INERTIAL)
"""Offset of ``Ia`` in a joint's 14 standard parameters."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def workspace(n: int) -> tuple:
    """The scratch arrays the compiled functions take (``ws``), made once per run (views cut from one array per call cost 0.18 us each time).

    Placements ``(n, 3, 3), (n, 3)``; link motions and forces ``(6, n, 3)``
    (``v, w, a, al, fl, fa``); composite inertias ``(n, 10)``; ``M``; the
    vectors ``h``, ``rhs`` and ``0`` of :func:`forward_at` ``(n,)`` each.
    :func:`rnea_at` and :func:`crba_at` read them by index, not by row views, and are
    compiled without numba's reference counting (see :mod:`ilic_cli.robot.loop`).
    """
    return (
        np.empty((n, 3, 3)),
        np.empty((n, 3)),
        np.empty((6, n, 3)),
        np.empty((n, 10)),
        np.empty((n, n)),
        np.empty(n),
        np.empty(n),
        np.empty(n),
    )


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def placements(prismatic, axes, rotations, translations, q, ws):
    """Compute every link's placement at ``q`` into the workspace (read by :func:`rnea_at` and :func:`crba_at`)."""
    Rs, ps = ws[0], ws[1]
    for i in range(len(q)):
        placement(prismatic[i], axes[i], q[i], rotations[i], translations[i], Rs[i], ps[i])


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple[float, float, float]:
    """``a x b`` of scalars (kept in registers: :func:`ilic_cli.robot.kernel.cross`'s formula)."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def rnea_at(prismatic, parents, axes, gravity, pi, qd, qdd, tau, ws):
    """:func:`rnea` at the placements already in ``ws`` (:func:`placements`).

    Each link's motion and force are computed in scalars (registers) and stored
    once, for its children and the backward pass (with 3-vector work arrays
    every store made the compiled code load the other vectors again): the same operations in the same order, bit for bit the same torques.
    The parent's motion comes in as :func:`ilic_cli.robot.kernel.act_inv` carries
    it; the force is ``f = I a + v x* (I v)``: with the momenta ``P = m v + w x h``
    and ``L = I_O w + h x v``, ``f_l = m a + al x h + w x P``, ``f_a = I_O al + h x a + w x L + v x P``.
    """
    n = len(qd)
    Rs, ps, links = ws[0], ws[1], ws[2]  # links (6, n, 3): v, w, a, al, fl, fa, read by index (:func:`workspace`)
    for i in range(n):
        par = parents[i]
        if par < 0:
            vl0, vl1, vl2, wl0, wl1, wl2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            al0, al1, al2, aa0, aa1, aa2 = -gravity[0], -gravity[1], -gravity[2], 0.0, 0.0, 0.0
        else:
            vl0, vl1, vl2, wl0, wl1, wl2 = links[0, par, 0], links[0, par, 1], links[0, par, 2], links[1, par, 0], links[1, par, 1], links[1, par, 2]
            al0, al1, al2 = links[2, par, 0], links[2, par, 1], links[2, par, 2]
            aa0, aa1, aa2 = links[3, par, 0], links[3, par, 1], links[3, par, 2]
        R00, R01, R02, R10, R11, R12 = Rs[i, 0, 0], Rs[i, 0, 1], Rs[i, 0, 2], Rs[i, 1, 0], Rs[i, 1, 1], Rs[i, 1, 2]
        R20, R21, R22 = Rs[i, 2, 0], Rs[i, 2, 1], Rs[i, 2, 2]
        p0, p1, p2 = ps[i, 0], ps[i, 1], ps[i, 2]
        # the parent's motion in this link's frame: lin' = R' (lin - p x ang), ang' = R' ang
        d0, d1, d2 = vl0 - (p1 * wl2 - p2 * wl1), vl1 - (p2 * wl0 - p0 * wl2), vl2 - (p0 * wl1 - p1 * wl0)
        v0, v1, v2 = R00 * d0 + R10 * d1 + R20 * d2, R01 * d0 + R11 * d1 + R21 * d2, R02 * d0 + R12 * d1 + R22 * d2
        w0, w1, w2 = R00 * wl0 + R10 * wl1 + R20 * wl2, R01 * wl0 + R11 * wl1 + R21 * wl2, R02 * wl0 + R12 * wl1 + R22 * wl2
        d0, d1, d2 = al0 - (p1 * aa2 - p2 * aa1), al1 - (p2 * aa0 - p0 * aa2), al2 - (p0 * aa1 - p1 * aa0)
        a0, a1, a2 = R00 * d0 + R10 * d1 + R20 * d2, R01 * d0 + R11 * d1 + R21 * d2, R02 * d0 + R12 * d1 + R22 * d2
        b0, b1, b2 = R00 * aa0 + R10 * aa1 + R20 * aa2, R01 * aa0 + R11 * aa1 + R21 * aa2, R02 * aa0 + R12 * aa1 + R22 * aa2
        u0, u1, u2 = axes[i, 0], axes[i, 1], axes[i, 2]
        sl0, sl1, sl2 = (u0, u1, u2) if prismatic[i] else (0.0, 0.0, 0.0)
        sa0, sa1, sa2 = (0.0, 0.0, 0.0) if prismatic[i] else (u0, u1, u2)
        x, xx = qd[i], qdd[i]
        v0, v1, v2 = v0 + sl0 * x, v1 + sl1 * x, v2 + sl2 * x
        w0, w1, w2 = w0 + sa0 * x, w1 + sa1 * x, w2 + sa2 * x
        t10, t11, t12 = sl0 * x, sl1 * x, sl2 * x
        t20, t21, t22 = sa0 * x, sa1 * x, sa2 * x
        # a += S qdd + v x (S qd) (spatial cross: (w x t1 + v x t2, w x t2))
        c0, c1, c2 = _cross(w0, w1, w2, t10, t11, t12)
        a0, a1, a2 = a0 + (sl0 * xx + c0), a1 + (sl1 * xx + c1), a2 + (sl2 * xx + c2)
        c0, c1, c2 = _cross(v0, v1, v2, t20, t21, t22)
        a0, a1, a2 = a0 + c0, a1 + c1, a2 + c2
        c0, c1, c2 = _cross(w0, w1, w2, t20, t21, t22)
        b0, b1, b2 = b0 + (sa0 * xx + c0), b1 + (sa1 * xx + c1), b2 + (sa2 * xx + c2)
        links[0, i, 0], links[0, i, 1], links[0, i, 2], links[1, i, 0], links[1, i, 1], links[1, i, 2] = v0, v1, v2, w0, w1, w2
        links[2, i, 0], links[2, i, 1], links[2, i, 2], links[3, i, 0], links[3, i, 1], links[3, i, 2] = a0, a1, a2, b0, b1, b2
        # f = I a + v x* (I v), with the momenta P and L
        c = STRIDE * i
        m, h0, h1, h2 = pi[c], pi[c + 1], pi[c + 2], pi[c + 3]
        Ixx, Ixy, Iyy, Ixz, Iyz, Izz = pi[c + 4], pi[c + 5], pi[c + 6], pi[c + 7], pi[c + 8], pi[c + 9]
        c0, c1, c2 = _cross(w0, w1, w2, h0, h1, h2)
        P0, P1, P2 = m * v0 + c0, m * v1 + c1, m * v2 + c2
        L0, L1, L2 = Ixx * w0 + Ixy * w1 + Ixz * w2, Ixy * w0 + Iyy * w1 + Iyz * w2, Ixz * w0 + Iyz * w1 + Izz * w2
        c0, c1, c2 = _cross(h0, h1, h2, v0, v1, v2)
        L0, L1, L2 = L0 + c0, L1 + c1, L2 + c2
        c0, c1, c2 = _cross(b0, b1, b2, h0, h1, h2)
        e0, e1, e2 = _cross(w0, w1, w2, P0, P1, P2)
        links[4, i, 0], links[4, i, 1], links[4, i, 2] = m * a0 + c0 + e0, m * a1 + c1 + e1, m * a2 + c2 + e2
        c0, c1, c2 = _cross(h0, h1, h2, a0, a1, a2)
        e0, e1, e2 = _cross(w0, w1, w2, L0, L1, L2)
        g0, g1, g2 = _cross(v0, v1, v2, P0, P1, P2)
        links[5, i, 0] = Ixx * b0 + Ixy * b1 + Ixz * b2 + (c0 + e0 + g0)
        links[5, i, 1] = Ixy * b0 + Iyy * b1 + Iyz * b2 + (c1 + e1 + g1)
        links[5, i, 2] = Ixz * b0 + Iyz * b1 + Izz * b2 + (c2 + e2 + g2)
    for i in range(n - 1, -1, -1):
        f0, f1, f2, F0, F1, F2 = links[4, i, 0], links[4, i, 1], links[4, i, 2], links[5, i, 0], links[5, i, 1], links[5, i, 2]
        u0, u1, u2 = axes[i, 0], axes[i, 1], axes[i, 2]
        if prismatic[i]:
            tau[i] = u0 * f0 + u1 * f1 + u2 * f2 + 0.0 * F0 + 0.0 * F1 + 0.0 * F2
        else:
            tau[i] = 0.0 * f0 + 0.0 * f1 + 0.0 * f2 + u0 * F0 + u1 * F1 + u2 * F2
        tau[i] += pi[STRIDE * i + IA] * qdd[i]
        par = parents[i]
        if par >= 0:
            # the force in the parent's frame: f_l' = R f_l, f_a' = R f_a + p x R f_l
            t0 = Rs[i, 0, 0] * f0 + Rs[i, 0, 1] * f1 + Rs[i, 0, 2] * f2
            t1 = Rs[i, 1, 0] * f0 + Rs[i, 1, 1] * f1 + Rs[i, 1, 2] * f2
            t2 = Rs[i, 2, 0] * f0 + Rs[i, 2, 1] * f1 + Rs[i, 2, 2] * f2
            links[4, par, 0] += t0
            links[4, par, 1] += t1
            links[4, par, 2] += t2
            links[5, par, 0] += Rs[i, 0, 0] * F0 + Rs[i, 0, 1] * F1 + Rs[i, 0, 2] * F2
            links[5, par, 1] += Rs[i, 1, 0] * F0 + Rs[i, 1, 1] * F1 + Rs[i, 1, 2] * F2
            links[5, par, 2] += Rs[i, 2, 0] * F0 + Rs[i, 2, 1] * F1 + Rs[i, 2, 2] * F2
            links[5, par, 0] += ps[i, 1] * t2 - ps[i, 2] * t1
            links[5, par, 1] += ps[i, 2] * t0 - ps[i, 0] * t2
            links[5, par, 2] += ps[i, 0] * t1 - ps[i, 1] * t0


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def rnea(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, qdd, tau):
    """Fill ``tau`` (n,) with the rigid torques at ``q, qd, qdd`` for standard parameters ``pi`` (``Ia qdd`` included)."""
    ws = workspace(len(q))
    placements(prismatic, axes, rotations, translations, q, ws)
    rnea_at(prismatic, parents, axes, gravity, pi, qd, qdd, tau, ws)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def crba_at(prismatic, parents, axes, pi, M, ws):
    """Fill ``M`` (n, n) with the joint-space inertia at the placements in ``ws`` (``Ia`` on the diagonal).

    Composite inertias ``(m, h, I_O)`` are carried to the parent's frame:
    ``h' = R h + m p``, ``I' = R I R' - ([R h]x [p]x + [p]x [R h]x) - m [p]x^2``.
    """
    n = len(parents)
    Rs, ps, comp = ws[0], ws[1], ws[3]
    M[:, :] = 0.0  # joints on other branches do not couple
    for i in range(n):
        for c in range(10):
            comp[i, c] = pi[STRIDE * i + c]
    for i in range(n - 1, 0, -1):
        if parents[i] >= 0:
            _composite_to_parent(Rs, ps, comp, i, parents[i])
    for i in range(n):
        u0, u1, u2 = axes[i, 0], axes[i, 1], axes[i, 2]
        sl0, sl1, sl2 = (u0, u1, u2) if prismatic[i] else (0.0, 0.0, 0.0)
        sa0, sa1, sa2 = (0.0, 0.0, 0.0) if prismatic[i] else (u0, u1, u2)
        # F = I^c S: (m s_l + s_a x h, I_O s_a + h x s_l), in scalars
        m, h0, h1, h2 = comp[i, 0], comp[i, 1], comp[i, 2], comp[i, 3]
        Ixx, Ixy, Iyy, Ixz, Iyz, Izz = comp[i, 4], comp[i, 5], comp[i, 6], comp[i, 7], comp[i, 8], comp[i, 9]
        c0, c1, c2 = _cross(sa0, sa1, sa2, h0, h1, h2)
        F0, F1, F2 = m * sl0 + c0, m * sl1 + c1, m * sl2 + c2
        c0, c1, c2 = _cross(h0, h1, h2, sl0, sl1, sl2)
        G0 = Ixx * sa0 + Ixy * sa1 + Ixz * sa2 + c0
        G1 = Ixy * sa0 + Iyy * sa1 + Iyz * sa2 + c1
        G2 = Ixz * sa0 + Iyz * sa1 + Izz * sa2 + c2
        M[i, i] = sl0 * F0 + sl1 * F1 + sl2 * F2 + sa0 * G0 + sa1 * G1 + sa2 * G2 + pi[STRIDE * i + IA]
        j = i
        while parents[j] >= 0:
            # the force in the parent's frame: F' = R F, G' = R G + p x R F
            R00, R01, R02, R10, R11, R12 = Rs[j, 0, 0], Rs[j, 0, 1], Rs[j, 0, 2], Rs[j, 1, 0], Rs[j, 1, 1], Rs[j, 1, 2]
            R20, R21, R22, p0, p1, p2 = Rs[j, 2, 0], Rs[j, 2, 1], Rs[j, 2, 2], ps[j, 0], ps[j, 1], ps[j, 2]
            t0 = R00 * F0 + R01 * F1 + R02 * F2
            t1 = R10 * F0 + R11 * F1 + R12 * F2
            t2 = R20 * F0 + R21 * F1 + R22 * F2
            g0 = R00 * G0 + R01 * G1 + R02 * G2
            g1 = R10 * G0 + R11 * G1 + R12 * G2
            g2 = R20 * G0 + R21 * G1 + R22 * G2
            G0, G1, G2 = g0 + (p1 * t2 - p2 * t1), g1 + (p2 * t0 - p0 * t2), g2 + (p0 * t1 - p1 * t0)
            F0, F1, F2 = t0, t1, t2
            j = parents[j]
            if prismatic[j]:
                M[i, j] = axes[j, 0] * F0 + axes[j, 1] * F1 + axes[j, 2] * F2
            else:
                M[i, j] = axes[j, 0] * G0 + axes[j, 1] * G1 + axes[j, 2] * G2
            M[j, i] = M[i, j]


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def crba(prismatic, parents, axes, rotations, translations, pi, q, M):
    """Fill ``M`` (n, n) with the joint-space inertia at ``q`` for standard parameters ``pi`` (``Ia`` on the diagonal)."""
    ws = workspace(len(q))
    placements(prismatic, axes, rotations, translations, q, ws)
    crba_at(prismatic, parents, axes, pi, M, ws)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def _composite_to_parent(Rs: np.ndarray, ps: np.ndarray, comp: np.ndarray, i: int, par: int) -> None:
    """``comp[par] += X* comp[i] X``: the composite inertia of child ``i`` (10 parameters) in its parent's frame (placements ``Rs[i], ps[i]``)."""
    m = comp[i, 0]
    R00, R01, R02, R10, R11, R12 = Rs[i, 0, 0], Rs[i, 0, 1], Rs[i, 0, 2], Rs[i, 1, 0], Rs[i, 1, 1], Rs[i, 1, 2]
    R20, R21, R22, p0, p1, p2 = Rs[i, 2, 0], Rs[i, 2, 1], Rs[i, 2, 2], ps[i, 0], ps[i, 1], ps[i, 2]
    Rh0 = R00 * comp[i, 1] + R01 * comp[i, 2] + R02 * comp[i, 3]
    Rh1 = R10 * comp[i, 1] + R11 * comp[i, 2] + R12 * comp[i, 3]
    Rh2 = R20 * comp[i, 1] + R21 * comp[i, 2] + R22 * comp[i, 3]
    ab = Rh0 * p0 + Rh1 * p1 + Rh2 * p2
    pp = p0 * p0 + p1 * p1 + p2 * p2
    comp[par, 0] += m
    comp[par, 1] += Rh0 + m * p0
    comp[par, 2] += Rh1 + m * p1
    comp[par, 3] += Rh2 + m * p2
    # R I R' + 2 (Rh . p) E - p Rh' - Rh p' - m (p p' - |p|^2 E), per (xx, xy, yy, xz, yz, zz): pinocchio's order
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz = comp[i, 4], comp[i, 5], comp[i, 6], comp[i, 7], comp[i, 8], comp[i, 9]
    # column s of I R': I R[s] (R[s]: row s of R); entry (r, s) of R I R' = R[r] . (I R[s])
    x0, x1, x2 = Ixx * R00 + Ixy * R01 + Ixz * R02, Ixy * R00 + Iyy * R01 + Iyz * R02, Ixz * R00 + Iyz * R01 + Izz * R02
    y0, y1, y2 = Ixx * R10 + Ixy * R11 + Ixz * R12, Ixy * R10 + Iyy * R11 + Iyz * R12, Ixz * R10 + Iyz * R11 + Izz * R12
    z0, z1, z2 = Ixx * R20 + Ixy * R21 + Ixz * R22, Ixy * R20 + Iyy * R21 + Iyz * R22, Ixz * R20 + Iyz * R21 + Izz * R22
    comp[par, 4] += R00 * x0 + R01 * x1 + R02 * x2 - (p0 * Rh0 + Rh0 * p0 - 2.0 * ab) - m * (p0 * p0 - pp)
    comp[par, 5] += R00 * y0 + R01 * y1 + R02 * y2 - (p0 * Rh1 + Rh0 * p1) - m * (p0 * p1)
    comp[par, 6] += R10 * y0 + R11 * y1 + R12 * y2 - (p1 * Rh1 + Rh1 * p1 - 2.0 * ab) - m * (p1 * p1 - pp)
    comp[par, 7] += R00 * z0 + R01 * z1 + R02 * z2 - (p0 * Rh2 + Rh0 * p2) - m * (p0 * p2)
    comp[par, 8] += R10 * z0 + R11 * z1 + R12 * z2 - (p1 * Rh2 + Rh1 * p2) - m * (p1 * p2)
    comp[par, 9] += R20 * z0 + R21 * z1 + R22 * z2 - (p2 * Rh2 + Rh2 * p2 - 2.0 * ab) - m * (p2 * p2 - pp)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
def cholesky_solve(M: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = M^-1 b`` for a symmetric positive definite ``M`` (small: written out, no LAPACK call); ``M`` is overwritten."""
    n = len(b)
    for j in range(n):
        d = M[j, j]
        for k in range(j):
            d -= M[j, k] * M[j, k]
        d = np.sqrt(d)
        M[j, j] = d
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= M[i, k] * M[j, k]
            M[i, j] = s / d
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= M[i, k] * out[k]
        out[i] = s / M[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, n):
            s -= M[k, i] * out[k]
        out[i] = s / M[i, i]


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def forward_at(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, tau, locked, qdd, ws):
    """Fill ``qdd`` with ``M^-1 (tau - h(q, qd))`` using the workspace ``ws``; joints with ``locked`` True are held (``qdd = 0``)."""
    n = len(q)
    placements(prismatic, axes, rotations, translations, q, ws)
    M, h, rhs, zero = ws[4], ws[5], ws[6], ws[7]
    zero[:] = 0.0
    rnea_at(prismatic, parents, axes, gravity, pi, qd, zero, h, ws)
    crba_at(prismatic, parents, axes, pi, M, ws)
    for i in range(n):
        rhs[i] = tau[i] - h[i]
        if locked[i]:
            rhs[i] = 0.0
            for j in range(n):
                M[i, j] = 0.0
                M[j, i] = 0.0
            M[i, i] = 1.0
    cholesky_solve(M, rhs, qdd)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def forward(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, tau, locked, qdd):
    """Fill ``qdd`` with ``M^-1 (tau - h(q, qd))``; joints with ``locked`` True are held: ``qdd = 0`` there."""
    forward_at(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, tau, locked, qdd, workspace(len(q)))


def arrays(robot: RobotModel) -> tuple[np.ndarray, ...]:
    """The kinematic arrays the compiled functions take first: ``prismatic, parents, axes, rotations, translations``."""
    return (
        np.array([k == "prismatic" for k in robot.kinds]),
        np.array(robot.parents, dtype=np.int64),
        np.ascontiguousarray(robot.axes),
        np.ascontiguousarray(robot.rotations),
        np.ascontiguousarray(robot.translations),
    )


def kept_vector(kept: np.ndarray, beta: np.ndarray, size: int) -> np.ndarray:
    """A standard vector with base parameters ``beta`` at their ``kept`` columns and 0 elsewhere: ``Y pi = Y_b beta``."""
    pi = np.zeros(size)
    pi[np.asarray(kept)] = beta
    return pi
