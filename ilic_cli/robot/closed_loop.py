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
iterations. The stop rule and the settings are the 1-DOF chain's
(:class:`ilic_cli.closed_loop_id.ClosedLoopSettings`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.closed_loop_id import DEFAULT_SETTINGS, METHODS, ClosedLoopSettings
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

    beta = start.theta
    Ws, ts = replay(beta)
    eps = residual(beta, ts)
    history = [(0, beta, eps)]
    converged, reason = False, f"iteration limit ({settings.max_iterations}) reached"
    res = start.result
    for k in range(1, settings.max_iterations + 1):
        if method == "didim":
            res = solve(Ws, yw - ts + Ws @ beta, base.names, sigma=ls_settings.sigma)
        else:
            res = solve_iv(Ws, Ww, yw, base.names, sigma=ls_settings.sigma)
        new = res.theta
        with np.errstate(divide="ignore", invalid="ignore"):
            change = np.abs(new - beta) / np.abs(beta)
        dtheta = float(100.0 * np.max(change[np.isfinite(change)], initial=0.0))
        Ws, ts = replay(new)
        new_eps = residual(new, ts)
        deps = 100.0 * abs(new_eps - eps) / eps if eps > 0 else 0.0
        history.append((k, new, new_eps))
        beta, eps = new, new_eps
        if deps < settings.tolerance_pct or dtheta < settings.tolerance_pct:
            converged, reason = True, f"moved by {min(deps, dtheta):.3g} % (< {settings.tolerance_pct:g} %) at iteration {k}"
            break
    return RobotClosedLoopResult(name, res, tuple(history), converged, reason)
