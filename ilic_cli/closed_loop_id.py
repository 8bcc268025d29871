"""Closed-loop identification: DIDIM and IDIM-IV, iterated on closed-loop simulations of the log.

Both start from the IDIM-LS estimate and, at each iteration ``k``, replay the
log's reference through the log's own controller with the plant of the
previous estimate ``theta_{k-1}`` (:func:`ilic_cli.simulation.replay.replay`),
and build the IDIM regressor ``W_s`` on the simulated position with the same
filtering, differentiation and parallel decimation as IDIM-LS
(:func:`ilic_cli.idim_ls.lsq_rows`):

* **DIDIM** (Gautier, Janot, Vandanjon, IEEE TCST 21(2), 2013): the
  parameters minimise the error between the measured force and the force of
  the closed-loop simulation. The Gauss-Newton step takes the Jacobian
  ``d tau_s / d theta ~= W_s`` (the sensitivity of the simulated states
  neglected: a stiff loop tracks the same reference whatever theta) and is the
  linear least squares ``theta_k = theta_{k-1} + W_s^+ (y - tau_s(theta_{k-1}))``.
  The plain form ``argmin ||y - W_s theta||`` would assume ``tau_s = W_s theta``,
  which the held command breaks (3.4 % on our plant; Fv -2.5 % biased).
* **IDIM-IV** (Janot, Vandanjon, Gautier, IEEE TCST 22(1), 2014): the
  instruments are ``Z = W_s(theta_{k-1})``, noise-free and correlated with the
  measured regressor ``W``: ``theta_k = (Z' W)^-1 Z' y`` (:func:`ilic_cli.lsq.solve_iv`).

The stop rule is the one of the BIRDy reference implementation: stop when
the residual norm ``eps_k`` (DIDIM: ``||y - W_s theta_k||``; IV:
``||y - W theta_k||``) moves by less than ``tolerance_pct`` relative to
``eps_{k-1}``, or the largest relative parameter change
``max |theta_k - theta_{k-1}| / |theta_{k-1}|`` is below it, or after
``max_iterations``. The estimate is the last iterate, with the standard
deviations of its own step (DIDIM: eq. 9 on ``W_s``; IV: the IV covariance).
One iteration (:func:`iterate`) for one joint and for an arm's n
(:mod:`ilic_cli.robot.closed_loop`).
Pure numerics on a :class:`~ilic_cli.runlog.RunLog` in memory: no file I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any, TypeVar

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.effects import EFFECTS, Fit
from ilic_cli.errors import IdentificationError, IlicError, ParameterError
from ilic_cli.estimators.base import LoopSimulator
from ilic_cli.filtering import butter_lowpass_zero_phase
from ilic_cli.idim_ls import LSSettings, lsq_rows
from ilic_cli.lsq import LSResult, finite_or_none, norm_pct, relative_error_pct, solve, solve_iv
from ilic_cli.parameters import PARAMETERS
from ilic_cli.prepare import PreparedLog, prepare_log
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.usable import identification_speed_noise, with_rest

METHODS = {"didim": "DIDIM", "iv": "IDIM-IV"}
"""Closed-loop methods: option value -> the name reports use."""


@dataclass(frozen=True)
class ClosedLoopSettings:
    """Iteration of DIDIM / IDIM-IV.

    Attributes
    ----------
    max_iterations : int
        Most iterations (closed-loop simulations plus one linear step each).
    tolerance_pct : float
        Stop when the residual norm or the largest relative parameter change
        moves by less than this (percent; BIRDy: 2.5 %).
    """

    max_iterations: int = 10
    tolerance_pct: float = 2.5

    def __post_init__(self) -> None:
        if not (isinstance(self.max_iterations, (int, np.integer)) and self.max_iterations >= 1):
            raise ParameterError("max_iterations", self.max_iterations, "a positive integer")
        if not (np.isfinite(self.tolerance_pct) and self.tolerance_pct > 0):
            raise ParameterError("tolerance_pct", self.tolerance_pct, "a positive percentage")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


DEFAULT_SETTINGS = {"didim": ClosedLoopSettings(max_iterations=20, tolerance_pct=0.1), "iv": ClosedLoopSettings(max_iterations=10, tolerance_pct=2.5)}
"""Defaults: IDIM-IV as BIRDy (10 iterations, 2.5 %); DIDIM to 0.1 % (it converges in 3-5 steps on EMPS, an output-error fit worth finishing)."""


@dataclass(frozen=True)
class Iteration:
    """One iteration: the estimate, its residual norm and how much it moved.

    Attributes
    ----------
    k : int
        Iteration number (0: the IDIM-LS start).
    theta : ndarray
        Estimate after this iteration.
    error_norm, relative_error_pct : float
        Residual norm ``eps_k`` (see the module) and ``100 eps_k / ||y||``.
    parameter_change_pct : float or None
        ``100 max |theta_k - theta_{k-1}| / |theta_{k-1}|`` (``None`` at k = 0).
    error_change_pct : float or None
        ``100 |eps_k - eps_{k-1}| / eps_{k-1}`` (``None`` at k = 0).
    """

    k: int
    theta: np.ndarray
    error_norm: float
    relative_error_pct: float
    parameter_change_pct: float | None = None
    error_change_pct: float | None = None

    def to_dict(self, names: tuple[str, ...]) -> dict[str, Any]:
        return {
            "k": self.k,
            "parameters": {n: finite_or_none(v) for n, v in zip(names, self.theta, strict=True)},
            "error_norm": finite_or_none(self.error_norm),
            "relative_error_pct": finite_or_none(self.relative_error_pct),
            "parameter_change_pct": None if self.parameter_change_pct is None else finite_or_none(self.parameter_change_pct),
            "error_change_pct": None if self.error_change_pct is None else finite_or_none(self.error_change_pct),
        }


STD_SOURCE = {
    "DIDIM": "eq. 9 of the final least-squares step, on the regressor of the simulated closed loop",
    "IDIM-IV": "IV covariance sigma^2 (Z'W)^-1 Z'Z (W'Z)^-1 of the final step",
}
"""Where each method's standard deviations come from."""

