"""The physical effects a rigid drive model leaves out: one definition each.

An :class:`Effect` holds everything the project knows about one effect:

* its plant parameters (:class:`PlantParam`: name, unit, default, valid range)
  and any further rule (:attr:`Effect.check`);
* its force term in the plant (:attr:`Effect.force`, a force of position and
  velocity, vectorised with NumPy; the plant's compiled kernel has its own
  form for the built-in effects, checked against this one by the tests, and
  compiles ``force`` itself for an effect it has no form for);
* for identification and diagnosis: the regressor columns it adds
  (:attr:`Effect.columns`, built by :attr:`Effect.build`), the nonlinear
  parameter to search and its grid (:class:`Scan`), or a time shift of the
  force (``shift``);
* the way a fit of those columns becomes plant parameters
  (:attr:`Effect.estimate`) and back (:attr:`Effect.scan_value`);
* its residual signature (region families of
  :mod:`ilic_cli.diagnosis.locate`) and its plain-word explanation and
  sentence for reports.

Adding an effect is one :func:`register` call with a new definition (see the
README's "Adding an effect"); the plant, ``ilic identify --effect``,
``ilic diagnose``, the model file and ``ilic replay`` pick it up.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.errors import ParameterError
from ilic_cli.filtering import bilinear_lfilter
from ilic_cli.lsq import finite_or_none
from ilic_cli.parameters import STANDARD_GRAVITY
from ilic_cli.regressor import GRAVITY_COLUMNS, Column, Kinematics, negative_side


# ---------------------------------------------------------------------------
# the parts of a definition
# ---------------------------------------------------------------------------
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
    """

    name: str
    unit: str
    grid: Callable[[Kinematics, float], np.ndarray]
    log: bool = True
    secondary: tuple[str, str, float, float, float] | None = None


@dataclass(frozen=True)
class Estimate:
    """A value with its standard deviation (``None`` when not estimated) and unit."""

    value: float
    std: float | None
    unit: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"value": finite_or_none(self.value), "std": None if self.std is None else finite_or_none(self.std), "unit": self.unit}


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
    """

    names: tuple[str, ...]
    theta: np.ndarray
    cov: np.ndarray
    value: Any = None
    value_std: float | None = None
    hold_s: float = 0.0

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
    """One regressor column an effect adds: the parameter it multiplies (all columns are built by :attr:`Effect.build`)."""

    name: str
    unit: str
    description: str = ""


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
    force : callable, optional
        ``(q, qd, prm) -> force`` added to the inverse dynamics, with ``prm``
        the parameter values in the order of ``params`` (a float64 array);
        NumPy operations only, so the plant can compile it.
    plant : bool
        Part of the plant (a model-file effect); ``offset`` is not (it is a
        rigid parameter). The plant's kernel has a compiled form of the
        built-in effects (``plant.dynamics.SLOTS``) and compiles ``force`` for
        any other.
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
    impossible : callable, optional
        ``(theta of its columns, value) -> reason or None``: estimates that
        cannot be this physics reject the candidate.
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
    force: Callable[[Any, Any, np.ndarray], Any] | None = None
    plant: bool = True
    check: Callable[[Mapping[str, float]], None] | None = None
    form: str = ""
    signature: str = ""
    signature_kinds: tuple[str, ...] = ()
    columns: tuple[EffectColumn, ...] = ()
    build: Callable[[Kinematics, Any, float], np.ndarray] | None = None
    scan: Scan | None = None
    shift: bool = False
    impossible: Callable[[np.ndarray, Any], str | None] | None = None
    estimate: Callable[[Fit], EstimateResult] | None = None
    scan_value: Callable[[Mapping[str, float], float], Any] | None = None
    sentence: Callable[[Mapping[str, Estimate]], str] | None = None
    realise: Callable[[Mapping[str, float], float], dict[str, dict[str, float]]] | None = None
    joints: tuple[str, ...] = ("prismatic", "revolute")
    strategy: str | None = None  # how the diagnosis identifies it beyond the inverse model (ilic_cli.diagnosis.strategies), by name

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
        if self.build is None:
            return np.zeros((len(kin.qd), 0))
        return np.asarray(self.build(kin, value, fs_hz), dtype=np.float64).reshape(len(kin.qd), -1)

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
        """The values in the order of the definition's parameters (the ``prm`` of ``force``)."""
        return np.array([self.params[n] for n in self.effect.names], dtype=np.float64)

    def to_dict(self) -> dict[str, float]:
        return {n: float(self.params[n]) for n in self.effect.names}


