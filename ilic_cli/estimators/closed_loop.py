"""DIDIM and IDIM-IV behind the estimator interface: iterated on replays of the loop, from IDIM-LS.

The loop simulation is handed to the estimator (:class:`ilic_cli.estimators.base.LoopSimulator`); the
numerics are :func:`ilic_cli.closed_loop_id.closed_loop_identify`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ilic_cli.closed_loop_id import METHODS, ClosedLoopSettings, closed_loop_identify, plant_of
from ilic_cli.estimators.base import Fit, LoopSimulator, ModelSpec
from ilic_cli.estimators.inverse import IDIMLS, ls_fit
from ilic_cli.idim_ls import LSSettings
from ilic_cli.prepare import PreparedLog


@dataclass(frozen=True)
class ClosedLoopFitSettings:
    """DIDIM / IDIM-IV: the iteration (``None``: the method's default, :data:`ilic_cli.closed_loop_id.DEFAULT_SETTINGS`),
    the IDIM filtering, and the start (``None``: the IDIM-LS estimate of the same model on the same log)."""

    iteration: ClosedLoopSettings | None = None
    ls: LSSettings = LSSettings()
    start: tuple[float, ...] | None = None


@dataclass(frozen=True)
class ClosedLoop:
    """DIDIM (``name="didim"``) or IDIM-IV (``"iv"``) with the loop simulation ``loop``."""

    name: str
    loop: LoopSimulator

    def fit(self, prepared: PreparedLog, model: ModelSpec, settings: ClosedLoopFitSettings) -> Fit:
        regressor = model.regressor(prepared.fs_hz)
        start = settings.start
        theta0 = IDIMLS().run(prepared, model, settings.ls).result.theta if start is None else np.asarray(start, dtype=np.float64)
        res = closed_loop_identify(
            self.name,
            prepared.log,
            regressor,
            theta0,
            effects=dict(model.effects),
            ls_settings=settings.ls,
            settings=settings.iteration,
            prepared=prepared,
            loop=self.loop,
        )
        warnings = () if res.converged else (f"{res.method} did not converge: {res.stop_reason}; the last iterate is reported",)
        return ls_fit(
            self.name,
            METHODS[self.name],
            res.result,
            res,
            plant_of(res.result.names, res.result.theta, model.effects),
            warnings,
            converged=res.converged,
            iterations=res.n_iterations,
            stop_reason=res.stop_reason,
            closed_loop_error_pct=dict(res.closed_loop_error_pct),
        )
