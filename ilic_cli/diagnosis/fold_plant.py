"""The plant a held-out fold's fit describes (:class:`ilic_cli.diagnosis.heldout_replay.HeldoutReplays`), and whether it is one.

A fold's fit of an effect can fall outside the effect's physics (a flexibility's load above the axis's inertia): its plant
leaves the effect out (:func:`ilic_cli.diagnosis.model_values.model_parameters`), and such a fold is left out of the
replay's judgement (:func:`not_a_plant`, :data:`MIN_PLANT_FOLDS`). Pure numerics on arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ilic_cli.diagnosis.drift import GivenDrift
from ilic_cli.diagnosis.model_values import effect_fit
from ilic_cli.diagnosis.system import Step, column_noise, fit_system, system
from ilic_cli.diagnosis.verdicts import PlantOf
from ilic_cli.idim_ls import IDIMData
from ilic_cli.lsq import lstsq, noise_corrected_lstsq
from ilic_cli.regressor import Model


def fitted_plant(
    data: IDIMData,
    base: Model,
    steps: list[Step],
    rows: np.ndarray,
    plant_of: PlantOf,
    train: np.ndarray | None = None,
    drift: GivenDrift | None = None,
) -> tuple[dict[str, float], dict[str, Any]]:
    """The plant of ``base + steps`` fitted on ``data``'s ``rows`` (``train`` of them); with a ``drift`` found on the rigid model,
    its trends' columns are in the fit and its ``friction_drift`` in the plant (:meth:`~ilic_cli.diagnosis.drift.GivenDrift.plant`).

    The selection fitted every candidate with the drift's columns (:func:`~ilic_cli.diagnosis.propose.drift_given`); a replay
    without it judged them against a plant whose friction does not change: on corpus s731 (gravity beside a warm-up of ``Fv``,
    20 % over 2 s) the drift's error over time swamped gravity's fall (held-out simulated force 2.76 % -> 2.77 %).
    """
    names, theta, trend = fold_fit(data, base, steps, rows, train, drift)
    rigid, effects = plant_of(steps, names, theta)
    return (rigid, effects) if drift is None or trend is None else drift.plant(rigid, effects, trend)


MIN_PLANT_FOLDS = 3
"""Held-out folds at least whose fit must be a plant of every effect (a majority of the five) for a replay to judge
(:meth:`ilic_cli.diagnosis.heldout_replay.HeldoutReplays.heldout`). A fold whose fit is not (a flexibility's load fraction outside (0, 1)) used to be replayed
without the effect, silently: 16 logs of the robot corpus's two seed sets had such replays, rev0.5 s721 in two of five folds
(its flexibility's replay 3.70 % -> 4.54 %)."""


def fold_fit(
    data: IDIMData, base: Model, steps: list[Step], rows: np.ndarray, train: np.ndarray | None = None, drift: GivenDrift | None = None
) -> tuple[tuple[str, ...], np.ndarray, np.ndarray | None]:
    """The fit :func:`fitted_plant` makes its plant of: the model's names and estimate, and the drift's trends' (``None``: no drift)."""
    if drift is None:
        fit = fit_system(data, base, steps, rows, train)
        return fit.names, fit.theta, None
    W, y, names = system(data, base, steps, rows)
    trends, noise = drift.columns(data.t_dec[rows], W, names), column_noise(data, base, steps, rows)
    W1, sel = np.hstack([W, trends]), (slice(None) if train is None else train)
    # with noisy columns, their noise corrected for (the trends' own, a velocity's times a function of time, is small)
    noise1 = None if noise is None else np.concatenate([noise, np.zeros((len(noise), *trends.shape))], axis=2)[:, sel]
    theta, _ = lstsq(W1[sel], y[sel]) if noise1 is None else noise_corrected_lstsq(W1[sel], y[sel], noise1)
    return names, theta[: len(names)], theta[len(names) :]


def not_a_plant(steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> list[str]:
    """The effects of ``steps`` whose fitted coefficients make no plant of them (a load fraction outside (0, 1), ...): a plant
    built of the fit leaves them out (:func:`ilic_cli.diagnosis.model_values.model_parameters`)."""
    zero = np.zeros((len(theta), len(theta)))
    return [st.effect.id for st in steps if st.effect.plant and effect_fit(st, names, theta, zero, None)[1] is None]
