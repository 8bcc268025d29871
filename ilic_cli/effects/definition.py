"""The parts of an effect's definition: :class:`Effect` and what it is made of.

An effect's plant force, when it is linear in its parameters, is its own
regressor columns times coefficients (:meth:`Effect.plant_force`): the plant
(:func:`plant.dynamics.force_model` and the compiled loop) takes it from here.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.errors import ParameterError
from ilic_cli.lsq import finite_or_none
from ilic_cli.regressor import COLUMNS, Column, Kinematics


@dataclass(frozen=True)
class PlantParam:
    """One plant parameter of an effect and its valid range.

    ``low``/``high`` bound the value (``low_open``: strictly above ``low``);
    every value must be finite.
    """

    name: str
    unit: str
    default: float
    meaning: str = ""
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False

    def check(self, effect: str, value: float) -> None:
        """Raise :class:`ParameterError` when ``value`` breaks the range."""
        label = f"{effect}.{self.name}"
        if not math.isfinite(value):
            raise ParameterError(label, value, "finite")
        if self.low_open and not value > self.low:
            raise ParameterError(label, value, f"> {self.low:g}")
        if not self.low_open and value < self.low:
            raise ParameterError(label, value, f">= {self.low:g}")
        if value > self.high:
            raise ParameterError(label, value, f"<= {self.high:g}")


@dataclass(frozen=True)
class Scan:
    """The nonlinear parameter of an effect and how to search it.

    Attributes
    ----------
    name, unit : str
        Parameter name and unit.
    grid : callable
        ``(kin, fs_hz) -> ndarray`` candidate values, sorted, from the data's
        own ranges (velocity, stroke, duration).
    log : bool
        Refine on a logarithmic scale (positive, scale-free parameters).
    secondary : tuple, optional
        A second nonlinear parameter ``(name, unit, low, high, default)``,
        refined by a 1-D search once the first is found (the value is then
        the pair ``(first, second)``).
    of_the_whole_log : bool
        The value is a time of the log (a payload's change time): the
        diagnosis's held-out check keeps the whole log's value and refits the
        rest on each fold's training blocks, since a fold whose held-out
        block holds that time cannot place it from its training blocks; and
        its folds are laid on each side of that time, so that each fold
        trains on rows before and after it
        (:func:`ilic_cli.diagnosis.stats.folds_either_side`).
    at_log_rate : callable, optional
        ``(kin, fs_hz) -> bool``: whether the value is searched at the log's rate (the full-rate samples of the rows'
        decimation spans), not on the decimated rows: where its signature lies above the band the rows keep (a flexible
        mode's resonance, which the 20 Hz of a 500 Hz log's rows filter out); its linear coefficients and every test
        stay on the rows. ``None``: always on the rows.
    """

    name: str
    unit: str
    grid: Callable[[Kinematics, float], np.ndarray]
    log: bool = True
    secondary: tuple[str, str, float, float, float] | None = None
    of_the_whole_log: bool = False
    at_log_rate: Callable[[Kinematics, float], bool] | None = None


Z95 = 1.959963984540054
"""The two-sided 95 % point of the normal distribution: an estimate's 95 % interval is ``value ± Z95 std``."""


@dataclass(frozen=True)
class Estimate:
    """A value with its standard deviation (``None`` when not estimated) and unit."""

    value: float
    std: float | None
    unit: str = ""

    @property
    def determined(self) -> bool:
        """Whether the log determines it: its 95 % interval, ``value ± 1.96 std``, leaves out 0 (a standard deviation above
        half the value's size does not: the log does not tell the value from none, e.g. gravity's ``MX`` where the swing is
        too short to separate ``cos q`` from the offset). Without a standard deviation nothing is claimed either way: ``True``
        (an infinite value: ``False``)."""
        return math.isfinite(self.value) and (self.std is None or (math.isfinite(self.std) and abs(self.value) > Z95 * self.std))

    def to_dict(self) -> dict[str, Any]:
        std = None if self.std is None else finite_or_none(self.std)
        return {"value": finite_or_none(self.value), "std": std, "unit": self.unit, "determined": self.determined}


