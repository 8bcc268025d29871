"""IDIM-ILIC of an arm of n joints, per window (paper section V, eqs. 23-24, stacking every joint).

The 1-DOF design (:mod:`ilic_cli.idim_ilic`) with the arm's base regressor:

- the observation matrix of window ``k`` is the base regressor at the
  noise-free reference ``(q_r, qd_r, qdd_r)``: every joint's rows (eq. 23),
  its Coulomb columns the mean sign over each period (:func:`period_sign`);
- each joint's torque and its columns are low-pass filtered and decimated in
  parallel (:func:`ilic_cli.filtering.lowpass_decimate`, 5 Hz at 1 kHz in the paper);
- the joints' decimated systems are stacked and solved by least squares with
  the standard deviations of eqs. 8-10 (:func:`ilic_cli.lsq.solve`);
- only the *essential* parameters (``%sigma <= %sigma_max``,
  :func:`ilic_cli.idim_ilic.essential_mask`) replace the controller's values;
  the others keep theirs.

The closed loop (:func:`ilic_cli.robot.plant.simulate_loop`) is handed
:func:`ilic_step` as a function by the scenario (:mod:`ilic_cli.robot.scenario`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.filtering import lowpass_decimate
from ilic_cli.idim_ilic import ILICSettings, essential_mask
from ilic_cli.lsq import LSResult, finite_or_none, solve
from ilic_cli.robot.base import BaseParameters
from ilic_cli.robot.idim import active_columns, base_columns
from ilic_cli.robot.model import RobotModel


@dataclass(frozen=True)
class RobotWindow:
    """The estimate of window ``k`` (iteration k of the paper) and the controller's base parameters after its update."""

    k: int
    t_start: float
    t_end: float
    result: LSResult
    essential: np.ndarray
    beta: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {
            "k": self.k,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "parameters": self.result.parameters(),
            "essential": {n: bool(e) for n, e in zip(self.result.names, self.essential, strict=True)},
            "relative_error_pct": finite_or_none(self.result.relative_error_pct),
            "controller": dict(zip(self.result.names, self.beta.tolist(), strict=True)),
        }


def reference_system(
    robot: RobotModel, base: BaseParameters, q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray, fs_hz: float, settings: ILICSettings
) -> np.ndarray:
    """``W`` of one window: the base regressor at the reference, filtered and decimated, joint-major (K n, b).

    It needs the reference only, so the closed loop can have it computed while
    it simulates the window (:func:`ilic_cli.robot.plant.simulate_loop`'s ``prepare``);
    the torque is filtered apart (:func:`torque_rows`): the filter's output for a
    row does not depend on the rows filtered with it (:func:`ilic_cli.filtering.lowpass_decimate`).
    """
    active = active_columns(robot, base)
    # only the columns a joint's rows can touch (about half on ur5like), time contiguous, filtered in one call
    columns, rows = base_columns(robot, base, active, q_ref, qd_ref, qdd_ref, np.zeros((len(q_ref), robot.n)))
    coulomb = period_sign(np.asarray(qd_ref, dtype=np.float64))
    for j in range(robot.n):
        at = np.flatnonzero(base.kept[active[j]] == robot.index("Fc", j))
        if at.size:
            columns[rows[j] + at[0]] = coulomb[:, j]
    # the torque's rows (zeros here) are filtered too: picking the others out would copy the 14 MB of a 10 s window
    filtered = lowpass_decimate(columns, settings.factor(fs_hz), settings.cutoff_hz, fs_hz, settings.filter_order, axis=1)
    W = np.zeros((robot.n, filtered.shape[1], base.b))
    for j in range(robot.n):
        W[j][:, active[j]] = filtered[rows[j] : rows[j + 1] - 1].T
    return W.reshape(-1, base.b)


def torque_rows(tau: np.ndarray, fs_hz: float, settings: ILICSettings) -> np.ndarray:
    """``y`` of one window: each joint's torque (N, n) filtered and decimated as :func:`reference_system`'s columns, joint-major."""
    t = np.ascontiguousarray(np.asarray(tau, dtype=np.float64).T)
    return lowpass_decimate(t, settings.factor(fs_hz), settings.cutoff_hz, fs_hz, settings.filter_order, axis=1).reshape(-1)


def period_sign(qd: np.ndarray) -> np.ndarray:
    """The mean of ``sign(qd)`` over ``[t_k - T/2, t_k + T/2]`` (N, n), the velocity linear between the half-period points.

    The Coulomb column of a window: with the torque moved half a period
    (``torque_held``), each row is the mean of the equation over that interval,
    and the friction's sign flips within it at a reversal. On the 6-joint
    scenario this cut the error of the best-determined base parameters
    (%sigma < 0.1) from at most 0.108 % to at most 0.055 % (sign at the samples).
    """
    edges = np.vstack([qd[:1], 0.5 * (qd[1:] + qd[:-1]), qd[-1:]])
    a, b = edges[:-1], edges[1:]
    sa, sb = np.sign(a), np.sign(b)
    flip = sa != sb
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(flip, a / np.where(flip, a - b, 1.0), 1.0)
    return np.where(flip, sa * f + sb * (1.0 - f), sa)


def ilic_step(
    robot: RobotModel,
    base: BaseParameters,
    settings: ILICSettings,
    fs_hz: float,
    k: int,
    t: np.ndarray,
    reference: tuple[np.ndarray, np.ndarray, np.ndarray],
    tau: np.ndarray,
    beta: np.ndarray,
    *,
    torque_held: bool = True,
    system: np.ndarray | None = None,
) -> RobotWindow:
    """Estimate window ``k`` (reference ``(q_r, qd_r, qdd_r)``, measured torque ``tau``) and update the essential parameters of ``beta``.

    ``torque_held``: ``tau[k]`` is the command held over ``[t_k, t_k+1)`` (the
    closed loop's), so it is moved half a period later, ``(tau[k-1] + tau[k]) / 2``,
    as :func:`ilic_cli.robot.idim.prepare` does: on the 6-joint scenario this
    halves the true parameters' residual (0.20 % to 0.11 % before the plant's
    reversals were resolved). ``system``: the window's :func:`reference_system`, when
    computed already.
    """
    tau = np.asarray(tau, dtype=np.float64)
    if torque_held:
        tau = np.vstack([tau[:1], 0.5 * (tau[1:] + tau[:-1])])
    W = reference_system(robot, base, *reference, fs_hz, settings) if system is None else system
    y = torque_rows(tau, fs_hz, settings)
    result = solve(W, y, base.names, sigma="eq8")
    essential = essential_mask(result, settings.sigma_max_pct)
    return RobotWindow(k, float(t[0]), float(t[-1]), result, essential, np.where(essential, result.theta, np.asarray(beta, dtype=np.float64)))


def relative_errors_pct(windows: list[RobotWindow], truth: list[np.ndarray]) -> np.ndarray:
    """``100 |theta_k - beta_k| / |beta_k|`` per window and base parameter (inf where the truth is 0 and the estimate is not)."""
    est = np.array([w.result.theta for w in windows])
    true = np.array(truth)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(true != 0, 100.0 * np.abs(est - true) / np.abs(true), np.where(est == true, 0.0, np.inf))
