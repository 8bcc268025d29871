"""The ``robot-sim`` scenario: an arm in CTC with online IDIM-ILIC per window (paper Table I, per base parameter).

The arm's true parameters are the URDF's with rotor inertias, friction and
offsets (:func:`true_parameters`); the controller starts from the URDF's
inertial parameters with a guessed rotor inertia and no friction
(:func:`initial_model`, after the paper's eq. 28: a rough inertia, the rest 0).
The reference is a sum of sines whose period is the window (5 harmonics of
``1 / window_s``), so every window sees the same excitation, as the paper's
``T_cycle``: its samples repeat bit for bit from window to window
(:class:`ilic_cli.robot.simulate.Periodic`), and so does each window's system.
After each window :func:`ilic_cli.robot.ilic.ilic_step` updates the
controller's essential base parameters.

``payload``: a mass added to the last link at ``payload_at_s`` (its centre on
the joint axis at ``payload_offset_m``), to be tracked by the windows that follow.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.robot.base import BaseParameters, base_parameters
from ilic_cli.robot.dynamics import kept_vector
from ilic_cli.robot.ilic import RobotWindow, ilic_step, reference_system, relative_errors_pct
from ilic_cli.robot.model import RobotModel
from ilic_cli.robot.plant import LoopRun, LoopSettings, Segment, loop_times, simulate_loop
from ilic_cli.robot.replay import SampledReference
from ilic_cli.robot.simulate import Periodic, exciting_trajectory


@dataclass(frozen=True)
class RobotSimSettings:
    """The scenario: windows, excitation, loop and payload.

    Attributes
    ----------
    windows : int
        Number of IDIM-ILIC windows simulated.
    window_s : float
        T_obs, also the reference's period.
    q0, speed : tuple of float
        Centre of each joint's reference and the bound of its velocity (rad/s);
        empty: 0 and 1.5 rad/s for every joint.
    loop : LoopSettings
        Controller and sensors (the paper's CTC at 20 Hz; ``velocity="exact"`` for Table I).
    ilic : ILICSettings
        Filter, decimation and %sigma_max of the windows (paper: 5 Hz, 15 %).
    payload_kg, payload_at_s, payload_offset_m : float
        The payload on the last link (0 kg: none).
    initial_rotor_inertia : float
        The controller's initial guess of every ``Ia``.
    seed : int
        Seed of the reference.
    """

    windows: int = 5
    window_s: float = 10.0
    q0: tuple[float, ...] = ()
    speed: tuple[float, ...] = ()
    loop: LoopSettings = field(default_factory=lambda: LoopSettings(velocity="exact"))
    ilic: ILICSettings = field(default_factory=lambda: ILICSettings(window_s=10.0))
    payload_kg: float = 0.0
    payload_at_s: float = 0.0
    payload_offset_m: float = 0.05
    initial_rotor_inertia: float = 0.2
    seed: int = 1


@dataclass(frozen=True)
class RobotSimResult:
    """The run, the windows' estimates, and the true base parameters of each window (after a payload change: the new ones)."""

    base: BaseParameters
    run: LoopRun
    windows: list[RobotWindow]
    truth: list[np.ndarray]

    def relative_errors_pct(self) -> np.ndarray:
        """(windows, b): each window's estimate against its truth (:func:`ilic_cli.robot.ilic.relative_errors_pct`)."""
        return relative_errors_pct(self.windows, self.truth)

    def to_dict(self) -> dict[str, Any]:
        return {
            "scenario": "robot-sim",
            "base_parameters": self.base.to_dict(),
            "windows": [w.to_dict() for w in self.windows],
            "truth": [dict(zip(self.base.names, t.tolist(), strict=True)) for t in self.truth],
        }


def true_parameters(robot: RobotModel) -> np.ndarray:
    """The scenario's arm: the URDF with rotor inertias, viscous and Coulomb friction and offsets that decrease along the chain."""
    scale = np.linspace(1.0, 0.25, robot.n)
    values: dict[str, float] = {}
    for j, s in zip(robot.joints, scale):
        values |= {f"Ia_{j}": 0.35 * s, f"Fv_{j}": 2.0 * s, f"Fc_{j}": 3.0 * s, f"offset_{j}": 0.2 * s}
    return robot.parameters(values)


def initial_model(robot: RobotModel, rotor_inertia: float) -> np.ndarray:
    """The controller's first model: the URDF's inertial parameters, ``Ia`` guessed, no friction and no offset."""
    values = {f"{p}_{j}": 0.0 for j in robot.joints for p in ("Fv", "Fc", "offset")}
    return robot.parameters(values | {f"Ia_{j}": rotor_inertia for j in robot.joints})


def with_payload(robot: RobotModel, pi: np.ndarray, mass_kg: float, offset_m: float) -> np.ndarray:
    """``pi`` with a point mass on the last link, on its joint axis at ``offset_m`` from the joint frame's origin."""
    c = offset_m * robot.axes[-1]
    i = robot.index("m", robot.n - 1)
    pi = np.array(pi, dtype=np.float64)
    pi[i] += mass_kg
    pi[i + 1 : i + 4] += mass_kg * c
    # inertia of a point mass about the origin: m (|c|^2 E - c c'), as (xx, xy, yy, xz, yz, zz)
    Ic = mass_kg * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    pi[i + 4 : i + 10] += (Ic[0, 0], Ic[0, 1], Ic[1, 1], Ic[0, 2], Ic[1, 2], Ic[2, 2])
    return pi


def same_system(known: list[tuple[tuple[np.ndarray, ...], np.ndarray]], reference: tuple[np.ndarray, ...], make: Callable[[], np.ndarray]) -> np.ndarray:
    """The window system of ``reference`` made by ``make()``, or the one made for the last window if its reference holds the same bits.

    :func:`ilic_cli.robot.ilic.reference_system` is a pure function of the
    reference, and the periodic reference (:class:`ilic_cli.robot.simulate.Periodic`)
    repeats each window bit for bit: the system is made once, not once a window
    (some 80 ms each on the 6-joint arm). ``known`` holds the last one.
    """
    if known and all(np.array_equal(a, b) for a, b in zip(known[-1][0], reference, strict=True)):
        return known[-1][1]
    system = make()
    known[:] = [(tuple(np.array(a) for a in reference), system)]
    return system


def robot_sim(
    robot: RobotModel, settings: RobotSimSettings = RobotSimSettings(), *, sink: Any = None, truth: np.ndarray | None = None, true_state: bool = True
) -> RobotSimResult:
    """Run the scenario; ``sink(run, start, stop)`` receives the log window by window (:func:`ilic_cli.robot.record`).

    ``truth``: the arm's standard parameters (default :func:`true_parameters`; an identified model's
    :func:`ilic_cli.robot.dynamics.kept_vector`). ``true_state=False``: the run's true position and
    velocity are not kept (:func:`ilic_cli.robot.plant.simulate_loop`; the same log, estimates and models).
    """
    q0 = np.asarray(settings.q0 or np.zeros(robot.n), dtype=np.float64)
    speed = np.asarray(settings.speed or np.full(robot.n, 1.5), dtype=np.float64)
    trajectory = Periodic(exciting_trajectory(q0, speed, settings.seed, f0_hz=1.0 / settings.window_s), settings.window_s, settings.loop.fs_hz)
    duration = settings.windows * settings.window_s
    # the reference's samples (fresh memory: some 0.4 s for 600 s of 6 joints on this project's machine) made beside the base parameters' QR
    with ThreadPoolExecutor(1, thread_name_prefix="ilic-reference") as ahead:
        samples = ahead.submit(trajectory.at, loop_times(duration, settings.loop.fs_hz))
        base = base_parameters(robot)
    reference = SampledReference(*samples.result())
    pi = true_parameters(robot) if truth is None else np.asarray(truth, dtype=np.float64)
    changes = []
    if settings.payload_kg:
        changes.append((settings.payload_at_s, with_payload(robot, pi, settings.payload_kg, settings.payload_offset_m)))
    beta = [base.values(initial_model(robot, settings.initial_rotor_inertia))]
    windows: list[RobotWindow] = []
    ilic = replace(settings.ilic, window_s=settings.window_s)

    def update(segment: Segment, model: np.ndarray) -> np.ndarray:
        reference = (segment.q_ref, segment.qd_ref, segment.qdd_ref)
        window = ilic_step(robot, base, ilic, settings.loop.fs_hz, segment.k, segment.t, reference, segment.tau, beta[-1], system=segment.prepared)
        windows.append(window)
        beta.append(window.beta)
        return kept_vector(base.kept, window.beta, len(pi))

    model = kept_vector(base.kept, beta[0], len(pi))

    systems: list[tuple[tuple[np.ndarray, ...], np.ndarray]] = []

    def prepare(k: int, t: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray) -> np.ndarray:
        return same_system(systems, (q_ref, qd_ref, qdd_ref), lambda: reference_system(robot, base, q_ref, qd_ref, qdd_ref, settings.loop.fs_hz, ilic))

    run = simulate_loop(
        robot,
        pi,
        reference,
        duration,
        model,
        settings.loop,
        window_s=settings.window_s,
        update=update,
        changes=changes,
        sink=sink,
        prepare=prepare,
        true_state=true_state,
    )
    truths = []
    for w in windows:
        now = pi if not changes or w.t_end < changes[0][0] else changes[0][1]
        truths.append(base.values(now))
    return RobotSimResult(base, run, windows, truths)
