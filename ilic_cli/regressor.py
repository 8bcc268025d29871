"""The regressor as a declarative list of named columns (paper eqs. 2, 6, 30).

A :class:`Column` maps kinematic signals to one column of the observation
matrix and names the parameter it multiplies. A :class:`Model` is an ordered
tuple of columns: a structure of :mod:`ilic_cli.parameters`, extended by the
columns of effects (:meth:`Model.extend`, :mod:`ilic_cli.effects`) without
touching the least-squares solver.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from ilic_cli import parameters


def evaluated_later(t: np.ndarray, x: np.ndarray, shift_s: float) -> np.ndarray:
    """``x``, sampled at ``t``, linearly interpolated at ``t + shift_s`` (the last value held at the end): the one
    definition of a signal evaluated later (the regressor beyond the drive's hold, a force shifted by a delay)."""
    return np.interp(t + shift_s, t, x)


def expected_sign(qd: np.ndarray, noise: float) -> np.ndarray:
    """The expected sign of a velocity measured as ``qd`` with Gaussian noise of RMS ``noise``: ``erf(qd / (sqrt(2) noise))``;
    ``sign(qd)`` when ``noise`` is 0 (:data:`ilic_cli.usable.SIGN_RULE`)."""
    if noise <= 0.0:
        return np.sign(qd)
    from scipy.special import erf  # deferred: a scipy submodule, for the logs with rows at rest only

    return np.asarray(erf(np.asarray(qd, dtype=np.float64) / (np.sqrt(2.0) * noise)), dtype=np.float64)


@dataclass(frozen=True)
class Kinematics:
    """Signals a column may use (arrays of equal length).

    ``sign_qd`` defaults to ``sign(qd)``, or to :func:`expected_sign` when ``speed_noise`` (the RMS of the
    velocity's noise) is given; the CTC law replaces it with ``(2/pi)*atan(alpha*qd)`` (paper section IV).
    """

    qd: np.ndarray
    qdd: np.ndarray
    q: np.ndarray | None = None
    t: np.ndarray | None = None
    sign_qd: np.ndarray | None = None
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    speed_noise: float = 0.0

    @property
    def sgn(self) -> np.ndarray:
        return expected_sign(self.qd, self.speed_noise) if self.sign_qd is None else self.sign_qd

    def later(self, shift_s: float) -> Kinematics:
        """These kinematics linearly interpolated at ``t + shift_s`` (the last value held at the end)."""
        t = self.t
        assert t is not None

        def at(x: np.ndarray) -> np.ndarray:
            return evaluated_later(t, x, shift_s)

        sign_qd = None if self.sign_qd is None else at(self.sign_qd)
        q = None if self.q is None else at(self.q)
        extra = {n: at(v) for n, v in self.extra.items()}
        return Kinematics(qd=at(self.qd), qdd=at(self.qdd), q=q, t=t, sign_qd=sign_qd, extra=extra, speed_noise=self.speed_noise)


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


def positive_side(kin: Kinematics) -> np.ndarray:
    """1 where the velocity is positive, 0 where negative (1/2 at rest): the benchmark's asymmetric model."""
    return (1.0 + kin.sgn) / 2.0


def negative_side(kin: Kinematics) -> np.ndarray:
    """1 where the velocity is negative, 0 where positive (1/2 at rest)."""
    return (1.0 - kin.sgn) / 2.0


_BUILDS: dict[str, Callable[[Kinematics], np.ndarray]] = {
    "M": lambda k: k.qdd,
    "Fv": lambda k: k.qd,
    "Fc": lambda k: k.sgn,
    "offset": lambda k: np.ones_like(k.qd),
    "Fv_pos": lambda k: k.qd * positive_side(k),
    "Fc_pos": lambda k: k.sgn * positive_side(k),
    "Fv_neg": lambda k: k.qd * negative_side(k),
    "Fc_neg": lambda k: k.sgn * negative_side(k),
}
"""Column of each rigid parameter (paper eq. 30; benchmark asymmetric model)."""

COLUMNS: dict[str, Column] = {n: Column(n, p.unit, _BUILDS[n], p.meaning) for n, p in parameters.PARAMETERS.items()}
"""The regressor column of every rigid parameter of :mod:`ilic_cli.parameters`."""


def _q(k: Kinematics) -> np.ndarray:
    if k.q is None:
        raise ValueError("the gravity columns need the position q")
    return k.q


_GRAVITY_BUILDS: dict[str, Callable[[Kinematics], np.ndarray]] = {
    "MX": lambda k: parameters.STANDARD_GRAVITY * np.cos(_q(k)),
    "MY": lambda k: -parameters.STANDARD_GRAVITY * np.sin(_q(k)),
}
"""Gravity on a revolute link, ``g·(MX cos q - MY sin q)`` (paper eq. 3), ``q`` from the joint's zero as given."""

GRAVITY_COLUMNS: dict[str, Column] = {n: Column(n, p.unit, _GRAVITY_BUILDS[n], p.meaning) for n, p in parameters.FIRST_MOMENTS.items()}
"""The column pair of the first moments ``MX, MY`` (:data:`ilic_cli.parameters.FIRST_MOMENTS`): the ``gravity`` effect's."""

MODELS: dict[str, Model] = {name: Model(name, tuple(COLUMNS[n] for n in names)) for name, names in parameters.STRUCTURES.items()}
"""Model structures by name (:data:`ilic_cli.parameters.STRUCTURES`)."""


def get_model(name: str) -> Model:
    """Return the named model structure (``rigid``, ``rigid-offset``, ``asymmetric``)."""
    parameters.structure_names(name)
    return MODELS[name]
