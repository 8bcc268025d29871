"""The inertial regressor of an arm, compiled (numba): one pass per sample, no work arrays of N.

For each sample, a forward pass gives every link's velocity ``(v, w)`` and
acceleration ``(a, al)`` in its own frame (pinocchio's conventions: motion
vectors ``(linear, angular)``, the base accelerating at ``-gravity``) and carries
the motion axis of every ancestor joint ``j`` into link ``i``'s frame, ``s_ji``.
The torque of joint ``j`` due to link ``i``'s parameters is ``s_ji . A_i pi_i``,
``A_i`` the 6 x 10 body regressor (``f = I a + v x* I v``); its products with
``s`` are written out (``g`` for the first moments, ``u' L(x)`` for the inertia):

- mass: ``s_lin . (a + w x v)``;
- first moments ``h = m c``: ``s_lin x al + (s_lin x w) x w - s_ang x (a + w x v)``;
- inertia ``(Ixx, Ixy, Iyy, Ixz, Iyz, Izz)``: ``s_ang' L(al) + (s_ang x w)' L(w)``.

Compiled once with ``cache=True`` (the machine code is kept in ``__pycache__``).
"""

from __future__ import annotations

import numpy as np

from ilic_cli.jit import njit


@njit(cache=True, nogil=True, inline="always")
def cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = a x b`` (``out`` may not alias ``a`` or ``b``)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True, nogil=True, inline="always")
def act_inv(R: np.ndarray, p: np.ndarray, lin: np.ndarray, ang: np.ndarray, out_lin: np.ndarray, out_ang: np.ndarray) -> None:
    """A motion vector of the parent's frame in the child's: ``w' = R' w``, ``v' = R' (v - p x w)``."""
    d0 = lin[0] - (p[1] * ang[2] - p[2] * ang[1])
    d1 = lin[1] - (p[2] * ang[0] - p[0] * ang[2])
    d2 = lin[2] - (p[0] * ang[1] - p[1] * ang[0])
    for r in range(3):
        out_lin[r] = R[0, r] * d0 + R[1, r] * d1 + R[2, r] * d2
        out_ang[r] = R[0, r] * ang[0] + R[1, r] * ang[1] + R[2, r] * ang[2]


@njit(cache=True, nogil=True, inline="always")
def _inertia_row(u: np.ndarray, x: np.ndarray, out: np.ndarray, c: int) -> None:
    """``out[c:c+6] += u' L(x)``: ``I x`` projected on ``u``, per ``(Ixx, Ixy, Iyy, Ixz, Iyz, Izz)``."""
    out[c] += u[0] * x[0]
    out[c + 1] += u[0] * x[1] + u[1] * x[0]
    out[c + 2] += u[1] * x[1]
    out[c + 3] += u[0] * x[2] + u[2] * x[0]
    out[c + 4] += u[1] * x[2] + u[2] * x[1]
    out[c + 5] += u[2] * x[2]


@njit(cache=True, nogil=True, inline="always")
def placement(prismatic: bool, u: np.ndarray, x: float, Rp: np.ndarray, tp: np.ndarray, R: np.ndarray, p: np.ndarray) -> None:
    """Placement ``(R, p)`` of a link in its parent's frame at joint position ``x``: the joint placement times the joint's motion."""
    if prismatic:
        for r in range(3):
            p[r] = tp[r] + x * (Rp[r, 0] * u[0] + Rp[r, 1] * u[1] + Rp[r, 2] * u[2])
            for c in range(3):
                R[r, c] = Rp[r, c]
        return
    # Rodrigues: Rj = I + sin K + (1 - cos) K K, K = [u]x; R = Rp Rj
    sn, cs = np.sin(x), 1.0 - np.cos(x)
    for r in range(3):
        p[r] = tp[r]
    for c in range(3):
        e0, e1, e2 = (1.0 if c == 0 else 0.0), (1.0 if c == 1 else 0.0), (1.0 if c == 2 else 0.0)
        k0, k1, k2 = u[1] * e2 - u[2] * e1, u[2] * e0 - u[0] * e2, u[0] * e1 - u[1] * e0
        kk0, kk1, kk2 = u[1] * k2 - u[2] * k1, u[2] * k0 - u[0] * k2, u[0] * k1 - u[1] * k0
        j0, j1, j2 = e0 + sn * k0 + cs * kk0, e1 + sn * k1 + cs * kk1, e2 + sn * k2 + cs * kk2
        for r in range(3):
            R[r, c] = Rp[r, 0] * j0 + Rp[r, 1] * j1 + Rp[r, 2] * j2


