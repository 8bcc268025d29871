"""The closed-loop iteration's stop rule (:func:`ilic_cli.closed_loop_id.iterate`), one joint's and an arm's.

The replays are scripted: iterate k's residual is the script's k-th value and each step moves the estimate as the
test says, so the rule is seen alone, without a simulation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ilic_cli.closed_loop_id import ClosedLoopSettings, iterate
from ilic_cli.lsq import LSResult, solve


def _run(errors: list[float], move: Callable[[np.ndarray], np.ndarray], start: list[float], limit: int = 20) -> tuple[list[float], np.ndarray, bool, str]:
    """``iterate`` over scripted residuals: the history's errors, the estimate, converged, the reason."""
    names = tuple(f"p{i}" for i in range(len(start)))
    W = np.eye(len(start))

    def step(Ws: np.ndarray, tau_s: np.ndarray, theta: np.ndarray) -> LSResult:
        return solve(W, move(theta), names)  # the next iterate, exactly (W = I)

    def replay_at(theta: np.ndarray, k: int) -> tuple[int, np.ndarray, np.ndarray]:
        return k, W, np.full(len(start), errors[k])

    def residual(theta: np.ndarray, tau_s: np.ndarray) -> float:
        return float(tau_s[0])

    history, res, theta, eps, sim, tau_s, converged, reason = iterate(
        np.array(start), replay_at, residual, step, 100.0, ClosedLoopSettings(max_iterations=limit, tolerance_pct=0.1)
    )
    assert sim == len(history) - 1 and eps == history[-1].error_norm and np.array_equal(res.theta, theta)  # the last iterate's own
    return [it.error_norm for it in history], theta, converged, reason


def test_birdys_rule_stops_when_the_residual_settles() -> None:
    """EMPS's DIDIM: the error falls every iteration until it moves by less than the tolerance (0.0416 %)."""
    errors, theta, converged, reason = _run([120.48, 120.24, 120.19, 120.18], lambda th: th + 1.0, [1.0])
    assert len(errors) == 3 and theta[0] == 3.0 and converged and "residual norm moved by 0.0416 %" in reason


def test_at_the_limit_the_estimate_is_the_last_iterate() -> None:
    """A noise-free CTC log's DIDIM: the output error wanders at its floor (5-10 % up and down), never below the tolerance."""
    errors, theta, converged, reason = _run([37.5, 36.1, 37.2, 36.8, 35.0, 35.5, 34.7], lambda th: 1.5 * th, [1.0], limit=6)
    assert len(errors) == 7 and theta[0] == 1.5**6 and not converged and reason == "iteration limit (6) reached"


def test_a_parameter_at_exactly_zero_has_no_relative_change() -> None:
    """An arm's base parameter the model holds at 0 stays 0: the others' change decides (0/0 would never let it stop)."""
    errors, theta, converged, reason = _run([10.0, 9.0, 8.0, 7.0], lambda th: np.array([th[0] * (1.0 + 1e-5), 0.0]), [1.0, 0.0])
    assert len(errors) == 2 and theta[1] == 0.0 and converged and "largest relative parameter change was 0.001 %" in reason
