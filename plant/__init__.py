"""Simulated plant: the EMPS-like 1-DOF prismatic axis in closed loop.

Modules
-------
``plant.dynamics``      parameters, named effects, :func:`force_model` (inverse dynamics)
``plant.trajectories``  exciting trajectories (trapezoidal velocity profiles)
``plant.controllers``   CTC (paper eqs. 11-16) and the benchmark PD loop settings
``plant.closed_loop``   compiled integrator, :func:`simulate_loop`, :func:`simulate_replay`
``plant.scenarios``     named scenarios (``paper-sim``, ``paper-payload``, ``emps-benchmark``)

Importing ``plant`` is cheap; the numba-compiled loop is imported with
``plant.closed_loop`` (first compile a few seconds, then cached).
"""

from __future__ import annotations

from typing import Any

__all__ = ["force_model", "run_scenario", "simulate_loop", "simulate_replay"]


def __getattr__(name: str) -> Any:
    if name == "force_model":
        from plant.dynamics import force_model

        return force_model
    if name in ("simulate_loop", "simulate_replay"):
        import plant.closed_loop as cl

        return getattr(cl, name)
    if name == "run_scenario":
        from plant.scenarios import run_scenario

        return run_scenario
    raise AttributeError(name)