@njit(cache=True, nogil=True)
def inertial_regressor(
    prismatic: np.ndarray,
    parents: np.ndarray,
    axes: np.ndarray,
    rotations: np.ndarray,
    translations: np.ndarray,
    gravity: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    out: np.ndarray,
    stride: int,
) -> None:
    """Fill ``out[j, k, stride * i + c]`` (c < 10) with joint ``j``'s torque per inertial parameter ``c`` of link ``i`` at sample ``k``.

    ``out`` is (n, N, >= stride * n); entries of a link not below a joint are left as they are (zeros).
    """
    N, n = q.shape
    v = np.zeros((n, 3))
    w = np.zeros((n, 3))
    a = np.zeros((n, 3))
    al = np.zeros((n, 3))
    s_lin = np.zeros((n, n, 3))  # s_lin[i, j]: joint j's axis in link i's frame (linear part)
    s_ang = np.zeros((n, n, 3))
    R = np.zeros((3, 3))
    p = np.zeros(3)
    zero = np.zeros(3)
    base_a = -gravity
    t1, t2, t3, av = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    for k in range(N):
        for i in range(n):
            u = axes[i]
            placement(prismatic[i], u, q[k, i], rotations[i], translations[i], R, p)
            par = parents[i]
            if par < 0:
                act_inv(R, p, zero, zero, v[i], w[i])
                act_inv(R, p, base_a, zero, a[i], al[i])
            else:
                act_inv(R, p, v[par], w[par], v[i], w[i])
                act_inv(R, p, a[par], al[par], a[i], al[i])
                j = par
                while j >= 0:
                    act_inv(R, p, s_lin[par, j], s_ang[par, j], s_lin[i, j], s_ang[i, j])
                    j = parents[j]
            for r in range(3):
                s_lin[i, i, r] = u[r] if prismatic[i] else 0.0
                s_ang[i, i, r] = 0.0 if prismatic[i] else u[r]
            # v += S qd; a += S qdd + v x (S qd)
            for r in range(3):
                v[i, r] += s_lin[i, i, r] * qd[k, i]
                w[i, r] += s_ang[i, i, r] * qd[k, i]
            for r in range(3):
                t1[r] = s_lin[i, i, r] * qd[k, i]
                t2[r] = s_ang[i, i, r] * qd[k, i]
            cross(w[i], t1, t3)
            for r in range(3):
                a[i, r] += s_lin[i, i, r] * qdd[k, i] + t3[r]
            cross(v[i], t2, t3)
            for r in range(3):
                a[i, r] += t3[r]
            cross(w[i], t2, t3)
            for r in range(3):
                al[i, r] += s_ang[i, i, r] * qdd[k, i] + t3[r]
        for i in range(n):
            cross(w[i], v[i], t1)
            for r in range(3):
                av[r] = a[i, r] + t1[r]
            c = stride * i
            j = i
            while j >= 0:
                cl, ca = s_lin[i, j], s_ang[i, j]
                row = out[j, k]
                row[c] = cl[0] * av[0] + cl[1] * av[1] + cl[2] * av[2]
                # g = cl x al + (cl x w) x w - ca x av
                cross(cl, w[i], t1)
                cross(t1, w[i], t2)
                cross(cl, al[i], t3)
                for r in range(3):
                    row[c + 1 + r] = t3[r] + t2[r]
                cross(ca, av, t3)
                for r in range(3):
                    row[c + 1 + r] -= t3[r]
                for r in range(6):
                    row[c + 4 + r] = 0.0
                _inertia_row(ca, al[i], row, c + 4)
                cross(ca, w[i], t1)
                _inertia_row(t1, w[i], row, c + 4)
                j = parents[j]


