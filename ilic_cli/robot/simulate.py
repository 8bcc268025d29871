"""An n-joint arm in closed loop for the tests: pinocchio's ``aba``, friction, PD tracking, sensors.

- Rigid dynamics: ``pin.aba`` of the true standard parameters (rotor inertia as
  pinocchio's armature), fourth-order Runge-Kutta at the control period (1 kHz),
  the command held over the period.
- Friction per joint: viscous ``Fv qd`` and a smooth Coulomb rule
  ``Fc tanh(qd / v_smooth)`` (no stick phase: the rule is continuous, so fixed-step
  RK4 stays accurate; ``v_smooth`` = 0.01 rad/s by default, well below the
  trajectories' speeds), plus the constant ``offset``; identification's model is
  ``Fc sign(qd)``, the two differ only within a few ``v_smooth`` of rest.
- Control: per-joint PD on the quantised encoder position (velocity by backward
  difference) around a sum-of-sines reference, with a feed-forward of the
  URDF's nominal model (``rnea`` at the reference; not the true parameters).
- Sensors: encoder quantisation of the position, Gaussian noise on the logged torque.

Deterministic per seed: the noise is drawn once from ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ilic_cli.robot.model import RobotModel, configuration, import_pinocchio, pinocchio_model

BLOCK = 4096
"""Times per block of :meth:`Trajectory.at`."""


@dataclass(frozen=True)
class Trajectory:
    """Sum of sines per joint: ``q_ref = q0 + sum_k A_k sin(2 pi f_k t + phi_k)`` (arrays (n,), (n, K))."""

    q0: np.ndarray
    amplitude: np.ndarray
    frequency_hz: np.ndarray
    phase: np.ndarray

    def at(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q, qd, qdd`` of the reference at times ``t`` (shape ``t.shape + (n,)``).

        Evaluated :data:`BLOCK` times at a time: the (times, n, harmonics)
        intermediates of a 10-minute 1 kHz reference would not fit in cache
        (3.1 s for 600 000 samples of 6 joints; 0.5 s by blocks, the same values).
        """
        times = np.asarray(t, dtype=np.float64)
        flat = times.reshape(-1)
        n = len(self.q0)
        q, qd, qdd = (np.empty((len(flat), n)) for _ in range(3))
        w = 2.0 * np.pi * self.frequency_hz
        for start in range(0, len(flat), BLOCK):
            s = slice(start, start + BLOCK)
            arg = w * flat[s, None, None] + self.phase
            sin = np.sin(arg)
            q[s] = self.q0 + np.sum(self.amplitude * sin, axis=-1)
            qd[s] = np.sum(self.amplitude * w * np.cos(arg), axis=-1)
            qdd[s] = -np.sum(self.amplitude * w * w * sin, axis=-1)
        return tuple(a.reshape(times.shape + (n,)) for a in (q, qd, qdd))  # type: ignore[return-value]


