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
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ilic_cli.robot.kernel import act_inv, cross, placement
from ilic_cli.robot.model import INERTIAL, PER_JOINT, RobotModel

STRIDE = len(PER_JOINT)
IA = len(INERTIAL)
"""Offset of ``Ia`` in a joint's 14 standard parameters."""


@njit(cache=True, nogil=True, inline="always")
def _inertia_times(pi: np.ndarray, c: int, x: np.ndarray, out: np.ndarray) -> None:
    """``out = I_O x`` for the symmetric inertia at ``pi[c+4 : c+10]``."""
    out[0] = pi[c + 4] * x[0] + pi[c + 5] * x[1] + pi[c + 7] * x[2]
    out[1] = pi[c + 5] * x[0] + pi[c + 6] * x[1] + pi[c + 8] * x[2]
    out[2] = pi[c + 7] * x[0] + pi[c + 8] * x[1] + pi[c + 9] * x[2]


@njit(cache=True, nogil=True)
def workspace(n: int) -> tuple:
    """The scratch arrays the compiled functions take (``ws``), made once per run (views cut from one array per call cost 0.18 us each time).

    Placements ``(n, 3, 3), (n, 3)``; link motions and forces ``(8, n, 3)``
    (``v, w, a, al, fl, fa, sl, sa``); composite inertias ``(n, 10)``; ``M``;
    vectors ``(3, n)``; scratch ``(12, 3)``.
    """
    return (
        np.empty((n, 3, 3)),
        np.empty((n, 3)),
        np.empty((8, n, 3)),
        np.empty((n, 10)),
        np.empty((n, n)),
        np.empty((3, n)),
        np.empty((12, 3)),
    )


@njit(cache=True, nogil=True, inline="always")
def _split(ws, n):
    """The workspace's arrays: placements, link motions and forces, composite inertias, M, vectors, scratch."""
    return ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6]


@njit(cache=True, nogil=True)
def placements(prismatic, axes, rotations, translations, q, ws):
    """Compute every link's placement at ``q`` into the workspace (read by :func:`rnea_at` and :func:`crba_at`)."""
    Rs, ps, _, _, _, _, _ = _split(ws, len(q))
    for i in range(len(q)):
        placement(prismatic[i], axes[i], q[i], rotations[i], translations[i], Rs[i], ps[i])


@njit(cache=True, nogil=True)
def rnea_at(prismatic, parents, axes, gravity, pi, qd, qdd, tau, ws):
    """:func:`rnea` at the placements already in ``ws`` (:func:`placements`)."""
    n = len(qd)
    Rs, ps, links, _, _, _, tmp = _split(ws, n)
    v, w, a, al, fl, fa, sl, sa = links[0], links[1], links[2], links[3], links[4], links[5], links[6], links[7]
    t1, t2, t3, P, L, zero, mg = tmp[0], tmp[1], tmp[2], tmp[3], tmp[4], tmp[5], tmp[6]
    for r in range(3):
        zero[r] = 0.0
        mg[r] = -gravity[r]
    for i in range(n):
        R, p = Rs[i], ps[i]
        par = parents[i]
        if par < 0:
            act_inv(R, p, zero, zero, v[i], w[i])
            act_inv(R, p, mg, zero, a[i], al[i])
        else:
            act_inv(R, p, v[par], w[par], v[i], w[i])
            act_inv(R, p, a[par], al[par], a[i], al[i])
        for r in range(3):
            sl[i, r] = axes[i, r] if prismatic[i] else 0.0
            sa[i, r] = 0.0 if prismatic[i] else axes[i, r]
            v[i, r] += sl[i, r] * qd[i]
            w[i, r] += sa[i, r] * qd[i]
            t1[r] = sl[i, r] * qd[i]
            t2[r] = sa[i, r] * qd[i]
        # a += S qdd + v x (S qd) (spatial cross: (w x t1 + v x t2, w x t2))
        cross(w[i], t1, t3)
        for r in range(3):
            a[i, r] += sl[i, r] * qdd[i] + t3[r]
        cross(v[i], t2, t3)
        for r in range(3):
            a[i, r] += t3[r]
        cross(w[i], t2, t3)
        for r in range(3):
            al[i, r] += sa[i, r] * qdd[i] + t3[r]
        _body_force(pi, STRIDE * i, v[i], w[i], a[i], al[i], fl[i], fa[i], t1, t2, t3, P, L)
    for i in range(n - 1, -1, -1):
        tau[i] = sl[i, 0] * fl[i, 0] + sl[i, 1] * fl[i, 1] + sl[i, 2] * fl[i, 2] + sa[i, 0] * fa[i, 0] + sa[i, 1] * fa[i, 1] + sa[i, 2] * fa[i, 2]
        tau[i] += pi[STRIDE * i + IA] * qdd[i]
        par = parents[i]
        if par >= 0:
            _act_force(Rs[i], ps[i], fl[i], fa[i], fl[par], fa[par], t1)


