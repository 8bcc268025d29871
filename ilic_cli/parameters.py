"""The identifiable parameters of the axis, once: names, units, meaning, structures.

Every module that names a parameter -- the regressor columns, the CTC's
parameter vector, the plant, diagnosis and the model file -- takes it from
here. The plant's own parameter set is ``M, Fv, Fc, offset`` plus, for an
axis whose friction depends on the direction of motion, the
``asymmetric_friction`` effect (``Fv_pos, Fc_pos, Fv_neg, Fc_neg``);
:func:`to_plant` and :func:`from_plant` map between that set and any model
structure (paper eq. 30; the benchmark's asymmetric model).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from ilic_cli.errors import ParameterError


@dataclass(frozen=True)
class Parameter:
    """One identifiable parameter of the inverse dynamic model.

    Attributes
    ----------
    name : str
        Key in reports, JSON documents, model files and log channels (``NAME_hat``).
    unit : str
        Unit on a prismatic axis (SI, load side).
    unit_revolute : str
        Unit on a revolute axis.
    meaning : str
        One line for reports.
    """

    name: str
    unit: str
    unit_revolute: str
    meaning: str

    def unit_for(self, joint: str = "prismatic") -> str:
        """The unit on a ``prismatic`` or ``revolute`` joint."""
        return self.unit_revolute if joint == "revolute" else self.unit


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter("M", "kg", "kg·m²", "mass (motor rotor, screw, nut and carriage)"),
        Parameter("Fv", "N·s/m", "N·m·s/rad", "viscous friction"),
        Parameter("Fc", "N", "N·m", "Coulomb friction"),
        Parameter("offset", "N", "N·m", "force offset (amplifier offset, Coulomb asymmetry)"),
        Parameter("Fv_pos", "N·s/m", "N·m·s/rad", "viscous friction, positive velocity"),
        Parameter("Fc_pos", "N", "N·m", "Coulomb friction, positive velocity"),
        Parameter("Fv_neg", "N·s/m", "N·m·s/rad", "viscous friction, negative velocity"),
        Parameter("Fc_neg", "N", "N·m", "Coulomb friction, negative velocity (a magnitude)"),
    )
}
"""Every identifiable parameter of the rigid axis, by name."""

FIRST_MOMENTS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter("MX", "kg·m", "kg·m", "first moment of the link along its zero direction (gravity torque g·MX at q = 0)"),
        Parameter("MY", "kg·m", "kg·m", "first moment of the link normal to its zero direction (gravity torque -g·MY at q = pi/2)"),
    )
}
"""The first moments of a revolute link (paper eq. 3): gravity's parameters, ``g·(MX cos q - MY sin q)``.
They are the ``gravity`` effect's (:mod:`ilic_cli.effects`), not rigid parameters of the plant."""

STANDARD_GRAVITY = 9.80665
"""g (m/s²): gravity's torque on a revolute link and the weight of the load of a vertical prismatic axis."""

RIGID = ("M", "Fv", "Fc", "offset")
"""The plant's rigid parameters (its parameter set without effects)."""

ASYMMETRIC = ("Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg")
"""The direction-dependent friction parameters (the plant's ``asymmetric_friction`` effect)."""

STRUCTURES: dict[str, tuple[str, ...]] = {
    "rigid": ("M", "Fv", "Fc"),
    "rigid-offset": ("M", "Fv", "Fc", "offset"),
    "asymmetric": ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"),
}
"""Model structures by name: the parameters each identifies, in column order (paper eq. 30)."""

DEFAULTS = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0}
"""The plant's default rigid parameters (paper section VI-E)."""


def weight(constant_N: float, std_N: float | None = None) -> dict[str, tuple[float, float | None, str]]:
    """The constant force of a vertical axis as the weight it is: ``weight = M·g`` (N) and the implied mass (kg), with standard deviations.

    The sign is the force's (a load pulled down along a positive-up axis needs a positive force to hold it).
    """
    g = STANDARD_GRAVITY
    return {
        "weight": (float(constant_N), std_N, "N"),
        "implied_mass": (float(constant_N) / g, None if std_N is None else float(std_N) / g, "kg"),
    }


def unit(name: str, joint: str = "prismatic") -> str:
    """Unit of a parameter (``""`` for a name that is not a rigid parameter or a first moment)."""
    p = PARAMETERS.get(name) or FIRST_MOMENTS.get(name)
    return "" if p is None else p.unit_for(joint)