@dataclass(frozen=True)
class Fit:
    """A least-squares fit seen by one effect: every column's estimate and the covariance.

    Attributes
    ----------
    names : tuple of str
        Column names (rigid parameters and effect columns).
    theta, cov : ndarray
        Estimates and their covariance.
    value : Any
        The effect's nonlinear value (``None`` without a scan).
    value_std : float or None
        Standard deviation of the nonlinear value.
    hold_s : float
        Half a sample period when the logged force is the held drive
        command, which the fit's regressor already accounts for (a ``delay``
        found is beyond it), else 0.
    joint : str
        The joint's type (``prismatic`` or ``revolute``): the units the notes write their values in (:func:`unit_on`).
    """

    names: tuple[str, ...]
    theta: np.ndarray
    cov: np.ndarray
    value: Any = None
    value_std: float | None = None
    hold_s: float = 0.0
    joint: str = "prismatic"

    def has(self, name: str) -> bool:
        return name in self.names

    def get(self, name: str, default: float = 0.0) -> float:
        return float(self.theta[self.names.index(name)]) if name in self.names else default

    def combination(self, weights: Mapping[str, float]) -> tuple[float, float]:
        """Value and standard deviation of ``sum(weights[n] * theta[n])``."""
        w = np.array([weights.get(n, 0.0) for n in self.names])
        return float(w @ self.theta), float(math.sqrt(max(w @ self.cov @ w, 0.0)))


@dataclass(frozen=True)
class EffectColumn:
    """One regressor column an effect adds: the parameter it multiplies.

    The columns are built together by :attr:`Effect.build`, or, without it, each by its own pointwise form ``of``:
    ``(q, qd, qdd, t, value) -> column`` with ``value`` the effect's nonlinear value (``None`` without a scan).
    ``of`` uses NumPy operations only (arrays or floats), so the plant's loop compiles it as it is; its force is a
    force of ``q, qd`` and ``t`` (the compiled loop calls it at ``qdd = 0``: an acceleration term is a mass, which
    a compiled form of its own gives).
    """

    name: str
    unit: str
    description: str = ""
    of: Callable[[Any, Any, Any, Any, Any], Any] | None = None


REVOLUTE_TOKENS = {"m": "rad", "N": "N·m", "kg": "kg·m²"}
"""A prismatic unit's factors on a revolute joint: metres turn to radians, newtons to newton-metres, kilograms to kg·m²."""


def unit_on(unit: str, joint: str) -> str:
    """The unit a catalogue quantity written for a prismatic axis has on a ``joint`` (N·s/m -> N·m·s/rad, m/s -> rad/s, kg -> kg·m²).

    The catalogue writes its effects in a prismatic axis's units, as the EMPS; on a revolute joint each factor turns by
    :data:`REVOLUTE_TOKENS`, and a unit without them (s, Hz, rad, none) stays."""
    if joint != "revolute":
        return unit
    return "".join(REVOLUTE_TOKENS.get(part, part) for part in re.split(r"([·/])", unit))


def col(name: str, description: str, unit: str = "", of: Callable[[Any, Any, Any, Any, Any], Any] | None = None) -> EffectColumn:
    """A column of a built-in effect (unit from :mod:`ilic_cli.parameters` when it is a rigid parameter)."""
    return EffectColumn(name, unit or parameters.unit(name), description, of)


LinearForm = tuple[Any, dict[str, Any]]
"""``(nonlinear value, {column name: coefficient})``: an effect's plant force as its columns times coefficients."""


EstimateResult = tuple[dict[str, Estimate], dict[str, float] | None, str]
"""``(reported estimates, plant parameters or None, note)`` of one effect's fit."""


