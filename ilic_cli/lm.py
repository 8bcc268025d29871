"""Levenberg-Marquardt on a simulated output, its sensitivities by forward differences (the output-error fits); and
:func:`minimise`, the bounded one-dimensional minimisation every search of one value refines with.

The unknowns are parameters ``p`` and, for multiple shooting, each stretch's initial state ``(q, qd)``; each
stretch's output depends on its own state only, so the states of all stretches are perturbed at once and a
Jacobian costs ``len(p) + 2`` evaluations, run side by side (:func:`ilic_cli.parallel.ordered_map`). The columns
are scaled to unit norm; the damping is raised fourfold until the error falls and lowered tenfold after.

Pure numerics: the residual is passed in. (The open-loop segments' fit of the diagnosis,
:func:`ilic_cli.diagnosis.segments.fit_segments`, runs the same scheme on its own.)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ilic_cli.errors import IlicError
from ilic_cli.parallel import ordered_map

DQ_M = 1e-6
"""Finite-difference step of a stretch's initial position (m)."""

DV_MPS = 1e-4
"""Finite-difference step of a stretch's initial velocity (m/s)."""

FLOOR = 1e-2
"""A value's finite-difference step is ``rel_step`` of ``max(|value|, FLOOR)`` (an offset near zero still moves)."""


