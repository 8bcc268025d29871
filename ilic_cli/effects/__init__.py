"""The physical effects a rigid drive model leaves out: one definition each.

An :class:`Effect` holds everything the project knows about one effect:

* its plant parameters (:class:`PlantParam`: name, unit, default, valid range)
  and any further rule (:attr:`Effect.check`);
* its force term in the plant: for an effect linear in its parameters, its
  own regressor columns times coefficients (:meth:`Effect.plant_force`,
  :attr:`Effect.coefficients`); the plant's compiled kernel has its own form
  for the built-in effects, checked against this one for every effect by the
  tests (sliding, stuck and at break-away), and compiles the columns' pointwise
  forms (:attr:`EffectColumn.of`) for an effect it has no form for; delay,
  flexibility and the current loop are blocks with their own state
  (:mod:`plant.blocks`);
* for identification and diagnosis: the regressor columns it adds
  (:attr:`Effect.columns`, built by :attr:`Effect.build`), the nonlinear
  parameter to search and its grid (:class:`Scan`), or a time shift of the
  force (``shift``);
* the way a fit of those columns becomes plant parameters
  (:attr:`Effect.estimate`) and back (:attr:`Effect.scan_value`);
* its residual signature (region families of
  :mod:`ilic_cli.diagnosis.locate`) and its plain-word explanation and
  sentence for reports.

Adding an effect is one :func:`register` call with a new definition, in one
module of its own (docs/adding-an-effect.md); the plant, ``ilic identify
--effect``, ``ilic diagnose``, the model file and ``ilic replay`` pick it up.

The package: :mod:`.definition` (the dataclasses), :mod:`.registry`
(:data:`EFFECTS` and its queries), :mod:`.grids` (search grids),
:mod:`.mechanics` and :mod:`.drive` (the built-in effects), :mod:`.catalogue`
(which registers them, in the order diagnosis tries them).
"""

from ilic_cli.effects.catalogue import BUILT_IN
from ilic_cli.effects.definition import Effect, EffectColumn, EffectParams, Effects, Estimate, EstimateResult, Fit, LinearForm, PlantParam, Scan, col, unit_on
from ilic_cli.effects.drive import CURRENT_LOOP, DELAY, DISTURBANCE, FLEXIBILITY, MAX_DELAY_S, NOISE, QUANTIZATION, SATURATION
from ilic_cli.effects.grids import FLEX_DAMPING, flexible_acceleration
from ilic_cli.effects.mechanics import (
    ASYMMETRIC_FRICTION,
    COULOMB_SMOOTHING,
    FRICTION_DRIFT,
    GRAVITY,
    OFFSET,
    PAYLOAD_CHANGE,
    POSITION_RIPPLE,
    SPRING,
    STRIBECK,
    drift_of,
)
from ilic_cli.effects.registry import EFFECTS, applicable, catalogue_ids, effects_to_dict, get, make_effects, plant_ids, register, unit_of, unregister
from ilic_cli.errors import ParameterError

__all__ = [
    "ASYMMETRIC_FRICTION",
    "BUILT_IN",
    "COULOMB_SMOOTHING",
    "CURRENT_LOOP",
    "DELAY",
    "DISTURBANCE",
    "EFFECTS",
    "FLEXIBILITY",
    "FLEX_DAMPING",
    "FRICTION_DRIFT",
    "GRAVITY",
    "MAX_DELAY_S",
    "NOISE",
    "OFFSET",
    "PAYLOAD_CHANGE",
    "POSITION_RIPPLE",
    "QUANTIZATION",
    "SATURATION",
    "SPRING",
    "STRIBECK",
    "Effect",
    "EffectColumn",
    "EffectParams",
    "Effects",
    "Estimate",
    "EstimateResult",
    "Fit",
    "LinearForm",
    "ParameterError",
    "PlantParam",
    "Scan",
    "applicable",
    "catalogue_ids",
    "col",
    "drift_of",
    "effects_to_dict",
    "flexible_acceleration",
    "get",
    "make_effects",
    "plant_ids",
    "register",
    "unit_of",
    "unit_on",
    "unregister",
]