@dataclass(frozen=True)
class Effect:
    """One physical effect: plant term, identification columns, search, signature, words.

    Attributes
    ----------
    id : str
        Stable identifier (model files, ``--effect``, log metadata).
    title, explanation : str
        Name in plain words; one sentence of physics.
    params : tuple of PlantParam
        Plant parameters (empty for ``offset``, which is a rigid parameter).
    plant : bool
        Part of the plant (a model-file effect); ``offset`` is not (it is a
        rigid parameter). The plant's kernel has a compiled form of the
        built-in effects (``plant.dynamics.SLOTS``, checked against
        :meth:`plant_force` by the tests) and compiles the columns' ``of``
        for any other.
    coefficients : callable, optional
        ``(plant values) -> (value, {column: coefficient})``: the plant force
        of the effect as its columns times coefficients (:meth:`plant_force`),
        the inverse of ``estimate``. A coefficient may multiply a rigid
        parameter's column (:data:`ilic_cli.regressor.COLUMNS`: the spring's
        rest position is an offset). Default: each column is the plant
        parameter of its name, the scan value the parameter of the scan's name
        (no linear form when a column is not a plant parameter).
    replaces : tuple of str
        Rigid parameters whose columns the plant force takes the place of
        (``asymmetric_friction``: ``Fv, Fc``).
    strategy : str, optional
        How diagnosis identifies it beyond a fit of its columns
        (``stribeck``: ``dwell_segments``).
    check : callable, optional
        ``(values) -> None``: rules beyond each parameter's range.
    form, signature : str
        What it adds to the inverse dynamic model; how it shows in the residual.
    signature_kinds : tuple of str
        Region families (:mod:`ilic_cli.diagnosis.locate`) where it shows.
    columns : tuple of EffectColumn
        Regressor columns it adds, built together by ``build``.
    build : callable, optional
        ``(kin, value, fs_hz) -> ndarray (n, len(columns))``.
    scan : Scan, optional
        The nonlinear parameter, if any.
    shift : bool
        No column: the force is shifted in time by the scanned value.
    noisy_columns : bool
        Its columns carry the position's noise amplified (a flexibility's, four derivatives near its resonance): a
        plant is fitted with least squares corrected for that noise (:func:`ilic_cli.lsq.noise_corrected_lstsq`).
    impossible : callable, optional
        ``(theta of its columns, value, joint) -> reason or None``: estimates that
        cannot be this physics reject the candidate (the reason in the ``joint``'s units, :func:`unit_on`).
    estimate : callable, optional
        ``(Fit) -> (estimates, plant parameters or None, note)``; default: the
        columns are the plant parameters of the same names, the scan value
        the plant parameter of the scan's name.
    scan_value : callable, optional
        ``(plant values, M) -> value``: the nonlinear value of a model file's
        effect (default: the plant parameter named like the scan).
    sentence : callable, optional
        ``(estimates) -> str`` for reports (default: ``name = value`` pairs).
    realise : callable, optional
        ``(plant parameters, hold_s) -> {plant effect id: parameters}``: the
        plant effects that realise the estimate (:meth:`plant_entries`;
        default: this effect with its own parameters).
    joints : tuple of str
        The joint types (:func:`ilic_cli.runlog.joint_type`) diagnosis
        proposes it on (``gravity``: a revolute joint only).
    """

    id: str
    title: str
    explanation: str
    params: tuple[PlantParam, ...] = ()
    plant: bool = True
    coefficients: Callable[[Mapping[str, float]], LinearForm] | None = None
    replaces: tuple[str, ...] = ()
    strategy: str | None = None
    check: Callable[[Mapping[str, float]], None] | None = None
    form: str = ""
    signature: str = ""
    signature_kinds: tuple[str, ...] = ()
    columns: tuple[EffectColumn, ...] = ()
    build: Callable[[Kinematics, Any, float], np.ndarray] | None = None
    scan: Scan | None = None
    shift: bool = False
    noisy_columns: bool = False
    impossible: Callable[[np.ndarray, Any, str], str | None] | None = None
    estimate: Callable[[Fit], EstimateResult] | None = None
    scan_value: Callable[[Mapping[str, float], float], Any] | None = None
    sentence: Callable[[Mapping[str, Estimate]], str] | None = None
    realise: Callable[[Mapping[str, float], float], dict[str, dict[str, float]]] | None = None
    joints: tuple[str, ...] = ("prismatic", "revolute")

    def plant_entries(self, plant: Mapping[str, float], hold_s: float = 0.0) -> dict[str, dict[str, float]]:
        """The plant effects (id -> parameters) that realise this effect's plant parameters in a model file and a replay.

        ``hold_s``: half a sample period when the logged force is the held drive command, else 0 (:class:`Fit`).
        """
        if self.realise is not None:
            return self.realise(plant, hold_s)
        return {self.id: {k: float(v) for k, v in plant.items()}}

    @property
    def names(self) -> tuple[str, ...]:
        """Plant parameter names, in order."""
        return tuple(p.name for p in self.params)

    @property
    def nonlinear(self) -> bool:
        return self.scan is not None

    @property
    def identifiable(self) -> bool:
        """Diagnosis can fit it (columns or a shift)."""
        return bool(self.columns) or self.shift

    @property
    def column_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    def matrix(self, kin: Kinematics, value: Any = None, fs_hz: float = 1000.0) -> np.ndarray:
        """Full-rate columns, shape ``(n, len(columns))``."""
        n = len(kin.qd)
        if self.build is not None:
            return np.asarray(self.build(kin, value, fs_hz), dtype=np.float64).reshape(n, -1)
        if self.columns and all(c.of is not None for c in self.columns):
            return np.column_stack([np.broadcast_to(c.of(kin.q, kin.qd, kin.qdd, kin.t, value), (n,)) for c in self.columns if c.of is not None])
        return np.zeros((n, 0))

    def linear_form(self, values: Mapping[str, float]) -> LinearForm | None:
        """The plant force of plant ``values`` as ``(value, {column: coefficient})`` (``None``: not linear in its columns)."""
        if not self.plant:
            return None
        if self.coefficients is not None:
            return self.coefficients(values)
        if not self.columns or any(c.name not in self.names for c in self.columns):
            return None
        value = None if self.scan is None else values[self.scan.name]
        return value, {c.name: values[c.name] for c in self.columns}

    def plant_force(self, values: Mapping[str, float], kin: Kinematics, fs_hz: float = 1000.0) -> np.ndarray | None:
        """The effect's force in the plant, ``columns(q, qd, qdd, t) @ coefficients`` (``None``: no linear form).

        Its own columns (:meth:`matrix`) and the rigid ones it names (:data:`ilic_cli.regressor.COLUMNS`).
        """
        form = self.linear_form(values)
        if form is None:
            return None
        value, theta = form
        own = self.column_names
        W = self.matrix(kin, value, fs_hz) if any(n in theta for n in own) else None
        tau = np.zeros(len(kin.qd))
        for name, coef in theta.items():
            column = W[:, own.index(name)] if name in own and W is not None else COLUMNS[name].build(kin)
            tau = tau + coef * column
        return tau

    def regressor_columns(self, value: Any = None, fs_hz: float = 1000.0) -> tuple[Column, ...]:
        """The columns as :class:`~ilic_cli.regressor.Column` s for a fixed nonlinear ``value``."""

        def column(kin: Kinematics, i: int) -> np.ndarray:
            return self.matrix(kin, value, fs_hz)[:, i]

        return tuple(Column(c.name, c.unit, functools.partial(column, i=i), c.description) for i, c in enumerate(self.columns))

    def fit_to_plant(self, fit: Fit) -> EstimateResult:
        """Reported estimates, plant parameters and a note from a fit that includes this effect."""
        if self.estimate is not None:
            return self.estimate(fit)
        est: dict[str, Estimate] = {}
        for c in self.columns:
            est[c.name] = Estimate(*fit.combination({c.name: 1.0}), c.unit)
        if self.scan is not None:
            est[self.scan.name] = Estimate(float(fit.value), fit.value_std, self.scan.unit)
        if not self.plant:
            return est, None, ""
        plant = {p.name: est[p.name].value for p in self.params if p.name in est}
        return est, {**{p.name: p.default for p in self.params}, **plant}, ""

    def value_from_plant(self, values: Mapping[str, float], M: float) -> Any:
        """The nonlinear value of a model file's effect (``None`` without a scan)."""
        if self.scan is None:
            return None
        if self.scan_value is not None:
            return self.scan_value(values, M)
        return float(values[self.scan.name])

    def unit_on(self, unit: str, joint: str) -> str:
        """One of this effect's units on a ``joint`` (:func:`unit_on`); an effect of a revolute joint only, gravity, is written
        in its units already."""
        return unit_on(unit, joint) if "prismatic" in self.joints else unit

    def on_joint(self, estimates: Mapping[str, Estimate], joint: str) -> dict[str, Estimate]:
        """``estimates`` with the units they have on a ``joint`` (:meth:`unit_on`)."""
        return {k: Estimate(e.value, e.std, self.unit_on(e.unit, joint)) for k, e in estimates.items()}

    def describe(self, estimates: Mapping[str, Estimate]) -> str:
        """``title (what was found)`` for reports."""
        what = self.sentence(estimates) if self.sentence is not None else ", ".join(f"{k} = {v.value:.4g}" for k, v in estimates.items())
        return f"{self.title} ({what})"

    def values(self, given: Mapping[str, Any] | None = None) -> dict[str, float]:
        """Checked plant values: defaults completed with ``given``."""
        given = dict(given or {})
        unknown = sorted(set(given) - set(self.names))
        if unknown:
            raise ParameterError(f"{self.id}.{unknown[0]}", given[unknown[0]], f"a parameter of '{self.id}' ({', '.join(self.names) or 'none'})")
        out: dict[str, float] = {}
        for p in self.params:
            raw = given.get(p.name, p.default)
            try:
                v = float(raw)
            except (TypeError, ValueError):
                raise ParameterError(f"{self.id}.{p.name}", raw, "a number") from None
            p.check(self.id, v)
            out[p.name] = v
        if self.check is not None:
            self.check(out)
        return out

    def to_dict(self) -> dict[str, object]:
        return {
            "id": self.id,
            "title": self.title,
            "explanation": self.explanation,
            "form": self.form,
            "signature": self.signature,
            "parameters": [{"name": c.name, "unit": c.unit, "description": c.description} for c in self.columns],
            "nonlinear": None if self.scan is None else {"name": self.scan.name, "unit": self.scan.unit},
        }


@dataclass(frozen=True)
class EffectParams:
    """An effect with checked plant values: what the plant simulates and a model file holds."""

    effect: Effect
    params: dict[str, float] = field(default_factory=dict)

    @property
    def id(self) -> str:
        return self.effect.id

    def __getitem__(self, name: str) -> float:
        return self.params[name]

    def vector(self) -> np.ndarray:
        """The values in the order of the definition's parameters."""
        return np.array([self.params[n] for n in self.effect.names], dtype=np.float64)

    def to_dict(self) -> dict[str, float]:
        return {n: float(self.params[n]) for n in self.effect.names}


Effects = dict[str, EffectParams]
