"""A fit's parameters in the plant's vocabulary: the estimates an effect reports, and the model file's rigid parameters and plant effects.

Shared by every stage (the replays of the decision, the refit, the model file of the report): a fit of
``base + steps`` (names, estimate, covariance) becomes plant parameters through each effect's own
:meth:`~ilic_cli.effects.Effect.fit_to_plant` and :meth:`~ilic_cli.effects.Effect.plant_entries`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ilic_cli.diagnosis.system import Step
from ilic_cli.effects import EFFECTS, Estimate, Fit
from ilic_cli.parameters import PARAMETERS


def effect_fit(
    step: Step, names: tuple[str, ...], theta: np.ndarray, cov: np.ndarray, value_std: float | None, hold_s: float = 0.0, joint: str = "prismatic"
) -> tuple[dict[str, Estimate], dict[str, float] | None, str]:
    """Reported estimates, plant parameters and a note of one accepted effect (:meth:`ilic_cli.effects.Effect.fit_to_plant`).

    ``hold_s``: half a sample period when the logged force is the held drive
    command; the baseline already evaluates the regressor that much later
    (:mod:`ilic_cli.diagnosis.baseline`), so a found ``delay`` is a lag beyond
    the hold and is the plant's ``delay`` as it is (the plant holds its force
    itself). ``joint``: the units the note writes its values in (the estimates keep the catalogue's, :meth:`Effect.on_joint`).
    """
    if step.level is not None:  # held at a closed-loop estimate: its coefficients join the fit's, with their own spread
        m = len(step.level)
        names = (*names, *step.effect.column_names)
        theta = np.r_[theta, step.level]
        cov = np.pad(cov, ((0, m), (0, m)))
        cov[-m:, -m:] = np.diag(np.square(step.level_std or (0.0,) * m))
    return step.effect.fit_to_plant(Fit(names, theta, cov, step.value, value_std, hold_s, joint))


def steps_from_effects(effects: dict[str, Any], M: float) -> list[Step]:
    """Known effects of a model file as fixed steps (their nonlinear values)."""
    out = []
    for eid, prm in effects.items():
        e = EFFECTS.get(eid)
        if e is None or not e.identifiable or not isinstance(prm, dict):
            continue
        out.append(Step(e, e.value_from_plant(e.values(prm), M)))
    return out


def model_parameters(
    steps: list[Step], names: tuple[str, ...], values: np.ndarray, cov: np.ndarray, hold_s: float = 0.0
) -> tuple[dict[str, float], dict[str, Any]]:
    """Rigid parameters (every rigid column of the fit, whatever the structure) and plant effects, for the model file.

    ``hold_s``: see :func:`effect_fit`.
    """
    rigid = {n: float(v) for n, v in zip(names, values, strict=True) if n in PARAMETERS}
    effects: dict[str, Any] = {}
    for st in steps:
        _, plant, _ = effect_fit(st, names, values, cov, None, hold_s)
        if st.effect.plant and plant is not None:
            effects.update(st.effect.plant_entries(plant, hold_s))
    return rigid, effects


def model_std(
    steps: list[Step], names: tuple[str, ...], values: np.ndarray, cov: np.ndarray, hold_s: float, value_std: dict[str, float | None]
) -> dict[str, Any]:
    """Standard deviations of the model file's values (rigid parameters, and each effect's plant parameters that have one).

    ``value_std``: effect id -> standard deviation of its nonlinear value.
    """
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    rigid = {n: float(s) for n, s in zip(names, std, strict=True) if n in PARAMETERS}
    effects: dict[str, Any] = {}
    for st in steps:
        est, plant, _ = effect_fit(st, names, values, cov, value_std.get(st.effect.id), hold_s)
        if st.effect.plant and plant is not None and st.effect.id in st.effect.plant_entries(plant, hold_s):  # a realisation's own values have none
            effects[st.effect.id] = {k: est[k].std for k in plant if k in est and est[k].std is not None}
    return {"parameters": rigid, "effects": effects}