Effects = dict[str, EffectParams]

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


def unit_of(name: str) -> str:
    """The unit of a regressor column: a rigid parameter's (:mod:`ilic_cli.parameters`) or an effect column's."""
    unit = parameters.unit(name)
    if unit:
        return unit
    return next((c.unit for e in EFFECTS.values() for c in e.columns if c.name == name), "")


def applicable(effect: Effect, base_names: tuple[str, ...]) -> bool:
    """Whether ``effect`` adds something to a model with columns ``base_names`` (not already its columns or its parameters)."""
    return not any(n in base_names for n in (*effect.column_names, *effect.names))


# ---------------------------------------------------------------------------
# data-driven search grids
# ---------------------------------------------------------------------------
def _vmax(kin: Kinematics) -> float:
    v = float(np.percentile(np.abs(kin.qd), 99.5))
    return v if v > 0 else 1.0


def _stribeck_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    # from 1 % (below: standstill, left out of the fit) to 40 % of the top speed
    vmax = _vmax(kin)
    return np.geomspace(0.01 * vmax, 0.4 * vmax, 32)


def _ripple_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    # spatial periods from what the IDIM bandwidth (40 Hz after decimation) can
    # see at the median moving speed up to half the stroke, spaced so that the
    # phase over the stroke moves by less than a tenth of a cycle per step
    q = kin.q if kin.q is not None else np.cumsum(kin.qd) / fs_hz
    stroke = float(np.ptp(q)) or 1.0
    moving = np.abs(kin.qd) > 0.05 * _vmax(kin)
    v_typ = float(np.median(np.abs(kin.qd[moving]))) if moving.any() else _vmax(kin)
    p_min = max(v_typ / 40.0, stroke / 2000.0)
    p_max = stroke / 2.0
    if p_max <= p_min:
        return np.array([p_max])
    # d(stroke/P) = 0.1  ->  P_{k+1} = P_k / (1 - 0.1 P_k / stroke)
    out = [p_min]
    while out[-1] < p_max:
        out.append(out[-1] / max(1.0 - 0.1 * out[-1] / stroke, 0.5))
    return np.array(out)


def _change_time_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    t = kin.t if kin.t is not None else np.arange(len(kin.qd)) / fs_hz
    t0, t1 = float(t[0]), float(t[-1])
    margin = 0.05 * (t1 - t0)
    return np.linspace(t0 + margin, t1 - margin, 200)


def _delay_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    # +-25 ms in steps of half a sample (refined afterwards)
    step = 0.5 / fs_hz
    return np.arange(-0.025, 0.025 + step / 2, step)


def _resonance_grid(kin: Kinematics, fs_hz: float) -> np.ndarray:
    # what survives the IDIM low-pass: up to 0.8 of the decimated Nyquist (40 Hz at 1 kHz / 10)
    return np.geomspace(2.0, 0.08 * fs_hz / 2 * 1.0, 40)


FLEX_DAMPING = 0.05
"""Damping ratio of the flexible mode while its frequency is searched (then refined)."""


def flexible_acceleration(qdd: np.ndarray, f_hz: float, fs_hz: float, zeta: float = FLEX_DAMPING) -> np.ndarray:
    """Acceleration of a load coupled to the measured side by a spring-damper.

    ``qdd_L = H(s) qdd`` with ``H = (2 zeta w s + w^2) / (s^2 + 2 zeta w s + w^2)``,
    ``w = 2 pi f_hz``, discretised by the bilinear transform and applied
    forward only (causal, like the physics).
    """
    w = 2.0 * math.pi * f_hz
    return bilinear_lfilter([2.0 * zeta * w, w * w], [1.0, 2.0 * zeta * w, w * w], fs_hz, qdd)