Residual = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``(parameters, states (s, 2)) -> residual``; raises :class:`~ilic_cli.errors.IlicError` where the model does not simulate."""


def _evaluator(residual: Residual) -> Callable[[np.ndarray, np.ndarray], np.ndarray | None]:
    """``residual``, ``None`` where the model does not simulate or the residual is not finite."""

    def evaluate(p: np.ndarray, x: np.ndarray) -> np.ndarray | None:
        try:
            r = residual(p, x)
        except IlicError:
            return None
        return r if np.all(np.isfinite(r)) else None

    return evaluate


def _jacobian(
    evaluate: Callable[[np.ndarray, np.ndarray], np.ndarray | None],
    p: np.ndarray,
    x: np.ndarray,
    base: np.ndarray,
    steps: np.ndarray,
    state_steps: tuple[float, float],
) -> np.ndarray | None:
    """Forward differences of the residual in each parameter and (all stretches at once) in each state component; ``None``
    where a shifted point does not simulate."""
    ng, ns = len(p), len(x)
    fit_states = ns > 0
    seg_len = len(base) // ns if fit_states else 0

    def probe_parameter(k: int) -> np.ndarray | None:
        return evaluate(p + steps[k] * np.eye(ng)[k], x)

    def probe_state(c: int) -> np.ndarray | None:
        return evaluate(p, x + state_steps[c] * np.eye(2)[c])

    jobs: list[Callable[[], np.ndarray | None]] = [functools.partial(probe_parameter, k) for k in range(ng)]
    if fit_states:
        jobs += [functools.partial(probe_state, c) for c in (0, 1)]
    out = ordered_map(lambda job: job(), jobs)
    if any(o is None for o in out):
        return None
    J = np.zeros((len(base), ng + 2 * ns))
    for k in range(ng):
        J[:, k] = (out[k] - base) / steps[k]
    for c in (0, 1) if fit_states else ():
        col = (out[ng + c] - base) / state_steps[c]
        for j in range(ns):
            J[j * seg_len : (j + 1) * seg_len, ng + 2 * j + c] = col[j * seg_len : (j + 1) * seg_len]
    return J


def _damped_step(
    evaluate: Callable[[np.ndarray, np.ndarray], np.ndarray | None], J: np.ndarray, r: np.ndarray, p: np.ndarray, x: np.ndarray, e: float, lam: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, int] | None:
    """The first damped step (damping raised fourfold each time) that lowers the squared error ``e``:
    ``(p, x, r, e, damping, evaluations)``; ``None`` when none does before the damping passes 1e8
    (:func:`_failed_evaluations` counts what that search spent)."""
    ng, ns = len(p), len(x)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    Js = J / scale
    A, g = Js.T @ Js, Js.T @ r
    D = np.diag(np.where(np.diag(A) > 0, np.diag(A), 1.0))
    evaluations = 0
    while lam <= 1e8:
        d = -np.linalg.solve(A + lam * D, g) / scale
        p1, x1 = p + d[:ng], x + d[ng:].reshape(ns, 2)
        r1 = evaluate(p1, x1)
        evaluations += 1
        e1 = np.inf if r1 is None else float(r1 @ r1)
        if r1 is not None and e1 < e:  # r1 is None -> e1 is inf
            return p1, x1, r1, e1, max(lam / 10.0, 1e-9), evaluations
        lam *= 4.0
    return None


def levenberg_marquardt(
    residual: Residual,
    p0: np.ndarray,
    x0: np.ndarray,
    steps: np.ndarray,
    *,
    state_steps: tuple[float, float] = (DQ_M, DV_MPS),
    max_iterations: int = 40,
    tolerance: float | None = None,
) -> dict[str, Any]:
    """Minimise ``|residual(p, x)|^2`` over the parameters ``p`` and the stretches' states ``x`` (see the module's stopping rule).

    The states of all stretches are perturbed at once (each stretch's output depends on its own state only), so a
    Jacobian costs ``len(p) + 2`` residuals (``len(p) + 1`` evaluations side by side with the base).
    Returns the estimate, its covariance (parameters then states), the residual and the history.
    """
    p, x = np.asarray(p0, dtype=np.float64).copy(), np.asarray(x0, dtype=np.float64).reshape(-1, 2).copy()
    ng, ns = len(p), len(x)
    per_jacobian = ng + (2 if ns > 0 else 0)
    evaluate = _evaluator(residual)
    r0 = evaluate(p, x)
    if r0 is None:
        raise IlicError(None, "the starting estimate does not simulate")
    r = r0
    e = e0 = float(r @ r)
    dof = max(len(r) - ng - 2 * ns, 1)
    lam, it, evaluations, converged = 1e-3, 0, 1, False
    history = [e]
    stop = f"iteration limit ({max_iterations}) reached"
    J = _jacobian(evaluate, p, x, r, steps, state_steps)
    evaluations += per_jacobian
    if J is None:
        raise IlicError(None, "a parameter shifted for its sensitivity does not simulate at the start")
    while it < max_iterations:
        it += 1
        step = _damped_step(evaluate, J, r, p, x, e, lam)
        if step is None:
            evaluations += _failed_evaluations(lam)
            converged, stop = True, f"no damped step lowers the squared error (iteration {it}): at its least"
            break
        p, x, r, e1, lam, spent = step
        evaluations += spent
        drop, e = e - e1, e1
        history.append(e)
        need = (ng + 2 * ns) / dof if tolerance is None else tolerance
        if drop < need * e:
            converged = True
            rule = f"k/dof = {need:.3g}" if tolerance is None else f"the tolerance {need:.3g}"
            stop = f"the step lowered the squared error by {drop / e:.3g} of it, less than {rule} (iteration {it})"
            break
        J1 = _jacobian(evaluate, p, x, r, steps, state_steps)
        evaluations += per_jacobian
        if J1 is None:
            stop = "a parameter shifted for its sensitivity does not simulate"
            break
        J = J1
    cov = (e / dof) * np.linalg.pinv(J.T @ J)
    return {
        "p": p,
        "x": x,
        "cov": cov,
        "r": r,
        "sse": e,
        "sse_start": e0,
        "history": history,
        "iterations": it,
        "evaluations": evaluations,
        "converged": converged,
        "stop": stop,
        "samples": len(r),
    }


def _failed_evaluations(lam: float) -> int:
    """Evaluations a search from damping ``lam`` spends before the damping passes 1e8 (as :func:`_damped_step` counts them)."""
    n = 0
    while lam <= 1e8:
        n += 1
        lam *= 4.0
    return n


def fd_steps(theta: np.ndarray, rel_step: float) -> np.ndarray:
    """Finite-difference steps of the parameters (:data:`FLOOR`)."""
    return rel_step * np.maximum(np.abs(theta), FLOOR)


def minimise(f: Any, lo: float, hi: float, use_log: bool, rel_tol: float = 1e-4) -> float:
    """Bounded 1-D minimisation of ``f`` on ``[lo, hi]`` (on a log scale when ``use_log``), to ``rel_tol`` of the range on that scale."""
    from scipy.optimize import minimize_scalar  # deferred: scipy.optimize is slow to import

    fwd = math.log if use_log else (lambda v: v)
    inv = math.exp if use_log else (lambda u: u)
    a, b = fwd(lo), fwd(hi)
    res = minimize_scalar(lambda u: f(inv(u)), bounds=(a, b), method="bounded", options={"xatol": rel_tol * abs(b - a) + 1e-12})
    return float(inv(res.x))