@dataclass(frozen=True)
class Periodic:
    """``trajectory`` known to repeat every ``period_s``: at the times of a grid of ``fs_hz``, one period is evaluated and repeated.

    When every frequency of the trajectory is a whole multiple of ``1 / period_s``
    and a period is a whole number ``P`` of samples (:meth:`period_samples`),
    the value at ``t`` is the value at ``t mod period_s``: the samples
    ``k / fs_hz`` (``k = 0, 1, ...``) are the trajectory at ``(k mod P) / fs_hz``,
    and every period's samples are the same bits. Evaluating ``sin`` at the
    phase within the period rather than at ``t`` differs by roundoff only
    (the argument ``2 pi f t`` loses some 1e-13 rad at t = 600 s; the phase
    loses none of that). Other times, or another period, are evaluated as given.
    """

    trajectory: Trajectory
    period_s: float
    fs_hz: float

    def period_samples(self) -> int | None:
        """``P``, the samples of a period on the grid; None when ``period_s`` is not a period of the trajectory or not whole samples."""
        cycles = np.asarray(self.trajectory.frequency_hz, dtype=np.float64) * self.period_s
        samples = self.period_s * self.fs_hz
        whole = np.allclose(cycles, np.round(cycles), rtol=0.0, atol=1e-9) and abs(samples - round(samples)) < 1e-9 and round(samples) >= 1
        return int(round(samples)) if whole else None

    def at(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q, qd, qdd`` at times ``t`` (shape ``t.shape + (n,)``), as :meth:`Trajectory.at`."""
        times = np.asarray(t, dtype=np.float64)
        flat = times.reshape(-1)
        index = np.arange(len(flat))
        period = self.period_samples()
        if period is None or not np.array_equal(index * (1.0 / self.fs_hz), flat):  # not the grid from 0 (simulate_loop's times)
            return self.trajectory.at(times)
        one = self.trajectory.at(index[:period] * (1.0 / self.fs_hz))
        phase = index % period
        return tuple(a[phase].reshape(times.shape + (len(self.trajectory.q0),)) for a in one)  # type: ignore[return-value]


def exciting_trajectory(q0: np.ndarray, speed: np.ndarray, seed: int, *, harmonics: int = 5, f0_hz: float = 0.1) -> Trajectory:
    """A random sum of ``harmonics`` sines per joint at multiples of ``f0_hz`` (up to ``harmonics * f0_hz`` apart, random phases).

    Each joint's amplitudes are scaled so that the sum of the sines' velocity
    amplitudes is ``speed[j]`` (rad/s or m/s): its velocity never exceeds it.
    """
    rng = np.random.default_rng(seed)
    q0 = np.asarray(q0, dtype=np.float64)
    n = len(q0)
    k = np.stack([rng.permutation(np.arange(1, 2 * harmonics + 1))[:harmonics] for _ in range(n)]).astype(np.float64)
    f = f0_hz * k
    raw = rng.uniform(0.3, 1.0, (n, harmonics))
    amp = raw * (np.asarray(speed, dtype=np.float64)[:, None] / np.sum(raw * 2.0 * np.pi * f, axis=1, keepdims=True))
    return Trajectory(q0=q0, amplitude=amp, frequency_hz=f, phase=rng.uniform(0.0, 2.0 * np.pi, (n, harmonics)))


@dataclass(frozen=True)
class SimSettings:
    """Closed loop and sensors of :func:`simulate`.

    Attributes
    ----------
    fs_hz : float
        Control and logging rate (also the RK4 step).
    bandwidth_hz : float
        PD bandwidth per joint: ``Kp = M_jj w^2``, ``Kd = 2 zeta M_jj w`` at the initial pose.
    damping_ratio : float
        ``zeta`` of the PD.
    encoder_counts : int
        Encoder counts per revolution (a revolute joint's quantisation step is ``2 pi / counts``).
    encoder_step_m : float
        Quantisation step of a prismatic joint.
    torque_noise : tuple of float
        Standard deviation of the logged torque's Gaussian noise per joint (N·m or N); empty: none.
    v_smooth : float
        Velocity scale of the smooth Coulomb rule ``tanh(qd / v_smooth)``.
    seed : int
        Seed of the noise.
    """

    fs_hz: float = 1000.0
    bandwidth_hz: float = 5.0
    damping_ratio: float = 0.8
    encoder_counts: int = 2**17
    encoder_step_m: float = 1e-6
    torque_noise: tuple[float, ...] = ()
    v_smooth: float = 0.01
    seed: int = 0


@dataclass(frozen=True)
class RobotLog:
    """A simulated log: time (N,), measured ``q`` and ``tau`` (N, n), the true state and the reference."""

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_true: np.ndarray
    qd_true: np.ndarray
    q_ref: np.ndarray
    fs_hz: float


def encoder_step(robot: RobotModel, settings: SimSettings) -> np.ndarray:
    """Quantisation step of each joint's encoder (rad or m)."""
    return np.where(np.array(robot.kinds) == "prismatic", settings.encoder_step_m, 2.0 * np.pi / settings.encoder_counts)


def quantise(q: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Encoder reading of positions ``q``: rounded to each joint's ``step``."""
    return np.round(q / step) * step


def simulate(robot: RobotModel, pi: np.ndarray, trajectory: Trajectory, duration_s: float, settings: SimSettings = SimSettings()) -> RobotLog:
    """Simulate the arm with true standard parameters ``pi`` tracking ``trajectory`` for ``duration_s``.

    The state starts on the reference. Sample ``k`` logs the quantised position
    at ``t_k`` and the torque commanded over ``[t_k, t_k+1)`` plus noise, so the
    logged torque and the state at ``t_k`` obey the model of
    :func:`ilic_cli.robot.model.inverse_dynamics` (with the smooth Coulomb rule).
    """
    pin = import_pinocchio()
    n = robot.n
    true = pinocchio_model(robot, pi)
    tdata = true.createData()
    nominal = robot.pin
    ndata = nominal.createData()
    Fv, Fc, off = (robot.drive(pi, p) for p in ("Fv", "Fc", "offset"))
    dt = 1.0 / settings.fs_hz
    N = int(round(duration_s * settings.fs_hz))
    t = np.arange(N) * dt
    q_ref, qd_ref, qdd_ref = trajectory.at(t)
    noise = np.zeros((N, n))
    if settings.torque_noise:
        noise = np.random.default_rng(settings.seed).standard_normal((N, n)) * np.asarray(settings.torque_noise, dtype=np.float64)
    Mjj = np.diag(pin.crba(true, tdata, configuration(robot, q_ref[0])))
    w = 2.0 * np.pi * settings.bandwidth_hz
    kp, kd = Mjj * w * w, 2.0 * settings.damping_ratio * Mjj * w
    unbounded = any(robot.unbounded)
    step = encoder_step(robot, settings)
    aba, inv_vs = pin.aba, 1.0 / settings.v_smooth
    # the nominal feed-forward of the whole reference at once (it does not depend on the state)
    q_ref_c = configuration(robot, q_ref)
    ff_all = np.array([pin.rnea(nominal, ndata, a, b, c) for a, b, c in zip(q_ref_c, qd_ref, qdd_ref)])

    def accel(q: np.ndarray, qd: np.ndarray, u: np.ndarray) -> np.ndarray:
        f = u - Fv * qd - Fc * np.tanh(qd * inv_vs) - off
        return aba(true, tdata, configuration(robot, q) if unbounded else q, qd, f)

    q, qd = q_ref[0].copy(), qd_ref[0].copy()
    q_log, qd_log, tau_log = np.empty((N, n)), np.empty((N, n)), np.empty((N, n))
    prev = quantise(q, step)
    h = 0.5 * dt
    for k in range(N):
        qm = quantise(q, step)
        vm = (qm - prev) / dt if k else qd_ref[0]
        prev = qm
        u = ff_all[k] + kp * (q_ref[k] - qm) + kd * (qd_ref[k] - vm)
        q_log[k], qd_log[k], tau_log[k] = q, qd, u
        k1a = accel(q, qd, u)
        k2v = qd + h * k1a
        k2a = accel(q + h * qd, k2v, u)
        k3v = qd + h * k2a
        k3a = accel(q + h * k2v, k3v, u)
        k4v = qd + dt * k3a
        k4a = accel(q + dt * k3v, k4v, u)
        k1v = qd
        q = q + dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        qd = qd + dt / 6.0 * (k1a + 2.0 * k2a + 2.0 * k3a + k4a)
    if not (np.all(np.isfinite(q_log)) and np.all(np.isfinite(qd_log))):
        raise FloatingPointError("the simulation diverged")
    return RobotLog(t=t, q=quantise(q_log, step), tau=tau_log + noise, q_true=q_log, qd_true=qd_log, q_ref=q_ref, fs_hz=settings.fs_hz)
