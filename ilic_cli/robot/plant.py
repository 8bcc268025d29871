"""An arm of n joints in closed loop: CTC (paper eqs. 11-16) with online IDIM-ILIC updates, or a per-joint PD.

:func:`simulate_loop` runs the compiled loop (:mod:`ilic_cli.robot.loop`) one
window at a time. Between windows it hands the window's samples to
``update`` (the online IDIM-ILIC step, :func:`ilic_cli.robot.ilic.online_update`,
bound by the caller: this module imports no estimator), which returns the
controller's new standard parameter vector. ``changes`` replace the plant's
true parameters at given times (a payload picked up by the last link).
``prepare``, if given, computes what ``update`` needs from the window's
reference alone (the IDIM-ILIC system of the reference) while the compiled
loop (no GIL) simulates that window, in two threads (:func:`ilic_cli.parallel.ordered_map`;
one after the other with ``ILIC_THREADS=1``: the same results).

Deterministic per seed: the loop is deterministic; the torque and position
noises of the log are drawn once from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ilic_cli.parallel import ordered_map
from ilic_cli.prefault import populate_beside
from ilic_cli.robot.dynamics import arrays, crba
from ilic_cli.robot.loop import CTC, PD, run_steps
from ilic_cli.robot.model import RobotModel

CONTROLLERS = {"ctc": CTC, "pd": PD}


class Reference(Protocol):
    """What the loop tracks: ``q, qd, qdd`` (N, n) at the loop's times (a :class:`ilic_cli.robot.simulate.Trajectory`, or a log's samples)."""

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


VELOCITIES = ("backward", "exact")


@dataclass(frozen=True)
class LoopSettings:
    """Controller, sensors and rate of :func:`simulate_loop`.

    Attributes
    ----------
    fs_hz : float
        Control and logging rate (and the RK4 step).
    controller : str
        ``ctc`` (eqs. 11-16) or ``pd`` (per joint, with the model's feed-forward along the reference).
    omega_hz, xi : float
        CTC: ``Kp = omega^2``, ``Kv = 2 xi omega`` (eq. 15; paper: 20 Hz, sqrt(2)/2).
    pd_bandwidth_hz, pd_damping : float
        PD: ``Kp = M_jj w^2``, ``Kd = 2 zeta M_jj w`` with the model's ``M`` at the first reference sample.
    alpha : float
        Coulomb smoothing of the controller, ``(2/pi) atan(alpha qd_r)`` (eq. 31; paper: 1000).
    velocity : str
        ``backward`` (eq. 25) or ``exact`` (the plant's velocity: the paper's exact-velocity case).
    encoder_counts : int
        Counts per revolution (0: exact positions).
    encoder_step_m : float
        Quantisation step of a prismatic joint.
    torque_noise, position_noise : tuple of float
        Standard deviations of the log's Gaussian noise per joint (torque, and position after
        quantisation); the controller sees neither. Empty: none.
    seed : int
        Seed of the log's noise.
    """

    fs_hz: float = 1000.0
    controller: str = "ctc"
    omega_hz: float = 20.0
    xi: float = math.sqrt(2.0) / 2.0
    pd_bandwidth_hz: float = 5.0
    pd_damping: float = 0.8
    alpha: float = 1000.0
    velocity: str = "backward"
    encoder_counts: int = 2**17
    encoder_step_m: float = 1e-6
    torque_noise: tuple[float, ...] = ()
    position_noise: tuple[float, ...] = ()
    seed: int = 0

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller {self.controller!r}: expected one of {', '.join(CONTROLLERS)}")
        if self.velocity not in VELOCITIES:
            raise ValueError(f"velocity {self.velocity!r}: expected one of {', '.join(VELOCITIES)}")


@dataclass(frozen=True)
class Segment:
    """The samples of one window handed to ``update``: reference, measured position, logged torque (without noise)."""

    k: int
    t: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    qdd_ref: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    prepared: Any = None
    """What ``prepare`` returned for this window (None without it)."""


@dataclass(frozen=True)
class LoopRun:
    """A simulated closed-loop log (arrays (N, n), ``t`` (N,)) and the controller's parameters per window."""

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_true: np.ndarray
    qd_true: np.ndarray
    q_ref: np.ndarray
    qd_ref: np.ndarray
    qdd_ref: np.ndarray
    fs_hz: float
    models: tuple[np.ndarray, ...] = field(default=())
    """The controller's standard vector used in each window (``models[0]``: the initial one)."""


