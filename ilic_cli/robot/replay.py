"""Replay of an n-joint log: its reference through its recorded controller, with the plant of given base parameters.

The log records the loop that ran in ``meta["controller"]`` (:func:`controller_meta`
writes it): the kind (``ctc`` or ``pd``), the gains' settings of
:class:`ilic_cli.robot.plant.LoopSettings`, and the controller's standard
parameter vector of each window (``models``, one per ``window_s``; the online
IDIM-ILIC updates of ``robot-sim``), or one ``model`` for the whole run. A log
that records no model is replayed with the URDF's nominal parameters as the
controller's (the ``nominal`` argument).

:func:`replay_loop` runs the compiled loop (:func:`ilic_cli.robot.plant.simulate_loop`)
on the log's own reference samples. DIDIM and IDIM-IV on n joints
(:mod:`ilic_cli.robot.closed_loop`) call it at each iteration; ``ilic replay
--urdf`` once. Deterministic: no noise is added.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ilic_cli.robot.dynamics import kept_vector
from ilic_cli.robot.model import RobotModel
from ilic_cli.robot.plant import LoopRun, LoopSettings, Segment, simulate_loop

SETTINGS = ("omega_hz", "xi", "pd_bandwidth_hz", "pd_damping", "alpha", "velocity", "encoder_counts", "encoder_step_m")
"""The :class:`LoopSettings` fields a log's controller records (besides its kind and rate)."""


@dataclass(frozen=True)
class SampledReference:
    """A reference given by its samples (N, n) on the loop's grid (the log's ``q_ref``, ``qd_ref``, ``qdd_ref``)."""

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The samples themselves: ``t`` must be the loop's grid of the same length."""
        if np.shape(t) != (len(self.q),):
            raise ValueError(f"a sampled reference of {len(self.q)} samples asked at {np.size(t)} times")
        return self.q, self.qd, self.qdd


def controller_meta(settings: LoopSettings, models: Sequence[np.ndarray], window_s: float | None = None) -> dict[str, Any]:
    """The ``meta["controller"]`` of a simulated log: kind, settings and the controller's model(s) (with their window)."""
    doc: dict[str, Any] = {"kind": settings.controller} | {k: getattr(settings, k) for k in SETTINGS}
    if len(models) > 1:
        doc |= {"window_s": window_s, "models": [np.asarray(m, dtype=np.float64).tolist() for m in models]}
    elif models:
        doc["model"] = np.asarray(models[0], dtype=np.float64).tolist()
    return doc


def loop_settings(controller: Mapping[str, Any], fs_hz: float) -> LoopSettings:
    """The :class:`LoopSettings` a log's controller records (``ValueError`` for an unknown kind or setting)."""
    known = {f.name: f.type for f in fields(LoopSettings)}
    values: dict[str, Any] = {"fs_hz": float(fs_hz), "controller": str(controller.get("kind", "")).lower(), "encoder_counts": 0}
    for key in SETTINGS:
        if key in controller and key in known:
            value = controller[key]
            values[key] = str(value) if key == "velocity" else int(value) if key == "encoder_counts" else float(value)
    return LoopSettings(**values)


def controller_models(robot: RobotModel, controller: Mapping[str, Any], nominal: np.ndarray) -> tuple[list[np.ndarray], float | None]:
    """The controller's standard vector per window (``ValueError`` for a wrong size) and the window; ``[nominal]`` when none is recorded."""
    raw = controller.get("models") or ([controller["model"]] if controller.get("model") is not None else [nominal])
    models = [np.asarray(m, dtype=np.float64) for m in raw]
    size = 14 * robot.n
    if any(m.shape != (size,) for m in models):
        raise ValueError(f"the recorded controller's model has {sorted({m.size for m in models})} parameters; the URDF's arm has {size}")
    window = controller.get("window_s") if len(models) > 1 else None
    return models, None if window is None else float(window)


def replay_loop(robot: RobotModel, pi: np.ndarray, reference: SampledReference, fs_hz: float, controller: Mapping[str, Any], nominal: np.ndarray) -> LoopRun:
    """The log's loop with the plant of standard parameters ``pi`` (no noise; the state starts on the reference)."""
    settings = loop_settings(controller, fs_hz)
    models, window = controller_models(robot, controller, nominal)

    def update(segment: Segment, model: np.ndarray) -> np.ndarray:
        return models[min(segment.k, len(models) - 1)]

    duration = len(reference.q) / fs_hz
    return simulate_loop(robot, pi, reference, duration, models[0], settings, window_s=window, update=update if window else None)


def base_simulator(robot: RobotModel, kept: np.ndarray, reference: SampledReference, fs_hz: float, controller: Mapping[str, Any], nominal: np.ndarray) -> Any:
    """``beta -> (q, tau)`` of the log's loop with the plant of base parameters ``beta`` (:data:`ilic_cli.robot.closed_loop.Simulator`)."""

    def simulate(beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        run = replay_loop(robot, kept_vector(kept, beta, 14 * robot.n), reference, fs_hz, controller, nominal)
        return run.q, run.tau

    return simulate
