"""The refit's results: :class:`Refit` (what was refitted, or why the inverse model's estimates stand), :class:`ValueSearch` (one nonlinear
value searched on the closed loop), and :func:`plant_problem` (whether an estimate is a plant of the effects it names).

Shared by the refit's parts (:mod:`ilic_cli.diagnosis.closed_loop_refit`, :mod:`ilic_cli.diagnosis.refit_search`,
:mod:`ilic_cli.diagnosis.oe_fit`) and the refit stage (:mod:`ilic_cli.diagnosis.refit`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ilic_cli.closed_loop_id import ClosedLoopResult
from ilic_cli.diagnosis.segments import SegmentFit
from ilic_cli.diagnosis.system import Step
from ilic_cli.diagnosis.verdicts import RefitOutcome
from ilic_cli.effects import Fit
from ilic_cli.errors import ParameterError
from ilic_cli.lsq import finite_or_none
from ilic_cli.runlog import RunLog

METHOD = "DIDIM closed-loop refit"
"""The method the findings and the model file name when the refit is accepted."""

OE_METHOD = "closed-loop output-error fit by Levenberg-Marquardt"
"""How the refit is estimated when DIDIM's step does not lower the output error (:func:`output_error_gauss_newton`)."""

CLOSED_LOOP_SPREAD = (
    "the closed-loop fit's, given its model (its last step's sensitivities, the residual's autocorrelation accounted for): "
    "no bias of the estimate is in it, and the difference from the inverse model's may show one"
)
"""What the standard deviations of a :data:`METHOD` or :data:`OE_METHOD` estimate are (the report says it with them). Measured on
the robot corpus's five sets (``python benchmarks/corpus_robot.py --jobs 2``, and ``--reseed 1`` to ``4``): of its flexibilities
beyond 15 %, 4 of 6 lie beyond 1.96 of this σ; payload changes 3 of 5 (the covariance whitened by the residual's AR model,
stated before the sandwich of the least squares: 5 of 5, s401 and s491 within it now)."""

INVERSE_METHOD = "closed-loop value search with IDIM-LS"
"""The method named when DIDIM does not lower the output error but the closed-loop search of the nonlinear values does
(the linear parameters are then the inverse model's at the values found)."""

InverseFit = Callable[[list[Step]], tuple[tuple[str, ...], np.ndarray, np.ndarray]]
"""``steps -> (names, theta, cov)``: the inverse model's fit (and covariance) of ``base + steps``."""


@dataclass(frozen=True)
class ValueSearch:
    """The closed-loop search of one nonlinear parameter.

    Attributes
    ----------
    effect, parameter, unit : str
        The effect, the parameter searched and its unit.
    inverse : float
        The inverse model's value (the centre of the range).
    optimum : float
        The search's optimum.
    value : float
        The value kept: the optimum, or ``inverse`` when the optimum is on the
        edge or does not lower the error.
    std : float or None
        Standard deviation of ``value`` from the curvature of the profile (``None`` when not kept or not convex).
    bounds : (float, float)
        The range searched.
    error_inverse_pct, error_pct : float
        Predicted closed-loop output error (%, decimated force) at ``inverse`` and at ``optimum``.
    evaluations : int
        Replays made.
    accepted : bool
        ``value`` is the optimum.
    reason : str
        Why it was kept or not.
    primary : bool
        The effect's first nonlinear parameter (the one the grid is of), not its secondary one.
    """

    effect: str
    parameter: str
    unit: str
    inverse: float
    optimum: float
    value: float
    std: float | None
    bounds: tuple[float, float]
    error_inverse_pct: float
    error_pct: float
    evaluations: int
    accepted: bool
    reason: str
    primary: bool = True

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "parameter": self.parameter,
            "unit": self.unit,
            "inverse_model": finite_or_none(self.inverse),
            "optimum": finite_or_none(self.optimum),
            "value": finite_or_none(self.value),
            "std": None if self.std is None else finite_or_none(self.std),
            "range_searched": [finite_or_none(b) for b in self.bounds],
            "closed_loop_error_pct": {"inverse_model": finite_or_none(self.error_inverse_pct), "optimum": finite_or_none(self.error_pct)},
            "replays": self.evaluations,
            "accepted": self.accepted,
            "reason": self.reason,
        }