@njit(cache=True, nogil=True)
def base_columns(
    prismatic: np.ndarray,
    parents: np.ndarray,
    axes: np.ndarray,
    rotations: np.ndarray,
    translations: np.ndarray,
    gravity: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    destination: np.ndarray,
    stride: int,
    out: np.ndarray,
    width: int,
    lo: int,
    hi: int,
) -> None:
    """Fill ``out[d // width, d % width, k]``, ``d = destination[j, c]``, with standard column ``c`` of joint ``j``'s row at sample ``k``.

    For ``lo <= k < hi``; ``destination < 0``: not kept. ``out`` (parts, width, N): the columns in parts of
    ``width`` (one part: ``out[None]`` of a (C, N) array).

    The same values as :func:`inertial_regressor` for the inertial columns and
    ``qdd, qd, sign(qd), 1`` for a joint's own ``Ia, Fv, Fc, offset`` (at
    ``stride * j + 10 ...``), computed a chunk of samples at a time in a scratch
    array that stays in cache: the full (n, N, stride n) regressor is never held.
    Disjoint ranges of samples may be filled in threads (no GIL held).
    """
    n = q.shape[1]
    chunk = 128
    scratch = np.zeros((n, chunk, stride * n))
    for a in range(lo, hi, chunk):
        b = min(hi, a + chunk)
        inertial_regressor(prismatic, parents, axes, rotations, translations, gravity, q[a:b], qd[a:b], qdd[a:b], scratch, stride)
        for j in range(n):
            c = stride * j + 10
            for k in range(b - a):
                scratch[j, k, c] = qdd[a + k, j]
                scratch[j, k, c + 1] = qd[a + k, j]
                scratch[j, k, c + 2] = np.sign(qd[a + k, j])
                scratch[j, k, c + 3] = 1.0
        for j in range(n):
            for c in range(stride * n):
                d = destination[j, c]
                if d >= 0:
                    part = out[d // width, d % width]
                    for k in range(b - a):
                        part[a + k] = scratch[j, k, c]


@njit(cache=True, nogil=True, inline="always")
def _poles(a: np.ndarray, w1: np.ndarray, w2: np.ndarray, u: np.ndarray) -> None:
    """One sample ``u`` (a value per column, replaced by the output) through sections ``(1 + z^-1)^2 / (1 + a1 z^-1 + a2 z^-2)`` in series.

    Direct form II: ``w = u - a1 w1 - a2 w2``, output ``w + 2 w1 + w2``; each loop runs across the columns.
    """
    for s in range(a.shape[0]):
        a1, a2, p, q = a[s, 0], a[s, 1], w1[s], w2[s]  # rows as 1-D views: the loop over columns is vectorised
        for c in range(u.shape[0]):
            w = u[c] - a1 * p[c] - a2 * q[c]
            u[c] = w + 2.0 * p[c] + q[c]
            q[c] = p[c]
            p[c] = w


@njit(cache=True, nogil=True)
def filtfilt_kept(x: np.ndarray, a: np.ndarray, k: float, gain: float, pad: int, first: int, r: int, out: np.ndarray, lo: int, hi: int) -> None:
    """Columns ``lo <= c < hi`` of ``x`` (N, C) filtered forward then backward; ``out[j, c]`` the output at sample ``first + r j``.

    The filter: ``k`` times the sections of :func:`_poles` (``a``: (S, 2)), whose
    DC gain is ``gain``. As :func:`ilic_cli.filtering.filtfilt_matlab`: each
    column odd-extended by ``pad`` samples at both ends, each pass from the
    steady state of its first sample (``gain x0`` plus the zero-state response
    to ``x - x0``). The forward pass is written over ``x``; the backward pass
    runs its recursion over every sample but forms only the kept outputs.
    Disjoint ranges of columns may be filtered in threads (no GIL held).
    """
    n, m, S = x.shape[0], hi - lo, a.shape[0]
    w1, w2 = np.zeros((S, m)), np.zeros((S, m))
    u, x0 = np.empty(m), np.empty(m)
    head, tail = np.empty((pad, m)), np.empty((pad, m))
    for c in range(m):
        for i in range(pad):
            head[i, c] = 2.0 * x[0, lo + c] - x[pad - i, lo + c]
            tail[i, c] = 2.0 * x[n - 1, lo + c] - x[n - 2 - i, lo + c]
        x0[c] = head[0, c]
    for i in range(pad):
        for c in range(m):
            u[c] = head[i, c] - x0[c]
        _poles(a, w1, w2, u)
    for i in range(n):
        row = x[i, lo:hi]  # a contiguous view: the loops over it are vectorised (no gathers)
        for c in range(m):
            u[c] = row[c] - x0[c]
        _poles(a, w1, w2, u)
        for c in range(m):
            row[c] = k * u[c] + gain * x0[c]
    for i in range(pad):
        for c in range(m):
            u[c] = tail[i, c] - x0[c]
        _poles(a, w1, w2, u)
        for c in range(m):
            tail[i, c] = k * u[c] + gain * x0[c]
    # backward, from the steady state of the last forward output
    w1[:] = 0.0
    w2[:] = 0.0
    for c in range(m):  # element by element: an array assignment compiles a shape check's error message (2.3 s of CPU)
        x0[c] = tail[pad - 1, c]
    for i in range(pad - 1, -1, -1):
        for c in range(m):
            u[c] = tail[i, c] - x0[c]
        _poles(a, w1, w2, u)
    j = (n - 1 - first) // r
    for i in range(n - 1, first - 1, -1):
        row = x[i, lo:hi]
        for c in range(m):
            u[c] = row[c] - x0[c]
        _poles(a, w1, w2, u)
        if i == first + r * j:
            kept = out[j, lo:hi]
            for c in range(m):
                kept[c] = k * u[c] + gain * x0[c]
            j -= 1