RESIDUAL = {
    "DIDIM": "output error ||y - tau_s(theta)|| (the closed-loop simulated force)",
    "IDIM-IV": "inverse-model residual ||y - W theta|| (the measured regressor)",
}
"""What each method's residual history measures: not the same quantity, so never one axis."""


@dataclass(frozen=True)
class ClosedLoopResult:
    """A DIDIM or IDIM-IV estimate with its iterations and convergence.

    Attributes
    ----------
    method : str
        ``DIDIM`` or ``IDIM-IV``.
    model : str
        Model structure name.
    result : LSResult
        Final estimate with the standard deviations of its step (:data:`STD_SOURCE`).
    settings, ls_settings : the iteration and the IDIM filtering.
    iterations : tuple of Iteration
        From the IDIM-LS start (k = 0) to the final estimate.
    converged : bool
        A tolerance was met before the iteration limit.
    stop_reason : str
        Which rule stopped the iteration.
    closed_loop_error_pct : dict
        Relative errors (%) of position, velocity and force of the replay
        with the final estimate against the log
        (:func:`relative_errors`).
    t, y, y_hat : ndarray
        Time of the decimated rows, measured force, and the final model's
        force on them (DIDIM: ``W_s theta``; IV: ``W theta``).
    """

    method: str
    model: str
    result: LSResult
    settings: ClosedLoopSettings
    ls_settings: LSSettings
    iterations: tuple[Iteration, ...]
    converged: bool
    stop_reason: str
    closed_loop_error_pct: dict[str, float] = field(default_factory=dict)
    t: np.ndarray | None = None
    y: np.ndarray | None = None
    y_hat: np.ndarray | None = None

    @property
    def n_iterations(self) -> int:
        """Iterations run after the IDIM-LS start."""
        return len(self.iterations) - 1

    def to_dict(self) -> dict[str, Any]:
        names = self.result.names
        return {
            "method": self.method,
            "model": self.model,
            **self.result.to_dict(),
            "std_source": STD_SOURCE[self.method],
            "converged": self.converged,
            "iterations": self.n_iterations,
            "stop_reason": self.stop_reason,
            "residual": RESIDUAL[self.method],
            "residual_history": [it.to_dict(names) for it in self.iterations],
            "closed_loop_error_pct": {k: finite_or_none(v) for k, v in self.closed_loop_error_pct.items()},
            "settings": {**self.settings.to_dict(), "idim": self.ls_settings.to_dict()},
        }

    def to_frame(self) -> Any:
        """One row per parameter: value, std, relative std."""
        import pandas as pd  # deferred: pandas is slow to import and only tables need it

        r = self.result
        return pd.DataFrame({"parameter": r.names, "value": r.theta, "std": r.std, "rel_std_pct": r.rel_std_pct})


