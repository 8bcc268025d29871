"""The regressor as a declarative list of named columns (paper eqs. 2, 6, 30).

A :class:`Column` maps kinematic signals to one column of the observation
matrix and names the parameter it multiplies. A :class:`Model` is an ordered
tuple of columns; diagnosis adds physics by extending it, without touching the
least-squares solver.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Kinematics:
    """Signals a column may use (arrays of equal length).

    ``sign_qd`` defaults to ``sign(qd)``; the CTC law replaces it with
    ``(2/pi)*atan(alpha*qd)`` (paper section IV).
    """

    qd: np.ndarray
    qdd: np.ndarray
    q: np.ndarray | None = None
    t: np.ndarray | None = None
    sign_qd: np.ndarray | None = None
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)

    @property
    def sgn(self) -> np.ndarray:
        return np.sign(self.qd) if self.sign_qd is None else self.sign_qd


@dataclass(frozen=True)
class Column:
    """One regressor column.

    Attributes
    ----------
    name : str
        Parameter name (``M``, ``Fv``, ...), the key used in reports and JSON.
    unit : str
        Unit of the parameter.
    build : callable
        ``Kinematics -> ndarray``: the column.
    description : str
        One line for reports.
    """

    name: str
    unit: str
    build: Callable[[Kinematics], np.ndarray]
    description: str = ""


@dataclass(frozen=True)
class Model:
    """An ordered set of columns: ``tau = W(kin) @ theta``."""

    name: str
    columns: tuple[Column, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    @property
    def units(self) -> tuple[str, ...]:
        return tuple(c.unit for c in self.columns)

    def matrix(self, kin: Kinematics) -> np.ndarray:
        """Observation matrix, shape ``kin.qd.shape + (n_columns,)``.

        Signals may be stacked (``(K, n)`` for K windows) to build K matrices at once.
        """
        shape = np.shape(kin.qd)
        return np.stack([np.broadcast_to(c.build(kin), shape) for c in self.columns], axis=-1).astype(np.float64, copy=False)

    def extend(self, *columns: Column, name: str | None = None) -> Model:
        """Return a model with ``columns`` appended (names must be new)."""
        clash = set(self.names) & {c.name for c in columns}
        if clash:
            raise ValueError(f"columns already in the model: {sorted(clash)}")
        return Model(name or self.name, self.columns + tuple(columns))

    def without(self, *names: str) -> Model:
        """Return a model without the named columns."""
        return Model(self.name, tuple(c for c in self.columns if c.name not in names))


def _positive(kin: Kinematics) -> np.ndarray:
    return (1.0 + kin.sgn) / 2.0


def _negative(kin: Kinematics) -> np.ndarray:
    return (1.0 - kin.sgn) / 2.0


MASS = Column("M", "kg", lambda k: k.qdd, "mass (motor rotor, screw, nut and carriage)")
VISCOUS = Column("Fv", "N/(m/s)", lambda k: k.qd, "viscous friction")
COULOMB = Column("Fc", "N", lambda k: k.sgn, "Coulomb friction")
OFFSET = Column("offset", "N", lambda k: np.ones_like(k.qd), "force offset (amplifier offset, Coulomb asymmetry)")
VISCOUS_POS = Column("Fv_pos", "N/(m/s)", lambda k: k.qd * _positive(k), "viscous friction, positive velocity")
COULOMB_POS = Column("Fc_pos", "N", lambda k: k.sgn * _positive(k), "Coulomb friction, positive velocity")
VISCOUS_NEG = Column("Fv_neg", "N/(m/s)", lambda k: k.qd * _negative(k), "viscous friction, negative velocity")
COULOMB_NEG = Column("Fc_neg", "N", lambda k: k.sgn * _negative(k), "Coulomb friction, negative velocity")

MODELS: dict[str, Model] = {
    "rigid": Model("rigid", (MASS, VISCOUS, COULOMB)),
    "rigid-offset": Model("rigid-offset", (MASS, VISCOUS, COULOMB, OFFSET)),
    "asymmetric": Model("asymmetric", (MASS, VISCOUS_POS, COULOMB_POS, VISCOUS_NEG, COULOMB_NEG)),
}
"""Model structures by name (paper eq. 30; benchmark asymmetric model)."""


def get_model(name: str) -> Model:
    """Return the named model structure (``rigid``, ``rigid-offset``, ``asymmetric``)."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model '{name}' (choose from {', '.join(MODELS)})") from None
