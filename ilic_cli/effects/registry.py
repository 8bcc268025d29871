"""The registry of effects: every definition by id, in the order diagnosis tries them, and the checked plant effects of a run."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ilic_cli import parameters
from ilic_cli.effects.definition import Effect, EffectParams, Effects
from ilic_cli.errors import ParameterError

EFFECTS: dict[str, Effect] = {}
"""Every effect by id, in the order diagnosis tries them."""


def register(effect: Effect) -> Effect:
    """Add a definition to :data:`EFFECTS` (ids are unique)."""
    if effect.id in EFFECTS:
        raise ValueError(f"effect '{effect.id}' is already defined")
    names = [c.name for c in effect.columns]
    if len(set(names)) != len(names):
        raise ValueError(f"effect '{effect.id}': column names repeat")
    EFFECTS[effect.id] = effect
    return effect


def unregister(effect_id: str) -> None:
    """Remove a definition (tests that add a toy effect clean up with it)."""
    EFFECTS.pop(effect_id, None)


def get(effect_id: str) -> Effect:
    """The definition of ``effect_id``; :class:`ParameterError` for an unknown id."""
    try:
        return EFFECTS[effect_id]
    except KeyError:
        raise ParameterError("effect", effect_id, f"one of {', '.join(plant_ids())}") from None


def plant_ids() -> tuple[str, ...]:
    """Ids of the plant's effects (what ``--effect`` and model files take)."""
    return tuple(i for i, e in EFFECTS.items() if e.plant)


def catalogue_ids(joint: str | None = None) -> tuple[str, ...]:
    """Ids of the effects diagnosis can fit, in the order they are tried (on a ``joint`` of that type only, when given)."""
    return tuple(i for i, e in EFFECTS.items() if e.identifiable and (joint is None or joint in e.joints))


def make_effects(spec: Mapping[str, Any] | None) -> Effects:
    """Checked effects from ``{id: {param: value}}`` (model files, metadata, options).

    A value of ``None``/``False`` leaves the effect out; ``True`` or ``{}``
    uses the documented defaults; an :class:`EffectParams` is taken as it is.
    """
    out: Effects = {}
    for eid, params in (spec or {}).items():
        if isinstance(params, EffectParams):
            out[eid] = params
            continue
        effect = get(eid)
        if not effect.plant:
            raise ParameterError("effect", eid, f"a plant effect ({', '.join(plant_ids())})")
        if params is None or params is False:
            continue
        if params is True:
            params = {}
        if not isinstance(params, Mapping):
            raise ParameterError(eid, params, "an object of parameter -> value")
        out[eid] = EffectParams(effect, effect.values(params))
    return out


def effects_to_dict(effects: Mapping[str, EffectParams]) -> dict[str, dict[str, float]]:
    """JSON form ``{id: {param: value}}`` in the stable order of :data:`EFFECTS`."""
    return {eid: effects[eid].to_dict() for eid in EFFECTS if eid in effects}


def unit_of(name: str, joint: str = "prismatic") -> str:
    """The unit of a regressor column on a ``joint`` (a revolute joint's N·m where a prismatic one has N): a rigid parameter's
    (:mod:`ilic_cli.parameters`) or an effect column's."""
    unit = parameters.unit(name, joint)
    if unit:
        return unit
    return next((e.unit_on(c.unit, joint) for e in EFFECTS.values() for c in e.columns if c.name == name), "")


def applicable(effect: Effect, base_names: tuple[str, ...]) -> bool:
    """Whether ``effect`` adds something to a model with columns ``base_names`` (not already its columns or its parameters)."""
    return not any(n in base_names for n in (*effect.column_names, *effect.names))