def encoder_steps(robot: RobotModel, settings: LoopSettings) -> np.ndarray:
    """Quantisation step of each joint's encoder (0: exact)."""
    if settings.encoder_counts <= 0:
        return np.zeros(robot.n)
    return np.where(np.array(robot.kinds) == "prismatic", settings.encoder_step_m, 2.0 * np.pi / settings.encoder_counts)


def gains(robot: RobotModel, model: np.ndarray, q0: np.ndarray, settings: LoopSettings) -> tuple[np.ndarray, np.ndarray]:
    """``(Kp, Kv)`` per joint of the controller (see :class:`LoopSettings`)."""
    if settings.controller == "ctc":
        w = 2.0 * np.pi * settings.omega_hz
        return np.full(robot.n, w * w), np.full(robot.n, 2.0 * settings.xi * w)
    M = np.empty((robot.n, robot.n))
    pr, par, ax, rot, tr = arrays(robot)
    crba(pr, par, ax, rot, tr, np.asarray(model, dtype=np.float64), np.asarray(q0, dtype=np.float64), M)
    w = 2.0 * np.pi * settings.pd_bandwidth_hz
    d = np.diag(M).copy()
    return d * w * w, 2.0 * settings.pd_damping * d * w


def _drive(robot: RobotModel, pi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    return pi, robot.drive(pi, "Fv").copy(), robot.drive(pi, "Fc").copy(), robot.drive(pi, "offset").copy()


def loop_times(duration_s: float, fs_hz: float) -> np.ndarray:
    """The loop's sample times over ``duration_s``: ``k / fs_hz``, ``k = 0 .. round(duration_s fs_hz) - 1`` (what :func:`simulate_loop` logs)."""
    return np.arange(int(round(duration_s * fs_hz))) * (1.0 / fs_hz)


def simulate_loop(
    robot: RobotModel,
    pi: np.ndarray,
    reference: Reference,
    duration_s: float,
    model: np.ndarray,
    settings: LoopSettings = LoopSettings(),
    *,
    window_s: float | None = None,
    update: Callable[[Segment, np.ndarray], np.ndarray] | None = None,
    changes: Sequence[tuple[float, np.ndarray]] = (),
    sink: Callable[[LoopRun, int, int], None] | None = None,
    prepare: Callable[[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray], Any] | None = None,
    true_state: bool = True,
) -> LoopRun:
    """Simulate the arm (true standard parameters ``pi``) tracking ``reference`` under the controller's ``model``.

    ``update(segment, model) -> model`` is called after each full window of
    ``window_s`` (the online IDIM-ILIC step); ``changes``: ``(time, new pi)``
    of the plant, applied from the first sample at or after that time.
    ``sink(run, start, stop)`` is called after each window with the samples
    ``start:stop`` logged (a writer streaming the log out).
    ``prepare(k, t, q_ref, qd_ref, qdd_ref)`` of each full window ``k`` runs beside its
    simulation; its result reaches ``update`` as ``segment.prepared``.
    The state starts on the reference.
    ``true_state=False``: the plant's position and velocity are not kept (``q_true``,
    ``qd_true`` of the run have no rows): the loop writes them into one window's
    buffers, reused, not into two more arrays of the run's length (58 MB of fresh
    memory for 600 s of 6 joints, some 0.25 s of system time at this machine's 4-5 ms a MB).
    """
    n = robot.n
    dt = 1.0 / settings.fs_hz
    t = loop_times(duration_s, settings.fs_hz)
    N = len(t)
    q_ref, qd_ref, qdd_ref = (np.ascontiguousarray(a) for a in reference.at(t))
    kin = arrays(robot)
    g = np.ascontiguousarray(robot.gravity)
    model = np.asarray(model, dtype=np.float64)
    kp, kv = gains(robot, model, q_ref[0], settings)
    step = encoder_steps(robot, settings)
    state = np.vstack([q_ref[0], qd_ref[0], q_ref[0] - qd_ref[0] * dt])
    if step.any():
        state[2] = np.where(step > 0, np.round(state[2] / np.where(step > 0, step, 1.0)) * step, state[2])
    q_log, tau = np.empty((N, n)), np.empty((N, n))
    win = N if window_s is None else max(1, int(round(window_s * settings.fs_hz)))
    q_true, qd_true = (np.empty((N, n)) if true_state else np.empty((0, n)) for _ in range(2))
    window_true: tuple[np.ndarray, ...] = () if true_state else (np.empty((min(win, N), n)), np.empty((min(win, N), n)))  # reused by every window
    backing = populate_beside((q_log, q_true, qd_true, tau))  # their pages' memory on the other core, not in the loop's writes
    noise_tau, noise_q = _noise((N, n), settings)
    stops = {N} | {min(N, s) for s in range(win, N, win)} | {int(math.ceil(c * settings.fs_hz - 1e-9)) for c, _ in changes if 0 < c * settings.fs_hz < N}
    plant_pi = {0: np.asarray(pi, dtype=np.float64)} | {int(math.ceil(c * settings.fs_hz - 1e-9)): np.asarray(p, dtype=np.float64) for c, p in changes}
    plant = _drive(robot, plant_pi[min(plant_pi)])
    models = [model]
    start = 0
    prepared = None
    run = LoopRun(t, q_log, tau, q_true, qd_true, q_ref, qd_ref, qdd_ref, settings.fs_hz)
    for stop in sorted(s for s in stops if s > 0):
        plant = _drive(robot, plant_pi[start]) if start in plant_pi else plant
        ctrl = (CONTROLLERS[settings.controller], float(settings.alpha), kp, kv)
        s = slice(start, stop)
        reference_part = (q_ref[s], qd_ref[s], qdd_ref[s])
        true = (q_true[s], qd_true[s]) if true_state else (window_true[0][: stop - start], window_true[1][: stop - start])
        logs = (q_log[s], *true, tau[s])
        hat = _drive(robot, model)
        steps = functools.partial(run_steps, kin, g, plant, ctrl, hat, step, settings.velocity == "exact", dt, *reference_part, state, *logs)
        if prepare is not None and update is not None and start % win == 0 and start + win <= N:
            w = slice(start, start + win)
            task = functools.partial(prepare, start // win + 1, t[w], q_ref[w], qd_ref[w], qdd_ref[w])
            prepared = ordered_map(lambda f: f(), [steps, task])[1]
        else:
            steps()
        if not np.all(np.isfinite(state)):
            raise FloatingPointError("the simulation diverged")
        if noise_tau is not None:
            tau[s] += noise_tau[s]
        if noise_q is not None:
            q_log[s] += noise_q[s]
        if stop % win == 0 or stop == N:
            if sink is not None:
                sink(run, (stop - 1) // win * win, stop)
            if update is not None and stop % win == 0:
                w = slice(stop - win, stop)
                segment = Segment(stop // win, t[w], q_ref[w], qd_ref[w], qdd_ref[w], q_log[w], tau[w], prepared)
                model = np.asarray(update(segment, model), dtype=np.float64)
                models.append(model)
        start = stop
    if backing is not None:
        backing.join()
    return LoopRun(t, q_log, tau, q_true, qd_true, q_ref, qd_ref, qdd_ref, settings.fs_hz, tuple(models))


def _noise(shape: tuple[int, int], settings: LoopSettings) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The log's torque and position noise, drawn once from the seed (None when none: nothing is added)."""
    rng = np.random.default_rng(settings.seed)
    tau = rng.standard_normal(shape) * np.asarray(settings.torque_noise, dtype=np.float64) if settings.torque_noise else None
    q = rng.standard_normal(shape) * np.asarray(settings.position_noise, dtype=np.float64) if settings.position_noise else None
    return tau, q