@njit(cache=True, nogil=True)
def rnea(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, qdd, tau):
    """Fill ``tau`` (n,) with the rigid torques at ``q, qd, qdd`` for standard parameters ``pi`` (``Ia qdd`` included)."""
    ws = workspace(len(q))
    placements(prismatic, axes, rotations, translations, q, ws)
    rnea_at(prismatic, parents, axes, gravity, pi, qd, qdd, tau, ws)


@njit(cache=True, nogil=True, inline="always")
def _act_force(R: np.ndarray, p: np.ndarray, fl: np.ndarray, fa: np.ndarray, acc_l: np.ndarray, acc_a: np.ndarray, t: np.ndarray) -> None:
    """``acc += X* f``: a child's force in its parent's frame, ``f_l' = R f_l``, ``f_a' = R f_a + p x R f_l``."""
    for r in range(3):
        t[r] = R[r, 0] * fl[0] + R[r, 1] * fl[1] + R[r, 2] * fl[2]
        acc_l[r] += t[r]
        acc_a[r] += R[r, 0] * fa[0] + R[r, 1] * fa[1] + R[r, 2] * fa[2]
    acc_a[0] += p[1] * t[2] - p[2] * t[1]
    acc_a[1] += p[2] * t[0] - p[0] * t[2]
    acc_a[2] += p[0] * t[1] - p[1] * t[0]


@njit(cache=True, nogil=True, inline="always")
def _body_force(pi, c, v, w, a, al, fl, fa, t1, t2, t3, P, L):
    """``f = I a + v x* (I v)`` of the link whose inertial parameters start at ``pi[c]``.

    ``P = m v + w x h`` and ``L = I_O w + h x v`` are the momenta;
    ``f_l = m a + al x h + w x P``, ``f_a = I_O al + h x a + w x L + v x P``.
    """
    m = pi[c]
    h = pi[c + 1 : c + 4]
    cross(w, h, t1)
    for r in range(3):
        P[r] = m * v[r] + t1[r]
    _inertia_times(pi, c, w, L)
    cross(h, v, t1)
    for r in range(3):
        L[r] += t1[r]
    cross(al, h, t1)
    cross(w, P, t2)
    for r in range(3):
        fl[r] = m * a[r] + t1[r] + t2[r]
    _inertia_times(pi, c, al, fa)
    cross(h, a, t1)
    cross(w, L, t2)
    cross(v, P, t3)
    for r in range(3):
        fa[r] += t1[r] + t2[r] + t3[r]


@njit(cache=True, nogil=True)
def crba_at(prismatic, parents, axes, pi, M, ws):
    """Fill ``M`` (n, n) with the joint-space inertia at the placements in ``ws`` (``Ia`` on the diagonal).

    Composite inertias ``(m, h, I_O)`` are carried to the parent's frame:
    ``h' = R h + m p``, ``I' = R I R' - ([R h]x [p]x + [p]x [R h]x) - m [p]x^2``.
    """
    n = len(parents)
    Rs, ps, _, comp, _, _, tmp = _split(ws, n)
    Fl, Fa, sl, sa, t, Gl, Ga = tmp[5], tmp[6], tmp[7], tmp[8], tmp[9], tmp[10], tmp[11]
    M[:, :] = 0.0  # joints on other branches do not couple
    for i in range(n):
        for c in range(10):
            comp[i, c] = pi[STRIDE * i + c]
    for i in range(n - 1, 0, -1):
        if parents[i] >= 0:
            _composite_to_parent(Rs[i], ps[i], comp[i], comp[parents[i]])
    for i in range(n):
        for r in range(3):
            sl[r] = axes[i, r] if prismatic[i] else 0.0
            sa[r] = 0.0 if prismatic[i] else axes[i, r]
        # F = I^c S: (m s_l + s_a x h, I_O s_a + h x s_l)
        m = comp[i, 0]
        h = comp[i, 1:4]
        cross(sa, h, t)
        for r in range(3):
            Fl[r] = m * sl[r] + t[r]
        _inertia_times(comp[i], 0, sa, Fa)
        cross(h, sl, t)
        for r in range(3):
            Fa[r] += t[r]
        M[i, i] = sl[0] * Fl[0] + sl[1] * Fl[1] + sl[2] * Fl[2] + sa[0] * Fa[0] + sa[1] * Fa[1] + sa[2] * Fa[2] + pi[STRIDE * i + IA]
        j = i
        while parents[j] >= 0:
            for r in range(3):
                Gl[r], Ga[r] = 0.0, 0.0
            _act_force(Rs[j], ps[j], Fl, Fa, Gl, Ga, t)
            for r in range(3):
                Fl[r], Fa[r] = Gl[r], Ga[r]
            j = parents[j]
            if prismatic[j]:
                M[i, j] = axes[j, 0] * Fl[0] + axes[j, 1] * Fl[1] + axes[j, 2] * Fl[2]
            else:
                M[i, j] = axes[j, 0] * Fa[0] + axes[j, 1] * Fa[1] + axes[j, 2] * Fa[2]
            M[j, i] = M[i, j]