def _col(name: str, description: str, unit: str = "") -> EffectColumn:
    """A column of a built-in effect (unit from :mod:`ilic_cli.parameters` when it is a rigid parameter)."""
    return EffectColumn(name, unit or parameters.unit(name), description)


# ---------------------------------------------------------------------------
# the built-in effects
# ---------------------------------------------------------------------------
def _asym_estimate(fit: Fit) -> EstimateResult:
    fv = fit.combination({"Fv": 1.0})
    fvn = fit.combination({"Fv": 1.0, "dFv_neg": 1.0})
    est = {"Fv_pos": Estimate(*fv, "N·s/m"), "Fv_neg": Estimate(*fvn, "N·s/m")}
    fc = fit.combination({"Fc": 1.0}) if fit.has("Fc") else (0.0, 0.0)
    note = ""
    if fit.has("offset"):
        est["Fc_pos"] = Estimate(*fit.combination({"Fc": 1.0, "offset": 1.0}), "N")
        est["Fc_neg"] = Estimate(*fit.combination({"Fc": 1.0, "offset": -1.0}), "N")
        note = (
            "Fc_pos/Fc_neg attribute the whole constant offset to Coulomb asymmetry; the two cannot be told apart "
            "(the model file keeps Fc symmetric plus the offset)"
        )
    return est, {"Fv_pos": fv[0], "Fv_neg": fvn[0], "Fc_pos": fc[0], "Fc_neg": fc[0]}, note


def _stribeck_estimate(fit: Fit) -> EstimateResult:
    level = fit.combination({"Fs": 1.0})
    est = {"Fs": Estimate(*level, "N"), "vs": Estimate(float(fit.value), fit.value_std, "m/s")}
    if fit.has("Fc_pos") and fit.has("Fc_neg"):
        fc = min(fit.get("Fc_pos"), fit.get("Fc_neg"))
    else:
        fc = fit.get("Fc")
    if fc + level[0] < 0:
        return est, None, f"Fs = {level[0]:.3g} N would put the static friction level Fc + Fs below 0: not in the model file"
    note = f"negative Fs, kept in the model file: the plant's static friction level Fc + Fs is {fc + level[0]:.3g} N" if level[0] < 0 else ""
    return est, {"Fs": level[0], "vs": float(fit.value)}, note


def _stribeck_sentence(p: Mapping[str, Estimate]) -> str:
    what = f"extra friction Fs = {p['Fs'].value:.3g} N below vs = {p['vs'].value * 1e3:.3g} mm/s"
    if p["Fs"].value < 0:
        what += (
            "; negative: friction is lower at low speed than the Coulomb-viscous line, the opposite of the Stribeck effect, "
            "so read it as a shape correction of the friction curve"
        )
    return what


def _ripple_estimate(fit: Fit) -> EstimateResult:
    a, b = fit.get("ripple_sin"), fit.get("ripple_cos")
    ia, ib = fit.names.index("ripple_sin"), fit.names.index("ripple_cos")
    A = math.hypot(a, b)
    J_A = np.array([a, b]) / A if A > 0 else np.zeros(2)
    J_ph = np.array([-b, a]) / (A * A) if A > 0 else np.zeros(2)
    C = fit.cov[np.ix_([ia, ib], [ia, ib])]
    est = {
        "A": Estimate(A, float(math.sqrt(max(J_A @ C @ J_A, 0.0))), "N"),
        "L": Estimate(float(fit.value), fit.value_std, "m"),
        "phase": Estimate(math.atan2(b, a), float(math.sqrt(max(J_ph @ C @ J_ph, 0.0))), "rad"),
    }
    return est, {"A": A, "L": float(fit.value), "phase": math.atan2(b, a)}, ""


