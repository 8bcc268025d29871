"""The one estimator interface: ``Estimator.fit(prepared, model, settings) -> Fit``.

- :class:`Fit`: what every estimator returns (method, parameter names, theta, covariance, standard deviations,
  residual RMS, relative error, rows used, diagnostics), with the method's own result in :attr:`Fit.detail`
  (the IDIM-LS system, the IDIM-ILIC windows, the DIDIM / IDIM-IV iterations, the output-error shots);
- :class:`ModelSpec`: which parameters are fitted (a structure and the effects whose columns join it);
- :class:`Estimator`: the protocol IDIM-LS, IDIM-ILIC, IDIM-IV, DIDIM, OE and CLOE implement
  (:mod:`ilic_cli.estimators`), each with a typed, frozen settings object;
- :class:`LoopSimulator`: the loop simulation the closed-loop estimators are handed (so that no estimator
  imports the plant): the replay of a log through its controller and the open-loop drive of the plant.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from ilic_cli.effects import get
from ilic_cli.errors import ParameterError
from ilic_cli.lsq import finite_or_none
from ilic_cli.prepare import PreparedLog
from ilic_cli.regressor import Column, Model, get_model
from ilic_cli.runlog import RunLog

SettingsT_contra = TypeVar("SettingsT_contra", contravariant=True)


@dataclass(frozen=True)
class Fit:
    """One estimate, whatever the method.

    Attributes
    ----------
    name : str
        The method's registry name (``ls``, ``ilic``, ``didim``, ``iv``, ``oe``, ``cloe``: :mod:`ilic_cli.methods`).
    method : str
        The name reports use (``IDIM-LS``, ``IDIM-ILIC``, ``DIDIM``, ``IDIM-IV``, ``OE``, ``CLOE``).
    names : tuple of str
        Parameter names (regressor columns; plant terms for the output-error methods, ``stribeck.vs``).
    theta, std, rel_std_pct : ndarray
        Estimate, standard deviations and relative standard deviations (%, the method's own: eq. 10).
    cov : ndarray (b, b)
        Covariance of ``theta`` (the method's own: eq. 9, the IV form, ``s^2 (J'J)^-1``).
    residual_rms : float
        RMS of the method's criterion residual (force for the inverse-model methods, N or N·m; position for OE, m).
    relative_error_pct : float or None
        The method's relative force error (%), ``None`` when it has none.
    rows : int
        Rows (or samples) fitted.
    diagnostics : mapping
        What else the method reports (convergence, iterations, stop reason, windows).
    warnings : tuple of str
        What the fit found worth saying (rank deficiency, no convergence), in the order it found it.
    plant : (dict, dict) or None
        The plant the estimate describes, as a model file holds it: rigid parameters and effects
        (:func:`ilic_cli.closed_loop_id.plant_of`; IDIM-ILIC: the last window's essential parameters).
    detail : object
        The method's own result (:class:`~ilic_cli.idim_ls.IDIMLSResult`, :class:`~ilic_cli.idim_ilic.ILICResult`,
        :class:`~ilic_cli.closed_loop_id.ClosedLoopResult`, :class:`~ilic_cli.output_error.OEResult`).
    """

    name: str
    method: str
    names: tuple[str, ...]
    theta: np.ndarray
    cov: np.ndarray
    std: np.ndarray
    rel_std_pct: np.ndarray
    residual_rms: float
    relative_error_pct: float | None
    rows: int
    diagnostics: Mapping[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    plant: tuple[dict[str, float], dict[str, dict[str, float]]] | None = None
    detail: Any = None

    def parameters(self) -> dict[str, float]:
        """``name -> value``."""
        return {n: float(v) for n, v in zip(self.names, self.theta, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "method": self.method,
            "parameters": {
                n: {"value": finite_or_none(v), "std": finite_or_none(s), "rel_std_pct": finite_or_none(p)}
                for n, v, s, p in zip(self.names, self.theta, self.std, self.rel_std_pct, strict=True)
            },
            "covariance": [[finite_or_none(x) for x in row] for row in np.asarray(self.cov, dtype=np.float64)],
            "residual_rms": finite_or_none(self.residual_rms),
            "relative_error_pct": None if self.relative_error_pct is None else finite_or_none(self.relative_error_pct),
            "rows": self.rows,
            "diagnostics": dict(self.diagnostics),
        }

    def to_frame(self) -> Any:
        """One row per parameter: method, parameter, value, std, relative std."""
        import pandas as pd  # deferred: pandas is slow to import and only tables need it

        return pd.DataFrame({"method": self.method, "parameter": self.names, "value": self.theta, "std": self.std, "rel_std_pct": self.rel_std_pct})


@dataclass(frozen=True)
class ModelSpec:
    """Which parameters a fit estimates: a structure's (``rigid``, ``rigid-offset``, ``asymmetric``) and the columns of ``effects``.

    ``effects``: effect id -> its nonlinear value (``None`` for a linear effect), as :meth:`regressor` builds the columns.
    """

    structure: str = "rigid-offset"
    effects: Mapping[str, Any] = field(default_factory=dict)

    @property
    def lag_s(self) -> float:
        """The drive lag the model states (:func:`stated_lag_s`)."""
        return stated_lag_s(self.effects)

    def regressor(self, fs_hz: float) -> Model:
        """The regressor of :attr:`structure` extended by the columns of :attr:`effects` (:func:`with_effects`)."""
        return with_effects(self.structure, dict(self.effects), fs_hz)


def stated_lag_s(effects: Mapping[str, Any]) -> float:
    """The drive lag (s) a model states: minus the value of its time shift (``delay``, negative when the force acts later).

    IDIM-LS evaluates its regressor that much later again, beyond the hold (:func:`ilic_cli.usable.identification_hold_s`):
    a lag left out leaves ``M lag dddq`` in the residual, which the rows at rest left out make lean on Fv and Fc (a current
    loop's 0.23 ms on a 50 kg axis: Fc +2.9 %, Fv -1.4 % at every rate from 250 Hz to 2 kHz); the closed-loop methods
    replay it in their plant (:func:`ilic_cli.closed_loop_id.plant_of`).
    """
    return -sum(float(v) for eid, v in effects.items() if get(eid).shift and v is not None)


def states_lag(effects: Mapping[str, Any]) -> bool:
    """Whether a model states its drive lag (a time shift among ``effects``, ``delay:delay=0`` for none): then no lag is estimated
    on the log (:func:`ilic_cli.drive_lag.drive_lag`)."""
    return any(get(eid).shift for eid in effects)


def with_effects(structure: str, effects: dict[str, Any] | None, fs_hz: float) -> Model:
    """The regressor of ``structure`` extended by the columns of ``effects`` (id -> nonlinear value or ``None``); a time shift
    adds none (:func:`stated_lag_s`)."""
    model = get_model(structure)
    if not effects:
        return model
    columns: list[Column] = []
    for eid, value in effects.items():
        effect = get(eid)
        if effect.shift:
            if value is None:
                raise ParameterError(eid, None, "given: the lag the regressor is evaluated after")
            continue
        if not effect.columns:
            raise ParameterError("effect", eid, "an effect with regressor columns (a time shift such as 'delay' is not a column)")
        if effect.scan is not None and value is None:  # nonlinear: its columns depend on the scanned value
            raise ParameterError(f"{eid}.{effect.scan.name}", None, "given: the columns depend on it")
        columns.extend(effect.regressor_columns(value, fs_hz))
    return model.extend(*columns, name=structure + "".join(f"+{e}" for e in effects))


def regressor_effects(effects: Mapping[str, Mapping[str, float]], mass: float, *, keep_all: bool = False) -> tuple[dict[str, Any], list[str]]:
    """The nonlinear values of the columns of the plant effects ``effects`` (id -> plant parameters, as a model file holds
    them) at the mass ``mass`` (:meth:`ilic_cli.effects.Effect.value_from_plant`), for :class:`ModelSpec`; and the effects
    with no column (a measurement effect), left out unless ``keep_all``; a time shift is kept (:func:`stated_lag_s`)."""
    chosen: dict[str, Any] = {}
    skipped: list[str] = []
    for eid, values in effects.items():
        effect = get(eid)
        if not keep_all and not effect.columns and not effect.shift:  # a measurement effect: nothing to add to the regressor
            skipped.append(eid)
            continue
        chosen[eid] = effect.value_from_plant(effect.values(values), mass)
    return chosen, skipped


class Estimator(Protocol[SettingsT_contra]):
    """An identification method: ``fit(prepared, model, settings) -> Fit``.

    ``prepared``: the one prepared log (:func:`ilic_cli.prepare.prepare_log`, its rows at rest marked by
    :func:`ilic_cli.usable.with_rest`); ``model``: which parameters (:class:`ModelSpec`); ``settings``: the
    method's typed, frozen settings.
    """

    @property
    def name(self) -> str:
        """The registry name (``ls``, ``ilic``, ...)."""
        ...

    def fit(self, prepared: PreparedLog, model: ModelSpec, settings: SettingsT_contra) -> Fit: ...


class LoopSimulator(Protocol):
    """The loop simulation the closed-loop estimators (DIDIM, IDIM-IV, OE, CLOE) are handed.

    The plant's (:data:`ilic_cli.simulation.loop.PLANT_LOOP`) is the one the registry binds; a test may hand another.
    """

    def replay(self, log: RunLog, params: dict[str, float], effects: dict[str, Any] | None) -> RunLog:
        """``log``'s reference through its own controller with the plant ``(params, effects)``: the simulated log."""
        ...

    def open_loop_segments(
        self,
        params: Mapping[str, float],
        effects: Mapping[str, Any],
        *,
        command: np.ndarray,
        fs_hz: float,
        starts: list[int],
        length: int,
        x0: np.ndarray,
        gain: float,
        substeps: int,
    ) -> np.ndarray:
        """The plant driven by ``gain * command`` without feedback over the stretches ``[i, i + length)`` of ``starts``, each
        from its own state ``x0[j] = (q, qd)``: the stretches' positions, one after another."""
        ...

    def initial_state(self, q_m: np.ndarray, init_samples: int, fs_hz: float) -> tuple[float, float]:
        """The state ``(q, qd)`` at sample ``init_samples - 1`` read from the first ``init_samples`` measured positions."""
        ...

    def measured_state(self, q_m: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity read from a measured position (low-passed, differentiated)."""
        ...