@njit(cache=True, nogil=True)
def crba(prismatic, parents, axes, rotations, translations, pi, q, M):
    """Fill ``M`` (n, n) with the joint-space inertia at ``q`` for standard parameters ``pi`` (``Ia`` on the diagonal)."""
    ws = workspace(len(q))
    placements(prismatic, axes, rotations, translations, q, ws)
    crba_at(prismatic, parents, axes, pi, M, ws)


@njit(cache=True, nogil=True)
def _composite_to_parent(R: np.ndarray, p: np.ndarray, c: np.ndarray, acc: np.ndarray) -> None:
    """``acc += X* c X``: the composite inertia ``c`` (10 parameters) of a child in its parent's frame."""
    m = c[0]
    Rh0 = R[0, 0] * c[1] + R[0, 1] * c[2] + R[0, 2] * c[3]
    Rh1 = R[1, 0] * c[1] + R[1, 1] * c[2] + R[1, 2] * c[3]
    Rh2 = R[2, 0] * c[1] + R[2, 1] * c[2] + R[2, 2] * c[3]
    ab = Rh0 * p[0] + Rh1 * p[1] + Rh2 * p[2]
    pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2]
    acc[0] += m
    acc[1] += Rh0 + m * p[0]
    acc[2] += Rh1 + m * p[1]
    acc[3] += Rh2 + m * p[2]
    # R I R' + 2 (Rh . p) E - p Rh' - Rh p' - m (p p' - |p|^2 E), per (xx, xy, yy, xz, yz, zz)
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz = c[4], c[5], c[6], c[7], c[8], c[9]
    # R I R' entry (r, s) = R[r] . (I R[s]) (R[r]: row r of R)
    slot = 4
    for s in range(3):
        a0 = Ixx * R[s, 0] + Ixy * R[s, 1] + Ixz * R[s, 2]
        a1 = Ixy * R[s, 0] + Iyy * R[s, 1] + Iyz * R[s, 2]
        a2 = Ixz * R[s, 0] + Iyz * R[s, 1] + Izz * R[s, 2]
        Rhs = Rh0 if s == 0 else (Rh1 if s == 1 else Rh2)
        for r in range(s + 1):  # (0,0) (0,1) (1,1) (0,2) (1,2) (2,2): pinocchio's order
            Rhr = Rh0 if r == 0 else (Rh1 if r == 1 else Rh2)
            e = 1.0 if r == s else 0.0
            RIR = R[r, 0] * a0 + R[r, 1] * a1 + R[r, 2] * a2
            acc[slot] += RIR - (p[r] * Rhs + Rhr * p[s] - 2.0 * ab * e) - m * (p[r] * p[s] - pp * e)
            slot += 1


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def forward_at(prismatic, parents, axes, rotations, translations, gravity, pi, q, qd, tau, locked, qdd, ws):
    """Fill ``qdd`` with ``M^-1 (tau - h(q, qd))`` using the workspace ``ws``; joints with ``locked`` True are held (``qdd = 0``)."""
    n = len(q)
    placements(prismatic, axes, rotations, translations, q, ws)
    _, _, _, _, M, vecs, _ = _split(ws, n)
    h, rhs, zero = vecs[0], vecs[1], vecs[2]
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


@njit(cache=True, nogil=True)
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