def _spring_estimate(fit: Fit) -> EstimateResult:
    k = fit.combination({"k_spring": 1.0})
    note = "the rest position q0 is absorbed by the offset (q0 = 0 in the model file)" if fit.has("offset") else ""
    return {"k": Estimate(*k, "N/m")}, {"k": k[0], "q0": 0.0}, note


def _delay_estimate(fit: Fit) -> EstimateResult:
    # the diagnosis baseline already holds the logged command (the regressor half a sample later): the delay found is beyond the hold
    d = float(fit.value)
    note = ""
    if fit.hold_s:
        note = f"the logged force is the held command: the delay is measured beyond its {fit.hold_s * 1e3:.3g} ms zero-order hold"
    if d < 0:
        note += ("; " if note else "") + "negative: the force acts after it is logged (drive lag)"
        if "current_loop" in _delay_realise({"delay": d}, fit.hold_s):
            note += (
                f", shorter than a sample: the drive's current loop, which the model file and the replays realise as a "
                f"first-order lag of {1.0 / (2.0 * math.pi * -d):.3g} Hz"
            )
    return {"delay": Estimate(float(fit.value), fit.value_std, "s")}, {"delay": d}, note


def _delay_realise(plant: Mapping[str, float], hold_s: float) -> dict[str, dict[str, float]]:
    """A drive lag shorter than a sample as the drive's current loop (the first-order lag of that time constant), else a delay.

    A lag within the sample is the current loop's (0.23 ms at 700 Hz): a pure
    delay of that size has the same low-frequency lag but not the loop's
    response to a step of the command, which the stick and break-away at a
    trapezoid's dwells show (measured: with a pure 0.24 ms delay in the replay,
    Stribeck friction at the dwells was kept on both clean current-loop
    trapezoids; with the first-order loop, on neither). ``hold_s`` is half the
    sample period (0: the logged force is no held command, and the sample does
    not bound the lag).
    """
    lag = -float(plant["delay"])
    if hold_s > 0.0 and 0.0 < lag < 2.0 * hold_s:
        return {"current_loop": {"bandwidth_hz": 1.0 / (2.0 * math.pi * lag)}}
    return {"delay": {"delay": float(plant["delay"])}}


def _flex_estimate(fit: Fit) -> EstimateResult:
    v = fit.value
    scalar = bool(np.isscalar(v))  # a bool: np.isscalar's TypeGuard would narrow v to types float() does not take
    f_res, zeta = (float(v), FLEX_DAMPING) if scalar else (float(v[0]), float(v[1]))
    ml = fit.combination({"M_load": 1.0})
    M = fit.get("M", float("nan"))
    w = 2.0 * math.pi * f_res
    frac = ml[0] / M if M > 0 else float("nan")
    k = w * w * ml[0]
    k_std = None
    if fit.value_std is not None and ml[0] > 0:
        k_std = k * math.sqrt((2 * fit.value_std / f_res) ** 2 + (ml[1] / ml[0]) ** 2)
    c = 2.0 * zeta * math.sqrt(max(k * ml[0], 0.0))
    est = {
        "f_res": Estimate(f_res, fit.value_std, "Hz"),
        "damping_ratio": Estimate(zeta, None, ""),
        "M_load": Estimate(*ml, "kg"),
        "load_fraction": Estimate(frac, ml[1] / M if M > 0 else None, ""),
        "stiffness": Estimate(k, k_std, "N/m"),
        "damping": Estimate(c, None, "N·s/m"),
    }
    plant = {"stiffness": k, "damping": c, "load_fraction": frac} if 0 < frac < 1 else None
    return est, plant, "" if plant else "the load fraction is outside (0, 1): not a plant flexibility"


def _flex_scan_value(values: Mapping[str, float], M: float) -> tuple[float, float]:
    ml = values["load_fraction"] * M
    k = values["stiffness"]
    return math.sqrt(k / ml) / (2 * math.pi), values["damping"] / (2.0 * math.sqrt(k * ml))


def _ripple_build(kin: Kinematics, period: Any, fs_hz: float) -> np.ndarray:
    if kin.q is None:
        raise ValueError("the ripple columns need the position q")
    return np.c_[np.sin(2.0 * np.pi * kin.q / period), np.cos(2.0 * np.pi * kin.q / period)]