def per_second(unit: str) -> str:
    """The unit of a quantity in ``unit`` changing per second: N·s/m -> N/m, N·m·s/rad -> N·m/rad, N -> N/s (a friction's wear rate)."""
    return unit.replace("·s/", "/", 1) if "·s/" in unit else f"{unit}/s"


def structure_names(structure: str) -> tuple[str, ...]:
    """The parameters of a model structure; :class:`ParameterError` for an unknown one."""
    try:
        return STRUCTURES[structure]
    except KeyError:
        raise ParameterError("structure", structure, f"one of {', '.join(STRUCTURES)}") from None


def structure_of(names: tuple[str, ...] | list[str] | set[str]) -> str | None:
    """The structure whose parameters are exactly the rigid ones among ``names`` (``None`` if none is)."""
    rigid = {n for n in names if n in PARAMETERS}
    for name, params in STRUCTURES.items():
        if set(params) == rigid:
            return name
    return None


def check_rigid(values: Mapping[str, float]) -> None:
    """The rules of the plant's rigid parameters: ``M > 0``, all finite, Coulomb levels ``>= 0``."""
    for name, value in values.items():
        if not math.isfinite(value):
            raise ParameterError(name, value, "finite")
    if "M" in values and not values["M"] > 0:
        raise ParameterError("M", values["M"], "> 0")
    for name in ("Fc", "Fc_pos", "Fc_neg"):
        if name in values and values[name] < 0:
            raise ParameterError(name, values[name], ">= 0")


def to_plant(values: Mapping[str, float]) -> tuple[dict[str, float], dict[str, float] | None]:
    """Split parameters of any structure into the plant's ``(rigid, asymmetric friction)``.

    Parameters
    ----------
    values : mapping
        Parameter name -> value; names outside :data:`PARAMETERS` are refused.

    Returns
    -------
    rigid : dict
        ``M, Fv, Fc, offset`` (missing ones 0; ``M`` is required).
    asymmetric : dict or None
        ``Fv_pos, Fc_pos, Fv_neg, Fc_neg`` when ``values`` has them (all four).
    """
    unknown = sorted(set(values) - set(PARAMETERS))
    if unknown:
        raise ParameterError(unknown[0], values[unknown[0]], f"a parameter of the axis ({', '.join(PARAMETERS)})")
    if "M" not in values:
        raise ParameterError("M", None, "given (the model has no mass)")
    rigid = {n: float(values.get(n, 0.0)) for n in RIGID}
    asym = {n: float(values[n]) for n in ASYMMETRIC if n in values}
    if asym and len(asym) != len(ASYMMETRIC):
        missing = [n for n in ASYMMETRIC if n not in asym]
        raise ParameterError(missing[0], None, "given with the other asymmetric friction parameters (Fv_pos, Fc_pos, Fv_neg, Fc_neg)")
    return rigid, (asym or None)


def from_plant(rigid: Mapping[str, float], asymmetric: Mapping[str, float] | None, structure: str) -> dict[str, float]:
    """The parameters of ``structure`` that a plant with ``rigid`` (and ``asymmetric`` friction) has.

    The asymmetric structure of a plant without asymmetric friction has
    ``Fv_pos = Fv_neg = Fv`` and ``Fc_pos = Fc_neg = Fc``; a symmetric structure
    of a plant with asymmetric friction is refused (it would lose the asymmetry).
    """
    names = structure_names(structure)
    if asymmetric is None:
        asymmetric = {"Fv_pos": rigid["Fv"], "Fv_neg": rigid["Fv"], "Fc_pos": rigid["Fc"], "Fc_neg": rigid["Fc"]}
    elif "Fv_pos" not in names:
        raise ParameterError("structure", structure, "'asymmetric' for a plant with asymmetric friction")
    merged = {**rigid, **asymmetric}
    return {n: float(merged[n]) for n in names}


PD_TIMINGS = ("recorded", "documented")
"""How a replay times a PD log's command: ``recorded``, as read from the recording
(:func:`ilic_cli.simulation.timing.recorded_loop`: the EMPS recordings' command follows
the same sample's position); ``documented``, as the log's metadata states it (the
benchmark's documented loop: one period late)."""
