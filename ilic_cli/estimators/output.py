"""OE and CLOE behind the estimator interface: the position's output error, from the IDIM-LS plant.

The loop simulation is handed to the estimator (:class:`ilic_cli.estimators.base.LoopSimulator`); the
numerics are :func:`ilic_cli.output_error.open_loop_oe` and :func:`ilic_cli.output_error.closed_loop_oe`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.closed_loop_id import plant_of
from ilic_cli.effects import get
from ilic_cli.errors import IlicError
from ilic_cli.estimators.base import Fit, LoopSimulator, ModelSpec, stated_lag_s, with_effects
from ilic_cli.estimators.inverse import IDIMLS
from ilic_cli.idim_ls import LSSettings, cross_validate
from ilic_cli.lsq import LSResult
from ilic_cli.output_error import METHODS, OEResult, OESettings, closed_loop_oe, open_loop_oe
from ilic_cli.prepare import PreparedLog, prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.usable import identification_hold_s, identification_speed_noise


@dataclass(frozen=True)
class OutputErrorFitSettings:
    """OE / CLOE: the fit's settings, IDIM-LS's processing (the inverse-model force error, the CLOE trim), and the
    start (``None``: the IDIM-LS estimate of the same model on the same log)."""

    oe: OESettings = OESettings()
    ls: LSSettings = LSSettings()
    start: tuple[float, ...] | None = None


@dataclass(frozen=True)
class OutputError:
    """OE (``name="oe"``, the recorded drive command into the model) or CLOE (``"cloe"``, the log's reference through its controller)."""

    name: str
    loop: LoopSimulator

    def fit(self, prepared: PreparedLog, model: ModelSpec, settings: OutputErrorFitSettings) -> Fit:
        log, effects = prepared.log, dict(model.effects)
        regressor = model.regressor(prepared.fs_hz)
        theta0 = IDIMLS().run(prepared, model, settings.ls).result.theta if settings.start is None else np.asarray(settings.start, dtype=np.float64)
        rigid, eff = plant_of(regressor.names, theta0, effects)
        names = parameters.structure_names(model.structure)
        warnings: list[str] = []
        if self.name == "oe":
            result = open_loop_oe(log, rigid, eff, names, model_name=regressor.name, settings=settings.oe, warnings=warnings, loop=self.loop)
        else:
            result = closed_loop_oe(log, rigid, eff, names, model_name=regressor.name, settings=settings.oe, trim=settings.ls.trim, loop=self.loop)
        force = inverse_model_error(result, log, prepare_log(log), effects, settings.ls)
        result = replace(result, force_error_pct=None if force is None else float(force.relative_error_pct))
        if "offset" in result.names and "Fc_pos" in result.names:
            warnings.append(
                f"{result.method}: the offset and the asymmetric Coulomb levels are one plant (Fc_pos + offset, Fc_neg - offset move the axis alike, "
                "break-away included): a simulation cannot tell them apart, and their standard deviations say so"
            )
        if not result.converged:
            warnings.append(f"{result.method} did not converge: {result.stop_reason}; the last iterate is reported")
        samples = len(result.starts) * result.length if result.starts else len(log) - settings.ls.trim
        return oe_fit(self.name, result, samples, tuple(warnings))


def oe_fit(name: str, r: OEResult, samples: int, warnings: tuple[str, ...] = ()) -> Fit:
    """The :class:`Fit` of an output-error estimate over ``samples`` fitted samples (residual RMS: the position's, m)."""
    cov = r.cov if r.cov is not None else np.diag(np.asarray(r.std, dtype=np.float64) ** 2)
    diagnostics = {"converged": r.converged, "iterations": r.iterations, "evaluations": r.evaluations, "stop_reason": r.stop_reason}
    return Fit(
        name, METHODS[name], r.names, r.theta, cov, r.std, r.rel_std_pct, float(r.rmse_m), r.force_error_pct, samples, diagnostics, warnings, r.plant(), r
    )


def inverse_model_error(oe: OEResult, log: RunLog, prepared: PreparedLog, effects: dict[str, Any], ls_settings: LSSettings) -> LSResult | None:
    """The inverse model's force error with an output-error estimate (IDIM-LS's processing; effects' columns at the fitted values)."""
    rigid, eff = oe.plant()
    values = {**rigid, **{k: v for params in eff.values() for k, v in params.items()}}
    try:
        fitted = {eid: get(eid).value_from_plant(eff.get(eid, {}), float(rigid["M"])) for eid in effects}
        m = with_effects(oe.model.split("+")[0], fitted, prepared.fs_hz)
        theta = np.array([values[n] for n in m.names], dtype=np.float64)
    except (KeyError, IlicError):
        return None  # the fitted plant has no inverse model of this form
    hold, noise = identification_hold_s(prepared) + stated_lag_s(effects), identification_speed_noise(prepared)
    v, seg = prepared.valid, prepared.segments
    return cross_validate(theta, log.t, log["q"], log["tau"], prepared.fs_hz, m, ls_settings, valid=v, segments=seg, hold_s=hold, speed_noise=noise)