def _flex_build(kin: Kinematics, value: Any, fs_hz: float) -> np.ndarray:
    scalar = bool(np.isscalar(value))  # a bool: np.isscalar's TypeGuard would narrow value to types float() does not take
    f_hz, zeta = (value, FLEX_DAMPING) if scalar else value
    return np.c_[flexible_acceleration(kin.qdd, float(f_hz), fs_hz, float(zeta)) - kin.qdd]


def _delay_check(v: Mapping[str, float]) -> None:
    if abs(v["delay"]) > MAX_DELAY_S:
        raise ParameterError("delay.delay", v["delay"], f"within +-{MAX_DELAY_S:g} s")


MAX_DELAY_S = 1.0
"""Largest delay (s) either way."""

ASYMMETRIC_FRICTION = register(
    Effect(
        "asymmetric_friction",
        "asymmetric friction",
        "Friction differs between the two directions of motion, e.g. from wear or fatigue of the screw on one side.",
        params=(
            PlantParam("Fv_pos", "N·s/m", 166.7061, "viscous friction, positive velocity"),
            PlantParam("Fv_neg", "N·s/m", 240.4236, "viscous friction, negative velocity"),
            PlantParam("Fc_pos", "N", 20.1440, "Coulomb friction, positive velocity", low=0.0),
            PlantParam("Fc_neg", "N", 20.6277, "Coulomb friction, negative velocity (a magnitude)", low=0.0),
        ),
        form="extra viscous coefficient for negative velocity: dFv * qd * (1 - sign(qd))/2 (Coulomb asymmetry is the constant offset)",
        signature="residual proportional to velocity on one side of zero only; mean residual differs between positive and negative velocity bins",
        signature_kinds=("velocity",),
        columns=(_col("dFv_neg", "extra viscous friction at negative velocity", "N·s/m"),),
        build=lambda kin, value, fs_hz: np.c_[kin.qd * negative_side(kin)],
        estimate=_asym_estimate,
        sentence=lambda p: f"viscous friction {p['Fv_pos'].value:.0f} N·s/m forward, {p['Fv_neg'].value:.0f} backward",
    )
)

STRIBECK = register(
    Effect(
        "stribeck",
        "Stribeck friction",
        "At low sliding speed the lubricant film breaks down and friction rises above its Coulomb level before it drops with speed.",
        params=(
            PlantParam("Fs", "N", 5.0, "static friction in excess of Coulomb (negative: lower at low speed)"),
            PlantParam("vs", "m/s", 0.01, "Stribeck velocity", low=0.0, low_open=True),
        ),
        force=lambda q, qd, prm: prm[0] * np.exp(-((qd / prm[1]) ** 2)) * np.sign(qd),
        form="Fs * sign(qd) * exp(-(qd/vs)^2), vs searched",
        signature="residual with the sign of the velocity, concentrated in the low-speed bins and at velocity reversals",
        signature_kinds=("velocity", "reversal"),
        columns=(_col("Fs", "static friction in excess of Coulomb", "N"),),
        build=lambda kin, vs, fs_hz: np.c_[kin.sgn * np.exp(-((kin.qd / vs) ** 2))],
        scan=Scan("vs", "m/s", _stribeck_grid),
        estimate=_stribeck_estimate,
        sentence=_stribeck_sentence,
        # Stribeck friction rises above Coulomb at low speed; a fit that falls below it
        # is another mechanism (pre-sliding, smoothed or stuck Coulomb friction at a
        # dwell), which the catalogue does not model, and is not named Stribeck
        impossible=lambda th, v: (
            None
            if th[0] > 0
            else f"static friction below Coulomb (Fs = {th[0]:.3g} N) is not Stribeck friction (pre-sliding or stuck Coulomb friction: outside the catalogue)"
        ),
        strategy="dwell_segments",  # the closed loop proposes it at a reference's dwells, the open-loop segments refit it
    )
)

