"""DIDIM and IDIM-IV of an arm of n joints, iterated on closed-loop simulations (the 1-DOF design of :mod:`ilic_cli.closed_loop_id`).

Both start from the IDIM-LS estimate. At iteration ``k`` the caller's
``simulate(beta)`` runs the log's reference through the log's controller with
the plant of the previous estimate (:func:`ilic_cli.robot.plant.simulate_loop`
with :func:`ilic_cli.robot.dynamics.kept_vector`: this module imports no
plant) and returns the simulated positions and torques. The simulated log is
prepared as the measured one (:func:`ilic_cli.robot.idim.prepare`, with the
measured system's rows), giving ``W_s`` and the decimated ``tau_s``:

- **DIDIM**: Gauss-Newton on the output error with ``d tau_s / d beta ~= W_s``,
  ``beta_k = beta_{k-1} + W_s^+ (y - tau_s)``;
- **IDIM-IV**: instruments ``Z = W_s``, ``beta_k = (Z' W)^-1 Z' y`` (:func:`ilic_cli.lsq.solve_iv`).

Each joint's rows are weighted by the IDIM-WLS estimate's error standard
deviations (:func:`ilic_cli.robot.idim.solve_system`), kept over the
iterations. The iteration, its stop rule and the settings are the 1-DOF chain's
(:func:`ilic_cli.closed_loop_id.iterate`, :class:`ilic_cli.closed_loop_id.ClosedLoopSettings`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.closed_loop_id import DEFAULT_SETTINGS, METHODS, ClosedLoopSettings, iterate
from ilic_cli.errors import ParameterError
from ilic_cli.idim_ls import LSSettings
from ilic_cli.lsq import LSResult, finite_or_none, solve, solve_iv
from ilic_cli.robot.base import BaseParameters
from ilic_cli.robot.idim import RobotSystem, prepare, solve_system
from ilic_cli.robot.model import RobotModel

Simulator = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``beta -> (q, tau)`` (N, n) of the closed loop with the plant of base parameters ``beta``."""


@dataclass(frozen=True)
class RobotClosedLoopResult:
    """A DIDIM or IDIM-IV estimate of the base parameters, with its iterations."""

    method: str
    result: LSResult
    history: tuple[tuple[int, np.ndarray, float], ...]
    """``(k, beta_k, eps_k)``; k = 0 is the IDIM-WLS start."""
    converged: bool
    stop_reason: str

    @property
    def theta(self) -> np.ndarray:
        return self.result.theta

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "parameters": self.result.parameters(),
            "iterations": [{"k": k, "error_norm": finite_or_none(e)} for k, _, e in self.history],
            "converged": self.converged,
            "stop_reason": self.stop_reason,
        }


def closed_loop_identify(
    method: str,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    robot: RobotModel,
    base: BaseParameters,
    simulate: Simulator,
    ls_settings: LSSettings = LSSettings(),
    settings: ClosedLoopSettings | None = None,
    *,
    min_speed: float = 0.0,
    torque_held: bool = False,
) -> RobotClosedLoopResult:
    """DIDIM (``method="didim"``) or IDIM-IV (``"iv"``) of the base parameters from measured ``q, tau`` (N, n).

    ``min_speed`` and ``torque_held`` as :func:`ilic_cli.robot.idim.prepare`;
    ``simulate`` as :data:`Simulator`.
    """
    if method not in METHODS:
        raise ParameterError("method", method, f"one of {', '.join(METHODS)}")
    name = METHODS[method]
    settings = settings or DEFAULT_SETTINGS[method]
    measured = prepare(q, tau, fs_hz, robot, base, ls_settings, min_speed=min_speed, torque_held=torque_held)
    start = solve_system(measured)
    w = 1.0 / start.joint_std[measured.joint]
    Ww, yw = measured.W * w[:, None], measured.y * w

    def replay(beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q_s, tau_s = simulate(beta)
        sim: RobotSystem = prepare(q_s, tau_s, fs_hz, robot, base, ls_settings, torque_held=torque_held, keep=measured.kept)
        return sim.W * w[:, None], sim.y * w

    def residual(beta: np.ndarray, tau_s: np.ndarray) -> float:
        return float(np.linalg.norm(yw - tau_s if method == "didim" else yw - Ww @ beta))

    def step(Ws: np.ndarray, ts: np.ndarray, beta: np.ndarray) -> LSResult:
        if method == "didim":
            return solve(Ws, yw - ts + Ws @ beta, base.names, sigma=ls_settings.sigma)
        return solve_iv(Ws, Ww, yw, base.names, sigma=ls_settings.sigma)

    def replay_at(beta: np.ndarray, k: int) -> tuple[None, np.ndarray, np.ndarray]:
        return (None, *replay(beta))

    history, res, _, _, _, _, converged, reason = iterate(start.theta, replay_at, residual, step, float(np.linalg.norm(yw)), settings)
    return RobotClosedLoopResult(name, res, tuple((it.k, it.theta, it.error_norm) for it in history), converged, reason)