def plant_of(
    names: tuple[str, ...], theta: np.ndarray, effects: Mapping[str, Any] | None = None, hold_s: float = 0.0
) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """The plant an estimate describes: rigid parameters and effects (:meth:`ilic_cli.effects.Effect.fit_to_plant`).

    ``effects``: effect id -> its nonlinear value (``None`` for a linear
    effect), as the columns of the model were built with. ``hold_s``: half a
    sample period when the logged force is the held command
    (:meth:`ilic_cli.effects.Effect.plant_entries`).
    """
    theta = np.asarray(theta, dtype=np.float64)
    rigid = {n: float(v) for n, v in zip(names, theta, strict=True) if n in PARAMETERS}
    out: dict[str, dict[str, float]] = {}
    for eid, value in (effects or {}).items():
        effect = EFFECTS[eid]
        _, plant, _ = effect.fit_to_plant(Fit(tuple(names), theta, np.zeros((len(theta), len(theta))), value, hold_s=hold_s))
        if effect.plant and plant is not None:
            out.update(effect.plant_entries(plant, hold_s))
    return rigid, out


def relative_errors(rec: RunLog, sim: RunLog, ls: LSSettings) -> dict[str, float]:
    """Relative errors (%) of position, velocity and force of ``sim`` against ``rec`` (first ``trim`` samples dropped).

    The benchmark's simulation table: position, and velocity from the filtered position (as IDIM-LS); force
    ``100 ||tau_sim - tau|| / ||tau||``.
    """
    fs = rec.fs_hz
    n = min(len(rec), len(sim))
    s = slice(ls.trim, n)

    def vel(q: np.ndarray) -> np.ndarray:
        return derivative(butter_lowpass_zero_phase(q[:n], ls.cutoff_hz, fs, ls.order, matlab=ls.matlab), 1.0 / fs, ls.at_rate(fs).stencil)

    return {
        "position": relative_error_pct(rec["q"][s], sim["q"][s]),
        "velocity": relative_error_pct(vel(rec["q"])[s], vel(sim["q"])[s]),
        "force": relative_error_pct(rec["tau"][s], sim["tau"][s]),
    }


def require_closed_loop(log: RunLog, source: str, what: str) -> None:
    """Refuse a log ``what`` (DIDIM, IDIM-IV, CLOE) cannot simulate: no recorded controller, or no reference.

    The log records its controller when its metadata names one (:attr:`ilic_cli.runlog.RunLog.controller`) or it
    holds the PD command ``vir`` (the rule of :func:`plant.replay.records_controller`).
    """
    if log.controller is None and "vir" not in log:
        raise IdentificationError(
            source, f"{what} needs the loop that ran: the log records no controller (its kind and gains, or the PD command vir with kp, kv and drive gain)"
        )
    if "q_ref" not in log:
        raise IdentificationError(source, f"{what} needs the reference position (q_ref) to simulate the closed loop")


Simulator = Callable[[dict[str, float], dict[str, dict[str, float]]], RunLog]
"""``(rigid parameters, effects) -> simulated log`` on the recorded log's time base."""


def _simulator_of(log: RunLog, simulate: Simulator | None, loop: LoopSimulator | None) -> Simulator:
    """``simulate``, else the replay of ``log`` through its own controller by ``loop``."""
    if simulate is not None:
        return simulate
    if loop is None:
        raise ParameterError("loop", None, "a loop simulator (ilic_cli.simulation.loop.PLANT_LOOP) or a simulate function")
    return lambda params, effects: loop.replay(log, params, effects)