POSITION_RIPPLE = register(
    Effect(
        "position_ripple",
        "position-dependent force ripple",
        "Cogging of the motor and the screw pitch make the force needed to move vary periodically with position.",
        params=(
            PlantParam("A", "N", 2.0, "amplitude"),
            PlantParam("L", "m", 0.01, "spatial period", low=0.0, low_open=True),
            PlantParam("phase", "rad", 0.0, "phase"),
        ),
        force=lambda q, qd, prm: prm[0] * np.sin(2.0 * np.pi * q / prm[1] + prm[2]),
        form="A * sin(2 pi q / P) + B * cos(2 pi q / P), spatial period P searched",
        signature="residual periodic in position: a peak in the residual against position, at frequency velocity/P in time",
        signature_kinds=("position", "frequency"),
        columns=(_col("ripple_sin", "ripple, sine component", "N"), _col("ripple_cos", "ripple, cosine component", "N")),
        build=_ripple_build,
        scan=Scan("L", "m", _ripple_grid),
        estimate=_ripple_estimate,
        sentence=lambda p: f"amplitude {p['A'].value:.3g} N, spatial period {p['L'].value * 1e3:.4g} mm",
    )
)

SPRING = register(
    Effect(
        "spring",
        "spring force",
        "A cable chain or a gravity-like preload pulls the carriage towards one end with a force proportional to position.",
        params=(PlantParam("k", "N/m", 100.0, "stiffness"), PlantParam("q0", "m", 0.1, "rest position")),
        force=lambda q, qd, prm: prm[0] * (q - prm[1]),
        form="k * q (its rest position is absorbed by the offset)",
        signature="residual growing linearly with position, same sign in both directions of motion",
        signature_kinds=("position",),
        columns=(_col("k_spring", "stiffness", "N/m"),),
        build=lambda kin, value, fs_hz: np.c_[kin.q],
        estimate=_spring_estimate,
        sentence=lambda p: f"stiffness {p['k'].value:.4g} N/m",
    )
)


def _gravity_sentence(p: Mapping[str, Estimate]) -> str:
    mx, my = p["MX"].value, p["MY"].value
    peak = STANDARD_GRAVITY * math.hypot(mx, my)
    return (
        f"first moments MX = {mx:.4g} kg·m, MY = {my:.4g} kg·m: a gravity torque of up to {peak:.4g} N·m, "
        f"largest at q = {math.atan2(-my, mx):+.3g} rad from the joint's zero"
    )


GRAVITY = register(
    Effect(
        "gravity",
        "gravity",
        "The link's weight acts at its centre of mass, off the joint's axis: a torque that varies with the angle as the cosine of the arm's "
        "angle to the horizontal (paper eq. 3, the first moments MX, MY).",
        params=(
            PlantParam("MX", "kg·m", 0.05, parameters.FIRST_MOMENTS["MX"].meaning),
            PlantParam("MY", "kg·m", 0.0, parameters.FIRST_MOMENTS["MY"].meaning),
        ),
        force=lambda q, qd, prm: STANDARD_GRAVITY * (prm[0] * np.cos(q) - prm[1] * np.sin(q)),
        form="g * (MX * cos q - MY * sin q), q from the joint's zero as given (revolute joint)",
        signature="residual periodic in the angle with one cycle per turn, same sign in both directions of motion",
        signature_kinds=("position",),
        columns=tuple(EffectColumn(c.name, c.unit, c.description) for c in GRAVITY_COLUMNS.values()),
        build=lambda kin, value, fs_hz: np.column_stack([c.build(kin) for c in GRAVITY_COLUMNS.values()]),
        sentence=_gravity_sentence,
        joints=("revolute",),
    )
)

