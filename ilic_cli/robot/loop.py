"""The compiled closed loop of an arm: per-joint stick/slip friction, CTC (paper eqs. 11-16) or PD, RK4 at the control rate.

One function, :func:`run_steps`, advances the loop over a run of control
periods; the Python driver (:mod:`ilic_cli.robot.plant`) calls it once per
IDIM-ILIC window and updates the controller's parameters between calls.

Plant, per joint ``j``: ``M(q) qdd + h(q, qd) = u - Fv qd - Fc s - offset``
(:func:`ilic_cli.robot.dynamics.forward_at`: rigid dynamics with rotor
inertias, checked against pinocchio's ``aba``). The Coulomb direction ``s`` is
frozen over each step and chosen at its start, as the 1-DOF plant does
(``plant.kernel``), joint by joint:

- ``|qd_j| > STICK_VELOCITY``: ``s_j = sign(qd_j)`` (sliding);
- otherwise (Karnopp stick/slip) the joint is held at rest and the friction
  torque that holds it is computed with every such joint held
  (``u - offset - rnea(q, qd, qdd_held)``); within ``Fc_j`` the joint sticks for
  the step (``qd_j = qdd_j = 0``), beyond it it breaks away, ``s_j`` in the
  direction of that torque.

A sliding joint whose velocity ends a step with the opposite sign makes the
step be redone up to that crossing, as the 1-DOF plant does (:func:`_period`).

Controller at sample ``k`` (command held over ``[t_k, t_k+1)``), on the
quantised position ``q_m`` and ``qd_hat`` (backward difference of ``q_m``,
eq. 25, or the plant's velocity: ``exact``):

- CTC: ``w = Kp (q_r - q_m) + Kv (qd_r - qd_hat) + qdd_r`` (eq. 13),
  ``u = M_hat(q_m) w + N_hat(q_m, qd_hat) + Fv_hat qd_r + Fc_hat (2/pi) atan(alpha qd_r) + offset_hat``
  (eqs. 16, 31), ``M_hat w + N_hat`` by :func:`~ilic_cli.robot.dynamics.rnea_at` of the controller's parameters;
- PD: ``u = ff_k + Kp (q_r - q_m) + Kv (qd_r - qd_hat)``, ``ff_k`` the same model along the reference.

The functions run at every step are compiled without numba's reference counting
(``_nrt=False``; they allocate nothing: :func:`run_steps` makes every array once):
with it, each array a compiled call takes (and each row view) was counted on entry
and released on exit, an atomic increment and decrement each, some hundred pairs a
step (``perf``: 19 % of all the samples of a process replaying the run's windows, about
a quarter of the loop's; 6.0-6.6 us a step before, 4.1-4.4 after, the same log bits). ``error_model="numpy"``: a float division by zero gives inf or nan
(caught by :func:`ilic_cli.robot.plant.simulate_loop`'s finiteness check) instead of
a raise path after every division. ``fastmath={"contract"}`` (here and in
:mod:`ilic_cli.robot.dynamics`): a product and the sum it feeds are fused (FMA, one
rounding instead of two) where the CPU has the instruction; no other fast-math
license (no reassociation, no finite-math assumption). 0.94x the CPU of a 600 s
``robot-sim`` run (8 paired runs); the torques move at roundoff (relative 1e-10 at
most within a window), which through the encoder's quantisation makes the 600 s log
another draw from 55 s on: the table's estimates moved by a median 0.08 % of the
truth, by about the windows' own spread (1.35 times their mean change), the median
error at the last window 0.19 % against 0.21 %. Deterministic on a machine (same
seed, same bits); a CPU without FMA rounds twice, as before.

numba's cache (``cache=True``) keys each function on its own file only: the
functions here are compiled with :mod:`ilic_cli.robot.dynamics`' kernels linked
into them, so a change there must come with a change to this file
(or the caches removed), else the old kernels keep running from the cache.

``forward_at`` is called, not inlined at numba's level (``inline="always"``): inlined, its body
was compiled anew in each of the three functions here that call it, 3.5 s of the 14.5 s of CPU
the first robot simulation compiles in (11.0 s now); the same bits, the same speed (a 20 s
6-joint run: 113 ms against 112-120 ms, 7 runs each, PD and CTC).
"""

from __future__ import annotations

import numpy as np

from ilic_cli.jit import njit
from ilic_cli.robot.dynamics import forward_at, placements, rnea_at, workspace