def closed_loop_identify(
    method: str,
    log: RunLog,
    model: Model,
    theta0: np.ndarray,
    *,
    effects: Mapping[str, Any] | None = None,
    ls_settings: LSSettings = LSSettings(),
    settings: ClosedLoopSettings | None = None,
    prepared: PreparedLog | None = None,
    simulate: Simulator | None = None,
    hold_s: float = 0.0,
    loop: LoopSimulator | None = None,
) -> ClosedLoopResult:
    """DIDIM (``method="didim"``) or IDIM-IV (``"iv"``) of ``model`` on ``log``, from ``theta0``.

    Parameters
    ----------
    method : {"didim", "iv"}
    log : RunLog
        Needs ``t, q, tau, q_ref`` and its controller (:func:`require_closed_loop`); one contiguous recording.
    model : Model
        Regressor columns (a structure, possibly extended by effect columns); each estimate's plant is :func:`plant_of`.
    theta0 : ndarray
        Start, normally the IDIM-LS estimate of ``model``.
    effects : dict, optional
        Effect id -> nonlinear value of the effect columns in ``model``.
    ls_settings : LSSettings
        Filtering and decimation (as IDIM-LS).
    hold_s : float
        Half a sample period when the logged force is the held command (:func:`plant_of`).
    settings : ClosedLoopSettings, optional
        Default :data:`DEFAULT_SETTINGS` of the method.
    prepared : PreparedLog, optional
        ``prepare_log(log)`` when the caller has it.
    simulate : callable, optional
        ``(params, effects) -> simulated log``; default the replay of ``log`` through its own controller by ``loop``.
    loop : LoopSimulator, optional
        The loop simulation (:class:`ilic_cli.estimators.base.LoopSimulator`); needed without ``simulate``.

    Raises
    ------
    IdentificationError, LogError
        No controller, no reference, a log with gaps, or an estimate that is not a plant (a negative mass) on the way.
    """
    if method not in METHODS:
        raise ParameterError("method", method, f"one of {', '.join(METHODS)}")
    name = METHODS[method]
    settings = settings or DEFAULT_SETTINGS[method]
    prepared = with_rest(prepared or prepare_log(log), ls_settings)  # the rows every fit uses (identify's: no standstill)
    log = prepared.log  # an irregularly sampled log is on a uniform grid now
    src = prepared.source
    require_closed_loop(log, src, name)
    prepared.require_contiguous(name)
    simulate = _simulator_of(log, simulate, loop)
    t, tau, fs, names = log.t, log["tau"], prepared.fs_hz, model.names
    measured = lsq_rows(t, log["q"], tau, fs, model, ls_settings, valid=prepared.valid, speed_noise=identification_speed_noise(prepared))  # IV's regressor
    y = measured.y
    y_norm = float(np.linalg.norm(y))

    def replay_at(theta: np.ndarray, k: int) -> tuple[RunLog, np.ndarray, np.ndarray]:
        """The replay with ``theta``, its regressor ``W_s`` and its force, filtered and decimated as ``y``."""
        try:
            sim = simulate(*plant_of(names, theta, effects, hold_s))
        except IlicError as exc:
            raise IdentificationError(src, f"{name} iteration {k}: the estimate cannot be simulated: {exc.problem}") from None
        data = lsq_rows(t, sim["q"], tau, fs, model, ls_settings, valid=prepared.valid)
        return sim, data.W, data.decimate(np.asarray(sim["tau"], dtype=np.float64)[ls_settings.trim :])

    def residual(theta: np.ndarray, tau_s: np.ndarray) -> float:
        """``eps``: DIDIM's output error ``||y - tau_s(theta)||``; IDIM-IV's ``||y - W theta||``."""
        return float(np.linalg.norm(y - tau_s if method == "didim" else y - measured.W @ theta))

    theta = np.asarray(theta0, dtype=np.float64)
    if theta.shape != (len(names),) or not np.all(np.isfinite(theta)):
        raise IdentificationError(src, f"{name} needs a finite start for {len(names)} parameters (the IDIM-LS estimate)")

    def step(Ws: np.ndarray, tau_s: np.ndarray, theta: np.ndarray) -> LSResult:
        """DIDIM: the least squares of ``y - tau_s + W_s theta`` on ``W_s``; IDIM-IV: the instruments ``W_s``."""
        if method == "didim":
            return solve(Ws, y - tau_s + Ws @ theta, names, sigma=ls_settings.sigma)
        return solve_iv(Ws, measured.W, y, names, sigma=ls_settings.sigma)

    history, res, theta, eps, sim, tau_s, converged, reason = iterate(theta, replay_at, residual, step, y_norm, settings)
    if method == "didim":  # the criterion DIDIM minimises, at the final estimate
        res = replace(res, error_norm=eps, relative_error_pct=norm_pct(eps, y_norm))
    return ClosedLoopResult(
        method=name,
        model=model.name,
        result=res,
        settings=settings,
        ls_settings=ls_settings,
        iterations=tuple(history),
        converged=converged,
        stop_reason=reason,
        closed_loop_error_pct=relative_errors(log, sim, ls_settings),
        t=measured.t_dec,
        y=y,
        y_hat=tau_s if method == "didim" else measured.W @ theta,
    )