PAYLOAD_CHANGE = register(
    Effect(
        "payload_change",
        "payload change",
        "A mass is added to (or removed from) the carriage during the run, changing the inertia from that time on.",
        params=(PlantParam("dM", "kg", 10.0, "mass added"), PlantParam("t_change", "s", 60.0, "time of the change", low=0.0)),
        form="dM * qdd * [t >= tc], change time tc searched",
        signature="residual proportional to acceleration, after a given time only",
        signature_kinds=("drift", "time"),
        columns=(_col("dM", "mass added at the change time", "kg"),),
        build=lambda kin, tc, fs_hz: np.c_[kin.qdd * (kin.t >= tc)],
        scan=Scan("t_change", "s", _change_time_grid, log=False),
        sentence=lambda p: f"{p['dM'].value:+.3g} kg from t = {p['t_change'].value:.3g} s",
    )
)


def drift_of(t: Any, change: float, tau: float, rate: float) -> Any:
    """Change of a friction coefficient at ``t`` (s, the log's time, as ``payload_change``'s ``t_change``).

    A warm-up ``change * (1 - exp(-t/tau))`` plus a wear ``rate * t``.

    NumPy operations only (arrays or floats); the plant's compiled loop has its own form, checked against this one by the tests.
    """
    return change * (1.0 - np.exp(-t / tau)) + rate * t


def _drift_sentence(p: Mapping[str, Estimate]) -> str:
    """``Fv -33 % from 200 (exponential, time constant 6 s)`` per drifting coefficient (:mod:`ilic_cli.diagnosis.drift`'s estimates)."""
    parts = []
    for key, est in p.items():
        if not key.endswith("_relative_change"):
            continue
        name = key[: -len("_relative_change")]
        start = p.get(f"{name}_start")
        what = f"{name} {est.value * 100:+.3g} %" + ("" if start is None else f" from {start.value:.4g}")
        if f"{name}_tau" in p:
            what += f" (exponential, time constant {p[f'{name}_tau'].value:.3g} s)"
        elif f"{name}_rate" in p:
            what += f" (linear, {p[f'{name}_rate'].value:+.3g} per s)"
        parts.append(what)
    return "; ".join(parts)


FRICTION_DRIFT = register(
    Effect(
        "friction_drift",
        "friction drift",
        "Friction changes during the run: it falls as the lubricant warms up (an exponential approach to its warm level) "
        "or changes steadily with wear (a linear trend).",
        params=(
            PlantParam("dFv", "N·s/m", -50.0, "change of viscous friction at the end of the warm-up (exponential)"),
            PlantParam("dFc", "N", 0.0, "change of Coulomb friction at the end of the warm-up (exponential)"),
            PlantParam("tau", "s", 10.0, "time constant of the warm-up", low=0.0, low_open=True),
            PlantParam("Fv_rate", "N·s/m/s", 0.0, "linear change of viscous friction per second (wear)"),
            PlantParam("Fc_rate", "N/s", 0.0, "linear change of Coulomb friction per second (wear)"),
        ),
        form="Fv(t) = Fv + dFv (1 - exp(-t/tau)) + Fv_rate t, Fc(t) likewise (Coulomb level kept >= 0), t the log's time",
        signature="the friction estimated on successive time windows follows a trend (exponential or linear) across the windows",
        signature_kinds=("drift", "time"),
        sentence=_drift_sentence,
    )
)

OFFSET = register(
    Effect(
        "offset",
        "force offset",
        "The drive's amplifier or current sensor adds a constant force, or Coulomb friction is not the same in both directions.",
        plant=False,
        form="constant offset",
        signature="constant mean residual in every bin",
        signature_kinds=("velocity", "time"),
        columns=(_col("offset", "constant force offset"),),
        build=lambda kin, value, fs_hz: np.ones((len(kin.qd), 1)),
        sentence=lambda p: f"{p['offset'].value:+.3g} N",
    )
)

DELAY = register(
    Effect(
        "delay",
        "actuation delay",
        "The logged force and the force acting on the axis are not simultaneous: the measurement lags (d > 0) or the drive lags the command (d < 0).",
        params=(PlantParam("delay", "s", 0.002, "logged force = applied force this much earlier; negative: the drive lags the command"),),
        check=_delay_check,
        form="IDM(t) = tau_logged(t + d): the logged force is shifted by the delay d, searched",
        signature="residual proportional to the rate of change of the force; cross-correlation of force and model peaks at a non-zero lag",
        signature_kinds=("lag", "acceleration"),
        scan=Scan("delay", "s", _delay_grid, log=False),
        shift=True,
        estimate=_delay_estimate,
        realise=_delay_realise,
        sentence=lambda p: f"{p['delay'].value * 1e3:+.3g} ms",
    )
)