STICK_VELOCITY = 1e-9
"""|qd| (rad/s or m/s) at or below which a joint's stick/slip decision is taken."""

CTC, PD = 0, 1
"""Controller kinds of :func:`run_steps`."""


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def _directions(kin, g, pi, Fv, Fc, off, q, qd, u, s, locked, qdd, tau_net, hold, ws):
    """The Coulomb directions ``s`` and the held joints of the next step (Karnopp, see the module's docstring)."""
    pr, par, ax, rot, tr = kin
    n = len(q)
    any_rest = False
    for j in range(n):
        locked[j] = False
        if abs(qd[j]) > STICK_VELOCITY:
            s[j] = 1.0 if qd[j] > 0 else -1.0
        else:
            s[j] = 0.0
            qd[j] = 0.0
            locked[j] = True
            any_rest = True
    if not any_rest:
        return
    for j in range(n):
        tau_net[j] = u[j] - Fv[j] * qd[j] - Fc[j] * s[j] - off[j]
    forward_at(pr, par, ax, rot, tr, g, pi, q, qd, tau_net, locked, qdd, ws)
    placements(pr, ax, rot, tr, q, ws)
    rnea_at(pr, par, ax, g, pi, qd, qdd, hold, ws)
    for j in range(n):
        if locked[j]:
            need = u[j] - off[j] - hold[j]  # the Coulomb torque that keeps the joint at rest
            if abs(need) > Fc[j]:
                locked[j] = False
                s[j] = 1.0 if need > 0 else -1.0


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def _accel(kin, g, pi, Fv, Fc, off, q, qd, u, s, locked, out, tau_net, ws):
    pr, par, ax, rot, tr = kin
    for j in range(len(q)):
        tau_net[j] = u[j] - Fv[j] * qd[j] - Fc[j] * s[j] - off[j]
    forward_at(pr, par, ax, rot, tr, g, pi, q, qd, tau_net, locked, out, ws)


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def _rk4(kin, g, plant, q, qd, u, dt, locked, s, sc, ws):
    """One RK4 step of ``dt`` under the held command ``u``, directions ``s`` and ``locked`` frozen; ``q, qd`` updated in place."""
    pi, Fv, Fc, off = plant
    n = len(q)
    k1, k2, k3, k4, tn, q2, v2, q3, v3, q4, v4 = sc[0], sc[1], sc[2], sc[3], sc[4], sc[5], sc[6], sc[7], sc[8], sc[9], sc[10]
    h = 0.5 * dt
    _accel(kin, g, pi, Fv, Fc, off, q, qd, u, s, locked, k1, tn, ws)
    for j in range(n):
        q2[j], v2[j] = q[j] + h * qd[j], qd[j] + h * k1[j]
    _accel(kin, g, pi, Fv, Fc, off, q2, v2, u, s, locked, k2, tn, ws)
    for j in range(n):
        q3[j], v3[j] = q[j] + h * v2[j], qd[j] + h * k2[j]
    _accel(kin, g, pi, Fv, Fc, off, q3, v3, u, s, locked, k3, tn, ws)
    for j in range(n):
        q4[j], v4[j] = q[j] + dt * v3[j], qd[j] + dt * k3[j]
    _accel(kin, g, pi, Fv, Fc, off, q4, v4, u, s, locked, k4, tn, ws)
    for j in range(n):
        q[j] += dt / 6.0 * (qd[j] + 2.0 * v2[j] + 2.0 * v3[j] + v4[j])
        qd[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def _period(kin, g, plant, q, qd, u, dt, locked, s, sc, ws):
    """Advance one control period: RK4 steps between the joints' velocity reversals.

    When a sliding joint's velocity changes sign within the step, the step is
    redone up to the first crossing (linear interpolation of the velocity), that
    joint's velocity is set to exactly 0 and the rest of the period starts with
    a new stick/slip decision.
    """
    pi, Fv, Fc, off = plant
    n = len(q)
    k1, tn, q0, v0 = sc[0], sc[4], sc[11], sc[12]
    left = dt
    for _ in range(2 * n + 2):
        _directions(kin, g, pi, Fv, Fc, off, q, qd, u, s, locked, k1, tn, sc[1], ws)
        for j in range(n):
            q0[j], v0[j] = q[j], qd[j]
        _rk4(kin, g, plant, q, qd, u, left, locked, s, sc, ws)
        first, theta = -1, 1.0
        for j in range(n):
            if s[j] != 0.0 and qd[j] * s[j] < 0.0:
                if v0[j] == 0.0:  # broke away from rest and came back within the step: at rest again
                    qd[j] = 0.0
                    continue
                f = v0[j] / (v0[j] - qd[j])
                if f < theta or first < 0:
                    first, theta = j, f
        if first < 0:
            return
        for j in range(n):
            q[j], qd[j] = q0[j], v0[j]
        _rk4(kin, g, plant, q, qd, u, theta * left, locked, s, sc, ws)
        qd[first] = 0.0
        left -= theta * left
        if left <= 1e-12 * dt:
            return
    for j in range(n):  # a reversal left unresolved after as many splits: the joint rests
        if s[j] != 0.0 and qd[j] * s[j] < 0.0:
            qd[j] = 0.0


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)
def _command(kin, g, ctrl, hat, q_m, qd_hat, q_r, qd_r, qdd_r, u, w, ws):
    """The controller's torque ``u`` at one sample (see the module's docstring)."""
    pr, par, ax, rot, tr = kin
    kind, alpha, kp, kv = ctrl
    pi, Fv, Fc, off = hat
    n = len(q_m)
    if kind == CTC:
        for j in range(n):
            w[j] = kp[j] * (q_r[j] - q_m[j]) + kv[j] * (qd_r[j] - qd_hat[j]) + qdd_r[j]
        placements(pr, ax, rot, tr, q_m, ws)
        rnea_at(pr, par, ax, g, pi, qd_hat, w, u, ws)
    else:
        placements(pr, ax, rot, tr, q_r, ws)
        rnea_at(pr, par, ax, g, pi, qd_r, qdd_r, u, ws)
        for j in range(n):
            u[j] += kp[j] * (q_r[j] - q_m[j]) + kv[j] * (qd_r[j] - qd_hat[j])
    for j in range(n):
        u[j] += Fv[j] * qd_r[j] + Fc[j] * (2.0 / np.pi) * np.arctan(alpha * qd_r[j]) + off[j]


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def run_steps(kin, g, plant, ctrl, hat, step, exact, dt, q_r, qd_r, qdd_r, state, q_log, q_true, qd_true, tau_log):
    """Advance the loop over ``len(q_r)`` control periods from ``state``.

    Parameters
    ----------
    kin : tuple
        ``prismatic, parents, axes, rotations, translations`` (:func:`ilic_cli.robot.dynamics.arrays`).
    g : ndarray (3,)
        Gravity.
    plant, hat : tuple
        ``(pi, Fv, Fc, offset)`` of the plant (true) and of the controller (its model).
    ctrl : tuple
        ``(kind, alpha, Kp, Kv)``: :data:`CTC` or :data:`PD`, the Coulomb smoothing, per-joint gains.
    step : ndarray (n,)
        Encoder quantisation step per joint (0: exact position).
    exact : bool
        ``qd_hat`` is the plant's velocity, not the backward difference (eq. 25).
    state : ndarray (3, n)
        ``q, qd`` of the plant and the previous measured position; updated in place.
    q_log, q_true, qd_true, tau_log : ndarray (K, n)
        Filled: measured position, true position and velocity at ``t_k``, command over ``[t_k, t_k+1)``.
    """
    n = q_r.shape[1]
    ws = workspace(n)
    q, qd, prev = state[0], state[1], state[2]
    q_m, qd_hat, u, w = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    locked, s = np.empty(n, dtype=np.bool_), np.empty(n)
    e = np.empty
    sc = (e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n), e(n))  # k1..k4, tau_net, the stages' q and qd, q0, v0
    for k in range(len(q_r)):
        for j in range(n):
            q_m[j] = q[j] if step[j] == 0.0 else np.round(q[j] / step[j]) * step[j]
            qd_hat[j] = qd[j] if exact else (q_m[j] - prev[j]) / dt
            prev[j] = q_m[j]
        _command(kin, g, ctrl, hat, q_m, qd_hat, q_r[k], qd_r[k], qdd_r[k], u, w, ws)
        for j in range(n):
            q_log[k, j], q_true[k, j], qd_true[k, j], tau_log[k, j] = q_m[j], q[j], qd[j], u[j]
        _period(kin, g, plant, q, qd, u, dt, locked, s, sc, ws)
