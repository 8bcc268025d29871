"""The refit by the closed loop's output error itself: every linear parameter and searched value at once, by Levenberg-Marquardt
with the closed loop's own sensitivities taken by finite differences of replays (:func:`output_error_gauss_newton`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import numpy as np

from ilic_cli.diagnosis.fits import OE_METHOD, Refit, ValueSearch, count
from ilic_cli.diagnosis.refit_search import ROUND_GAIN, slot_range, slot_value, slots_of, with_slot
from ilic_cli.diagnosis.search import at_edge
from ilic_cli.diagnosis.system import Step
from ilic_cli.diagnosis.verdicts import RefitOutcome
from ilic_cli.lsq import norm_pct, robust_covariance
from ilic_cli.parallel import ordered_map


class ExtraValue(NamedTuple):
    """A value the output error is fitted with that is no kept effect's (the friction law's ``vc``): its name, start and range."""

    effect: str
    parameter: str
    unit: str
    start: float
    bounds: tuple[float, float]


def output_error_refit(
    known: list[Step],
    steps: list[Step],
    names: tuple[str, ...],
    theta0: np.ndarray,
    grids: Mapping[str, np.ndarray],
    residual_of: Callable[[list[Step], np.ndarray, tuple[float, ...]], np.ndarray | None],
    error_inverse: float,
    y_norm: float,
    round_gain: float = ROUND_GAIN,
    joint: str = "prismatic",
    lead: str = "refitted instead by",
    extra: Sequence[ExtraValue] = (),
) -> Refit | str:
    """The refit by :func:`output_error_gauss_newton`: the linear parameters ``names`` and every searched value of the kept effects at once.

    The values enter as ratios to their start (``steps``'). The estimate is
    refused (the reason returned) when it lowers the output error by less
    than ``round_gain`` (:data:`ROUND_GAIN`) of ``error_inverse`` (%), or ends with a value on
    the edge of the range the closed loop searches it in
    (:func:`~ilic_cli.diagnosis.select.at_edge`), or an ``extra`` value on its bounds. ``residual_of(steps, theta,
    extra_values)``. Its covariance is that of the
    least squares on the final Jacobian, the residual's autocorrelation accounted for
    (:func:`~ilic_cli.lsq.robust_covariance`). ``lead``: the words the reason starts with.
    """
    slots = slots_of(known, steps, grids, joint)
    v0 = np.array([*(slot_value(steps[j].value, k) for j, _, _, k in slots), *(x.start for x in extra)])
    n_lin, n_slots = len(theta0), len(slots)

    def steps_at(ratio: np.ndarray) -> list[Step]:
        new = list(steps)
        for (j, _, _, k), v in zip(slots, v0[:n_slots] * ratio, strict=True):
            new[j] = Step(new[j].effect, with_slot(new[j].value, k, float(v)))
        return new

    def residual(z: np.ndarray) -> np.ndarray | None:
        return residual_of(steps_at(z[n_lin : n_lin + n_slots]), z[:n_lin], tuple(v0[n_slots:] * z[n_lin + n_slots :]))

    fit = output_error_gauss_newton(residual, np.r_[theta0, np.ones(len(v0))], first_gain=round_gain)
    error = norm_pct(float(np.linalg.norm(fit.residual)), y_norm)
    found = steps_at(fit.z[n_lin : n_lin + n_slots])
    values = [*(slot_value(found[j].value, k) for j, _, _, k in slots), *(v0[n_slots:] * fit.z[n_lin + n_slots :])]
    if not error < (1.0 - round_gain) * error_inverse:
        return f"the {OE_METHOD} gives {error:.3g} %, not {round_gain:.0%} lower ({fit.stop})"
    ranges = [*(slot_range(steps[j], k, grids[steps[j].effect.id]) for j, _, _, k in slots), *(np.asarray(x.bounds) for x in extra)]
    for (j, _, _, k), sub in zip(slots, ranges[:n_slots], strict=True):
        if k == 0 and (edge := at_edge(found[j].effect, sub, found[j].value, joint)):
            return f"the {OE_METHOD} ends with {edge}"
    for x, v in zip(extra, values[n_slots:], strict=True):
        if not x.bounds[0] < v < x.bounds[1]:
            return f"the {OE_METHOD} ends with {x.parameter} = {v:.4g} {x.unit} outside the range searched ({x.bounds[0]:.4g} to {x.bounds[1]:.4g})"
    cov = robust_covariance(fit.sensitivity, fit.residual)
    std = np.abs(v0) * np.sqrt(np.clip(np.diag(cov)[n_lin:], 0.0, None))
    searches = [
        ValueSearch(
            effect,
            pname,
            unit,
            float(v0[i]),
            values[i],
            values[i],
            float(std[i]),
            (float(ranges[i][0]), float(ranges[i][-1])),
            error_inverse,
            error,
            fit.replays,
            True,
            f"fitted on the closed loop with the linear parameters: {pname} {v0[i]:.4g} -> {values[i]:.4g} {unit}".strip(),
            k == 0,
        )
        for i, (effect, pname, unit, k) in enumerate(
            [*((steps[j].effect.id, p, u, k) for j, p, u, k in slots), *((x.effect, x.parameter, x.unit, 1) for x in extra)]
        )
    ]
    return Refit(
        True,
        f"{lead} a {OE_METHOD}, its sensitivities by finite differences of replays "
        f"({count(len(fit.history) - 1, 'iteration')}, {fit.replays} replays): closed-loop output error {error_inverse:.3g} % -> {error:.3g} %",
        found[len(known) :],
        names,
        theta=fit.z[:n_lin],
        cov=cov[:n_lin, :n_lin],
        value_std={s.effect: s.std for s in searches if s.primary},
        searches=searches,
        error_pct=error,
        method=OE_METHOD,
        outcome=RefitOutcome.OUTPUT_ERROR,
    )


class OutputErrorFit(NamedTuple):
    """The result of :func:`output_error_gauss_newton`."""

    z: np.ndarray
    """The parameters at the end."""
    residual: np.ndarray
    """The output residual there."""
    sensitivity: np.ndarray
    """``d(output)/dz`` by finite differences at the last point the Jacobian was taken (rows of ``residual``)."""
    history: list[float]
    """Residual norm at the start and after each step taken."""
    replays: int
    """Evaluations of the residual."""
    stop: str
    """Why it stopped."""


def output_error_gauss_newton(
    residual: Callable[[np.ndarray], np.ndarray | None],
    z0: np.ndarray,
    *,
    rel_step: float = 1e-2,
    max_iter: int = 8,
    tol: float = 1e-3,
    first_gain: float = 0.0,
) -> OutputErrorFit:
    """Levenberg-Marquardt on an output error whose sensitivities are taken by forward differences.

    ``residual(z)`` is the recorded minus the simulated output (``None``: no
    simulation at ``z``, an infinite error). Each iteration takes the Jacobian
    by one evaluation per parameter (step ``rel_step`` of ``max(|z_k|, 1e-3)``,
    evaluated side by side), then the damped Gauss-Newton step
    ``(J'J + lam diag(J'J)) dz = J'r``, the damping raised tenfold until the
    error falls (at most 5 tries) and lowered tenfold after. It stops when a
    step lowers the error by less than ``tol`` of it, or after ``max_iter``,
    and without trying a step when the undamped step's linear prediction
    lowers it by less than ``tol`` (less than ``first_gain`` on the first
    iteration: a fit that must gain that much to be kept need not be run on).
    This is the output-error criterion DIDIM minimises (Gautier, Janot,
    Vandanjon, IEEE TCST 21(2), 2013), with the closed loop's own sensitivity
    ``d tau_s / d z`` instead of DIDIM's regressor of the simulated states
    (:mod:`ilic_cli.closed_loop_id`). ``sensitivity`` is the last Jacobian
    taken, at the point before the last step.
    """
    z = np.asarray(z0, dtype=np.float64).copy()
    r = residual(z)
    evaluations = 1
    if r is None:
        return OutputErrorFit(z, np.full(1, np.inf), np.zeros((1, len(z))), [math.inf], evaluations, "the start does not simulate")
    e = float(np.linalg.norm(r))
    history = [e]
    J = np.zeros((len(r), len(z)))
    lam = 1e-3
    stop = f"{max_iter} iterations"
    for _ in range(max_iter):
        h = rel_step * np.maximum(np.abs(z), 1e-3)

        def shifted(k: int, z: np.ndarray = z, h: np.ndarray = h) -> np.ndarray | None:
            zk = z.copy()
            zk[k] += h[k]
            return residual(zk)

        cols = ordered_map(shifted, range(len(z)))
        evaluations += len(z)
        if any(c is None for c in cols):
            stop = "a parameter shifted for its sensitivity does not simulate"
            break
        J = np.column_stack([(r - c) / hk for c, hk in zip(cols, h, strict=True) if c is not None])
        predicted = float(np.linalg.norm(r - J @ np.linalg.lstsq(J, r, rcond=None)[0]))
        need = first_gain if len(history) == 1 else tol
        if not e > 0.0 or (e - predicted) / e < need:
            stop = f"its step is predicted to lower the error by less than {need:.2%}"
            break
        jtj, jtr = J.T @ J, J.T @ r
        damp = np.diag(np.diag(jtj))
        for _ in range(5):
            dz = np.linalg.lstsq(jtj + lam * damp, jtr, rcond=None)[0]
            rt = residual(z + dz)
            evaluations += 1
            et = math.inf if rt is None else float(np.linalg.norm(rt))
            if et < e:
                break
            lam *= 10.0
        else:
            stop = "no damping of its step lowers the error"
            break
        assert rt is not None
        z, r, gain, e = z + dz, rt, (e - et) / e, et
        lam = max(lam / 10.0, 1e-6)
        history.append(e)
        if gain < tol:
            stop = f"its step lowered the error by less than {tol:.2%}"
            break
    return OutputErrorFit(z, r, J, history, evaluations, stop)