@dataclass
class Refit:
    """The closed-loop refit of the final model, or why the inverse model's estimates are kept.

    Attributes
    ----------
    accepted : bool
        The closed-loop estimates replace the inverse model's.
    reason : str
        What was done, or why not.
    steps : list of Step
        The kept effects (not a model file's) with their nonlinear values (closed-loop when accepted).
    names : tuple of str
        Column names of the refitted model.
    theta, cov : ndarray
        DIDIM's estimate and covariance (``None`` when DIDIM did not run to the end).
    value_std : dict
        Effect id -> standard deviation of its (primary) nonlinear value from the closed-loop search.
    searches : list of ValueSearch
        One per nonlinear parameter searched.
    error_inverse_pct, error_pct : float or None
        Closed-loop output error (%, the decimated force, DIDIM's criterion) of the inverse model's estimate and of the refit.
    didim : ClosedLoopResult or None
        The final DIDIM run (iterations, stop reason); ``None`` for :data:`INVERSE_METHOD`.
    simulated : RunLog or None
        The replay of the refitted model (the final DIDIM iteration's).
    method : str
        :data:`METHOD`, or :data:`INVERSE_METHOD` when DIDIM was not kept but the search of the nonlinear values was,
        or :data:`ilic_cli.diagnosis.segments.METHOD` for Stribeck friction found at the dwells.
    segments : SegmentFit or None
        The open-loop segments' fit (:mod:`ilic_cli.diagnosis.segments`), when one was made.
    outcome : RefitOutcome
        What was done (:class:`~ilic_cli.diagnosis.verdicts.RefitOutcome`).
    """

    accepted: bool
    reason: str
    steps: list[Step]
    names: tuple[str, ...]
    theta: np.ndarray | None = None
    cov: np.ndarray | None = None
    value_std: dict[str, float | None] = field(default_factory=dict)
    searches: list[ValueSearch] = field(default_factory=list)
    error_inverse_pct: float | None = None
    error_pct: float | None = None
    didim: ClosedLoopResult | None = None
    simulated: RunLog | None = field(default=None, repr=False)
    method: str = METHOD
    segments: SegmentFit | None = None
    outcome: RefitOutcome = RefitOutcome.NOT_LOWERED
    """What was done, typed (``reason`` says it in words; ``accepted`` whether the estimates replace the inverse model's)."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "accepted": self.accepted,
            "reason": self.reason,
            "open_loop_segments": None if self.segments is None else self.segments.to_dict(),
            "closed_loop_error_pct": {
                "inverse_model": None if self.error_inverse_pct is None else finite_or_none(self.error_inverse_pct),
                "closed_loop": None if self.error_pct is None else finite_or_none(self.error_pct),
            },
            "searches": [s.to_dict() for s in self.searches],
            "didim": None
            if self.didim is None
            else {
                "iterations": self.didim.n_iterations,
                "converged": self.didim.converged,
                "stop_reason": self.didim.stop_reason,
                "parameters": self.didim.result.parameters(),
            },
        }


class Point(NamedTuple):
    """One evaluation of the closed-loop profile: a DIDIM step from an estimate at one value."""

    error: float
    """Predicted output error after the step (%, decimated force)."""
    theta: np.ndarray
    """The estimate after the step."""
    at_anchor: float
    """Output error of the estimate the step started from (%)."""
    rho: float
    """Lag-1 autocorrelation of the predicted residual."""
    anchor: np.ndarray
    """The estimate the step started from."""


def estimate(fit: Refit) -> np.ndarray:
    """The estimate of a refit that has one (the output-error refit always sets it)."""
    assert fit.theta is not None
    return fit.theta


def plant_problem(steps: list[Step] | tuple[Step, ...], names: tuple[str, ...], theta: np.ndarray, *, joint: str) -> str | None:
    """Why the estimate ``theta`` of the model with ``steps`` is not a plant of the effects it names, else ``None`` (the
    reason in the units of a ``joint`` of that type).

    Each effect must give plant parameters (:meth:`~ilic_cli.effects.Effect.fit_to_plant`) that pass
    their checks (:meth:`~ilic_cli.effects.Effect.values`), and must not be outside its physics
    (:attr:`~ilic_cli.effects.Effect.impossible`, e.g. a Stribeck level below Coulomb).
    """
    col = 0
    start = {n: i for i, n in enumerate(names)}
    for st in steps:
        e = st.effect
        cols = [start[c] for c in e.column_names if c in start]
        col += len(cols)
        if e.impossible is not None and cols:
            why = e.impossible(np.asarray(theta)[cols], st.value, joint)
            if why:
                return f"{e.id}: {why}"
        if not e.plant:
            continue
        _, plant, note = e.fit_to_plant(Fit(names, np.asarray(theta), np.zeros((len(theta), len(theta))), st.value, joint=joint))
        if plant is None:
            return f"{e.id}: {note or 'no plant form'}"
        try:
            e.values(plant)
        except ParameterError as exc:
            return f"{e.id}: {exc.problem}"
    return None


def count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless one (``1 iteration``, ``3 iterations``)."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"