def _flex_check(v: Mapping[str, float]) -> None:
    if not 0.0 < v["load_fraction"] < 1.0:
        raise ParameterError("flexibility.load_fraction", v["load_fraction"], "in (0, 1)")


FLEXIBILITY = register(
    Effect(
        "flexibility",
        "transmission flexibility",
        "The carriage is coupled to the motor through a compliant screw and belt, so part of the mass lags the measured motion near a resonance.",
        params=(
            PlantParam("stiffness", "N/m", 2.0e6, "coupling stiffness", low=0.0, low_open=True),
            PlantParam("damping", "N·s/m", 500.0, "coupling damping", low=0.0),
            PlantParam("load_fraction", "", 0.3, "share of M behind the coupling"),
        ),
        check=_flex_check,
        form="M_load * (H(s) - 1) qdd with H the load's spring-damper response: resonance frequency f_res searched, then its damping ratio",
        signature="residual proportional to acceleration at high frequency: oscillations after acceleration steps and pulses; a spectral peak",
        signature_kinds=("frequency", "acceleration"),
        columns=(_col("M_load", "mass behind the flexibility", "kg"),),
        build=_flex_build,
        scan=Scan("f_res", "Hz", _resonance_grid, secondary=("damping_ratio", "", 0.005, 0.5, FLEX_DAMPING)),
        impossible=lambda th, v: None if th[0] > 0 else f"negative mass behind the flexibility ({th[0]:.3g} kg)",
        estimate=_flex_estimate,
        scan_value=_flex_scan_value,
        sentence=lambda p: f"resonance {p['f_res'].value:.3g} Hz, {p['M_load'].value:.3g} kg behind the spring",
    )
)

SATURATION = register(
    Effect(
        "saturation",
        "drive saturation",
        "The drive cannot apply more than its peak force: the applied force is clipped.",
        params=(PlantParam("force_max", "N", 350.0, "largest force the drive applies", low=0.0, low_open=True),),
    )
)

QUANTIZATION = register(
    Effect(
        "quantization",
        "encoder quantization",
        "The encoder measures the position in whole counts (EMPS: about 2e-7 m per count).",
        params=(PlantParam("resolution", "m", 2.0e-7, "one count", low=0.0, low_open=True),),
    )
)

NOISE = register(
    Effect(
        "noise",
        "measurement noise",
        "Gaussian noise on the logged force and on the measured position (seeded, drawn up front).",
        params=(PlantParam("tau_std", "N", 0.0, "force noise std", low=0.0), PlantParam("q_std", "m", 0.0, "position noise std", low=0.0)),
    )
)

DISTURBANCE = register(
    Effect(
        "disturbance",
        "band-limited force disturbance",
        "An unmodelled force acts on the axis (cable drag, vibration of the frame): white noise through a low-pass filter, seeded, not in the logged force.",
        params=(
            PlantParam("std", "N", 2.0, "standard deviation of the force", low=0.0),
            PlantParam("bandwidth_hz", "Hz", 20.0, "corner (-3 dB) frequency of its second-order Butterworth low-pass", low=0.0, low_open=True),
        ),
    )
)

CURRENT_LOOP = register(
    Effect(
        "current_loop",
        "current-loop lag",
        "The drive's current loop makes the applied force follow the command as a first-order lag of time constant 1/(2 pi f), "
        "f its bandwidth (about 700 Hz: 0.23 ms); an inverse model sees it as a drive lag of that size.",
        params=(PlantParam("bandwidth_hz", "Hz", 700.0, "closed-loop bandwidth f of the current loop", low=0.0, low_open=True),),
    )
)
