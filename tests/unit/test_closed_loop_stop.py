"""The closed-loop iteration's stop rule (:func:`ilic_cli.closed_loop_id.iterate`), one joint's and an arm's.

The replays are scripted: iterate k's estimate is ``[k + 1]`` and its residual the script's k-th value, so the
rule is seen alone, without a simulation.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.closed_loop_id import STALL_ITERATIONS, ClosedLoopSettings, iterate
from ilic_cli.lsq import LSResult, solve


def _run(errors: list[float], *, minimises: bool, limit: int = 20, tol: float = 0.1) -> tuple[list[float], float, float, bool, str]:
    """``iterate`` over scripted residuals: the history's errors, the estimate, its residual, converged, the reason."""
    W = np.ones((3, 1))

    def step(Ws: np.ndarray, tau_s: np.ndarray, theta: np.ndarray) -> LSResult:
        return solve(W, np.full(3, theta[0] + 1.0), ("p",))  # the next iterate: theta + 1 (a 1 % change or more)

    def replay_at(theta: np.ndarray, k: int) -> tuple[int, np.ndarray, np.ndarray]:
        return k, W, np.full(3, errors[k])

    def residual(theta: np.ndarray, tau_s: np.ndarray) -> float:
        return float(tau_s[0])

    history, res, theta, eps, sim, tau_s, converged, reason = iterate(
        np.array([1.0]), replay_at, residual, step, 100.0, ClosedLoopSettings(max_iterations=limit, tolerance_pct=tol), minimises=minimises
    )
    assert sim == round(theta[0]) - 1 and tau_s[0] == eps  # the replay and force returned are the estimate's own
    assert res.theta[0] == theta[0]  # and so is its step (its standard deviations)
    return [it.error_norm for it in history], round(float(theta[0]), 9), eps, converged, reason


def test_didim_stops_at_its_error_floor_with_the_iterate_of_the_smallest_error() -> None:
    """Noise-free CTC: the output error falls, then wanders on the floor the replay's quantisation sets (3 % up and down)."""
    floor = [50.0, 40.0, 36.1, 37.2, 36.8, 35.0, 35.5, 34.7, 35.8]
    errors, theta, eps, converged, reason = _run(floor, minimises=True)
    assert len(errors) == 3 + STALL_ITERATIONS and errors == floor[: 3 + STALL_ITERATIONS]  # iteration 2's error is the smallest
    assert converged and theta == 3.0 and eps == 36.1 and "stopped falling" in reason and "iteration 2's" in reason


def test_a_falling_error_runs_as_birdys_rule_and_ends_at_the_last_iterate() -> None:
    """EMPS: the error falls every iteration until it moves by less than the tolerance."""
    errors, theta, eps, converged, reason = _run([120.48, 120.24, 120.19, 120.18], minimises=True)
    assert len(errors) == 3 and theta == 3.0 and converged and "residual norm moved by 0.0416 %" in reason


def test_at_the_limit_didim_keeps_the_smallest_error_and_iv_its_last_iterate() -> None:
    rises = [10.0, 9.0, 9.5, 8.0, 8.5, 7.9, 9.9, 7.0]  # never two rises in a row: only the limit stops it
    errors, theta, eps, converged, reason = _run(rises, minimises=True, limit=6)
    assert not converged and len(errors) == 7 and theta == 6.0 and eps == 7.9 and "iteration 5's, of the smallest" in reason
    errors, theta, eps, converged, reason = _run(rises, minimises=False, limit=6)
    assert not converged and theta == 7.0 and eps == 9.9 and reason == "iteration limit (6) reached"
    # IDIM-IV does not minimise its residual ||y - W theta||: rises never stop it
    errors, theta, eps, converged, reason = _run([50.0, 40.0, 36.1, 37.2, 36.8, 38.0, 39.0], minimises=False, limit=6)
    assert len(errors) == 7 and theta == 7.0 and not converged


@pytest.mark.parametrize("minimises", [True, False])
def test_an_error_above_the_start_is_never_the_estimate_of_a_step(minimises: bool) -> None:
    """When every step raises the error above the IDIM-LS start, there is no step's estimate to return but the last."""
    errors, theta, eps, converged, reason = _run([10.0, 11.0, 12.0, 13.0], minimises=minimises, limit=3)
    assert theta == 4.0 and eps == 13.0 and not converged