Step = Callable[[np.ndarray, np.ndarray, np.ndarray], LSResult]
"""``(W_s, tau_s, theta_{k-1}) -> the linear step's estimate`` (DIDIM's Gauss-Newton least squares, IDIM-IV's IV)."""


S = TypeVar("S")
"""A replay of the iteration: a one-joint :class:`~ilic_cli.runlog.RunLog`, or nothing an arm keeps."""


def iterate(
    theta: np.ndarray,
    replay_at: Callable[[np.ndarray, int], tuple[S, np.ndarray, np.ndarray]],
    residual: Callable[[np.ndarray, np.ndarray], float],
    step: Step,
    y_norm: float,
    settings: ClosedLoopSettings,
) -> tuple[list[Iteration], LSResult, np.ndarray, float, S, np.ndarray, bool, str]:
    """The iteration from ``theta`` (the module's stop rule), for one joint or an arm's n (:mod:`ilic_cli.robot.closed_loop`).

    ``replay_at(theta, k) -> (replay, W_s, tau_s)``. Returns the history, the last step's estimate, its theta and
    residual, its replay and force, converged, why it stopped.
    """
    sim, Ws, tau_s = replay_at(theta, 0)
    eps = residual(theta, tau_s)
    history = [Iteration(0, theta, eps, norm_pct(eps, y_norm))]
    converged, reason = False, f"iteration limit ({settings.max_iterations}) reached"
    res: LSResult | None = None
    tol = settings.tolerance_pct
    for k in range(1, settings.max_iterations + 1):
        # DIDIM: Gauss-Newton on the output error with the Jacobian d tau_s / d theta ~= W_s:
        # theta_k = theta_{k-1} + W_s^+ (y - tau_s), i.e. the LS of y - tau_s + W_s theta_{k-1} on W_s; IDIM-IV: Z = W_s
        res = step(Ws, tau_s, theta)
        new = res.theta
        with np.errstate(divide="ignore", invalid="ignore"):
            change = np.abs(new - theta) / np.abs(theta)
        dtheta = float(100.0 * np.max(change[np.isfinite(change)], initial=0.0))  # a parameter at exactly 0 (held by the model) has none
        sim, Ws, tau_s = replay_at(new, k)
        new_eps = residual(new, tau_s)
        deps = 100.0 * abs(new_eps - eps) / eps if eps > 0 else 0.0
        history.append(Iteration(k, new, new_eps, norm_pct(new_eps, y_norm), dtheta, deps))
        theta, eps = new, new_eps
        if deps < tol:
            converged, reason = True, f"the residual norm moved by {deps:.3g} % (< {tol:g} %) at iteration {k}"
            break
        if dtheta < tol:
            converged, reason = True, f"the largest relative parameter change was {dtheta:.3g} % (< {tol:g} %) at iteration {k}"
            break
    assert res is not None  # max_iterations >= 1
    return history, res, theta, eps, sim, tau_s, converged, reason
