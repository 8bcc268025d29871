"""Simulated plant: the EMPS-like 1-DOF prismatic axis in closed loop.

Modules
-------
``plant.dynamics``      rigid parameters, the plant vector, :func:`force_model` (inverse dynamics);
                        the effects themselves are defined in :mod:`ilic_cli.effects`
``plant.trajectories``  exciting trajectories (trapezoidal velocity profiles, multisines)
``plant.controllers``   CTC (paper eqs. 11-16) and the benchmark PD loop settings
``plant.kernel``        the compiled inner loop (controller per period, RK4, stick/slip)
``plant.generic``       the loop compiled for effects without a compiled form
``plant.sensors``       the logged force (held, delayed, noisy) and the noise
``plant.closed_loop``   :func:`simulate_loop` (online IDIM-ILIC) and the run log
``plant.replay``        :func:`simulate_replay`: a recorded log's reference through the plant
``plant.scenarios``     named scenarios (``paper-sim``, ``paper-payload``, ``emps-benchmark``)
``plant.corpus``        named simulated logs with known truth, to calibrate and test the diagnosis

Importing ``plant`` is cheap (deferred: numba's import and the compiled loop
cost about a second); the loop is compiled once and cached.
"""

from __future__ import annotations

from typing import Any

__all__ = ["force_model", "run_scenario", "simulate_loop", "simulate_replay"]


def __getattr__(name: str) -> Any:
    if name == "force_model":
        from plant.dynamics import force_model

        return force_model
    if name == "simulate_loop":
        from plant.closed_loop import simulate_loop

        return simulate_loop
    if name == "simulate_replay":
        from plant.replay import simulate_replay

        return simulate_replay
    if name == "run_scenario":
        from plant.scenarios import run_scenario

        return run_scenario
    raise AttributeError(name)
