"""The plant as the closed-loop estimators' loop simulation (:class:`ilic_cli.estimators.base.LoopSimulator`).

DIDIM, IDIM-IV, OE and CLOE are handed :data:`PLANT_LOOP` by the method registry (:mod:`ilic_cli.methods`) and by
:func:`ilic_cli.identify.identify`: the estimators import no plant, the binding happens here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ilic_cli.runlog import RunLog


class PlantLoop:
    """The replay of a log through its own controller (:func:`ilic_cli.simulation.replay.replay`) and the plant's open-loop drive."""

    def replay(self, log: RunLog, params: dict[str, float], effects: dict[str, Any] | None) -> RunLog:
        from ilic_cli.simulation.replay import replay  # deferred: the plant pulls in numba

        return replay(log, params, effects)

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
        from plant.closed_loop import simulate_segments  # deferred: the plant pulls in numba
        from plant.dynamics import plant_model  # deferred: with the plant

        rigid, eff = plant_model(params, effects)
        return simulate_segments(params=rigid, effects=eff, command=command, fs_hz=fs_hz, starts=starts, length=length, x0=x0, gain=gain, substeps=substeps)

    def initial_state(self, q_m: np.ndarray, init_samples: int, fs_hz: float) -> tuple[float, float]:
        from plant.replay import initial_state  # deferred: the plant pulls in numba

        return initial_state(q_m, init_samples, fs_hz)

    def measured_state(self, q_m: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
        from plant.replay import measured_state  # deferred: the plant pulls in numba

        return measured_state(q_m, fs_hz)


PLANT_LOOP = PlantLoop()
"""The plant's loop simulation: what the registry hands DIDIM, IDIM-IV, OE and CLOE."""
