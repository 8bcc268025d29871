"""``ilic identify`` logic: the methods of the registry (:mod:`ilic_cli.methods`) on one prepared log, then validation.

Takes a :class:`~ilic_cli.runlog.RunLog`, returns an :class:`IdentifyReport`, a list of fits
(:class:`ilic_cli.estimators.base.Fit`; no file I/O here); renderers live in :mod:`ilic_cli.identify_report` and
plots in :mod:`ilic_cli.plotting`. The closed-loop methods are handed the plant's loop simulation
(:data:`ilic_cli.simulation.loop.PLANT_LOOP`) here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.closed_loop_id import ClosedLoopResult, ClosedLoopSettings, plant_of, relative_errors, require_closed_loop
from ilic_cli.drive_lag import DriveLag, drive_lag, lag_rows
from ilic_cli.effects import unit_of, unit_on
from ilic_cli.errors import IdentificationError, IlicError, ParameterError
from ilic_cli.estimators.base import Fit, LoopSimulator, ModelSpec, states_lag, with_effects
from ilic_cli.estimators.closed_loop import ClosedLoopFitSettings
from ilic_cli.estimators.inverse import TRACKING_LIMIT, ilic_unusable
from ilic_cli.estimators.output import OutputErrorFitSettings, inverse_model_error
from ilic_cli.filtering import kept_indices
from ilic_cli.friction_shape import FrictionShape, shape_of
from ilic_cli.idim_ilic import ILICResult, ILICSettings
from ilic_cli.idim_ls import IDIMLSResult, LSSettings, cross_validate, decimated_systems
from ilic_cli.lsq import LSResult
from ilic_cli.methods import CHOICES, METHODS, effect_methods, label, methods_of, model_method
from ilic_cli.output_error import OEResult, OESettings
from ilic_cli.plausible import opposed_force
from ilic_cli.prepare import PreparedLog, prepare_log
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.loop import PLANT_LOOP
from ilic_cli.simulation.pd_law import follows_the_law_on_the_state, inside_is_closer
from ilic_cli.usable import UNKNOWN_FORCE_TIMING, UsableRows, force_timing_unknown, identification_hold_s, identification_speed_noise, usable_rows, with_rest

if TYPE_CHECKING:
    from ilic_cli.simulation.timing import ControlTiming

__all__ = ["IDENTIFY_METHODS", "TRACKING_LIMIT", "IdentifyReport", "Validation", "identify", "ilic_unusable", "with_effects"]

IDENTIFY_METHODS = CHOICES
"""Values of ``identify(method=...)`` (:data:`ilic_cli.methods.CHOICES`)."""


@dataclass(frozen=True)
class Validation:
    """Estimates of one log applied to another (cross-test validation)."""

    source: str
    method: str
    result: LSResult | None
    open_loop: dict[str, Any] | None = None
    """OE / CLOE runs: the benchmark's open-loop figure of these estimates on the log (:class:`plant.replay.BenchmarkFigure`)."""

    def to_dict(self) -> dict[str, Any]:
        d = {} if self.result is None else self.result.to_dict()
        d.pop("parameters", None)
        return {"source": self.source, "method": self.method, **d, "open_loop": self.open_loop}


@dataclass
class IdentifyReport:
    """Everything ``ilic identify`` found on one log: the fits of the methods asked for, in the registry's order."""

    source: str
    model: str
    fs_hz: float
    samples: int
    fits: list[Fit] = field(default_factory=list)
    """One per method run (:data:`ilic_cli.methods.METHODS` order)."""
    validation: list[Validation] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    effects: dict[str, Any] = field(default_factory=dict)
    """Effects identified as regressor columns: id -> nonlinear value (``None`` for a linear one)."""
    joint: str | None = None
    """The joint's name, when the log names it."""
    joint_type: str = "prismatic"
    """``prismatic`` or ``revolute`` (from the position's unit): the parameters' units."""
    method: str = "both"
    """The ``method`` asked for: :func:`ilic_cli.methods.model_method` names the fit the model file takes (:meth:`model_fit`)."""
    timing: ControlTiming | None = None
    """The PD loop's timing read from the recording for the closed-loop methods, if read."""
    usable: UsableRows | None = None
    """The rows every method fits and the rule for samples at rest (:func:`ilic_cli.usable.with_rest`)."""
    drive_lag: DriveLag | None = None
    """The drive's lag estimated on the log (:func:`ilic_cli.drive_lag.drive_lag`; ``None``: not sought, :func:`_drive_lag`)."""
    friction_shape: FrictionShape | None = None
    """How far IDIM-LS's Fv and Fc rest on the sign in the Coulomb column (:func:`ilic_cli.friction_shape.shape_of`; ``None``: not asked)."""

    def fit(self, name: str) -> Fit | None:
        """The fit of method ``name`` (``ls``, ``ilic``, ...), if run."""
        return next((f for f in self.fits if f.name == name), None)

    def result(self, name: str) -> Any:
        """The method's own result (:attr:`Fit.detail`) of method ``name``, if run."""
        f = self.fit(name)
        return None if f is None else f.detail

    # the methods' own results, by name: views over :attr:`fits` for the renderers and callers
    @property
    def ls(self) -> IDIMLSResult | None:
        return self.result("ls")

    @property
    def ilic(self) -> ILICResult | None:
        return self.result("ilic")

    @property
    def didim(self) -> ClosedLoopResult | None:
        return self.result("didim")

    @property
    def iv(self) -> ClosedLoopResult | None:
        return self.result("iv")

    @property
    def oe(self) -> OEResult | None:
        return self.result("oe")

    @property
    def cloe(self) -> OEResult | None:
        return self.result("cloe")

    def closed_loop(self) -> list[ClosedLoopResult]:
        """The results of the closed-loop methods that iterate on the inverse model (DIDIM, IDIM-IV), in the registry's order."""
        return [f.detail for f in self.fits if METHODS[f.name].closed_loop and not METHODS[f.name].output_error]

    def output_errors(self) -> list[OEResult]:
        """The output-error results (OE, CLOE) that were run."""
        return [f.detail for f in self.fits if METHODS[f.name].output_error]

    def model_fit(self) -> Fit | None:
        """The fit whose estimate the model file takes: the asked method's (a composite's choice), else IDIM-LS's."""
        return self.fit(model_method(self.method)) or self.fit("ls")

    def output_error(self) -> OEResult | None:
        """The OE or CLOE estimate the model file takes (``method`` ``oe`` / ``cloe``), if run."""
        f = self.model_fit()
        return f.detail if f is not None and METHODS[f.name].output_error else None

    def model_method(self) -> str:
        """The name of the method whose estimate the model file takes."""
        f = self.model_fit()
        return f.method if f is not None else label("ilic")

    def unit(self, name: str) -> str:
        """The unit of parameter ``name`` on this log's joint (a revolute joint's N·m where a prismatic one has N)."""
        return unit_of(name, self.joint_type)

    def to_dict(self) -> dict[str, Any]:
        first = self.fits[0].names if self.fits else ()
        return {
            "source": self.source,
            "model": self.model,
            "joint": self.joint,
            "joint_type": self.joint_type,
            "units": {n: self.unit(n) for n in first},
            "effects": {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.effects.items()},
            "sample_rate_hz": self.fs_hz,
            "samples": self.samples,
            **{name: (None if (f := self.fit(name)) is None else f.detail.to_dict()) for name in METHODS},
            "validation": [v.to_dict() for v in self.validation],
            "loop_timing": None if self.timing is None else self.timing.to_dict(),
            "usable_rows": None if self.usable is None else self.usable.to_dict(),
            "drive_lag": None if self.drive_lag is None else self.drive_lag.to_dict(),
            "friction_shape": None if self.friction_shape is None else self.friction_shape.to_dict(),
            "warnings": list(self.warnings),
        }

    def to_frame(self) -> Any:
        """Tidy table: one row per method, window and parameter (``k``: the window, or an iterative method's iterations)."""
        import pandas as pd  # deferred: pandas is slow to import and only tables need it

        rows: list[dict[str, Any]] = []
        for f in self.fits:  # one estimate on the whole log (k: a closed-loop or output-error method's iterations)
            if f.name == "ilic":
                continue
            for n, v, s, p in zip(f.names, f.theta, f.std, f.rel_std_pct, strict=True):
                rows.append(_row(f.method, f.diagnostics.get("iterations"), None, None, n, v, s, p, None, f.relative_error_pct, None))
        if self.ilic is not None:
            for w in self.ilic.windows:
                r = w.result
                for n, v, s, p, e in zip(r.names, r.theta, r.std, r.rel_std_pct, w.essential, strict=True):
                    rows.append(_row("IDIM-ILIC", w.k, w.t_start, w.t_end, n, v, s, p, bool(e), r.relative_error_pct, w.tracking_error_ratio))
        return pd.DataFrame(rows)

    def model_parameters(self) -> dict[str, float]:
        """Rigid parameters for a model file: the :meth:`model_fit`'s plant when run, else the last window's essential estimates."""
        f = self.model_fit()
        if f is not None and f.plant is not None:
            return f.plant[0]
        if self.ilic is not None and self.ilic.windows:
            w = self.ilic.windows[-1]
            return {n: float(v) for n, v, e in zip(w.result.names, w.result.theta, w.essential, strict=True) if e}
        return {}

    def model_effects(self) -> dict[str, dict[str, float]]:
        """Plant effects of the :meth:`model_fit`, for a model file (:func:`ilic_cli.closed_loop_id.plant_of`)."""
        f = self.model_fit()
        return {} if f is None or f.plant is None else f.plant[1]


def _row(method: str, k: Any, t0: Any, t1: Any, n: str, v: float, s: float, p: float, essential: Any, rel: Any, track: Any) -> dict[str, Any]:
    return {
        "method": method,
        "k": k,
        "t_start": t0,
        "t_end": t1,
        "parameter": n,
        "value": v,
        "std": s,
        "rel_std_pct": p,
        "essential": essential,
        "relative_error_pct": rel,
        "tracking_error_ratio": track,
    }


def _masked_summary(report: IdentifyReport, valid: np.ndarray, saturation_note: str) -> str:
    parts = [saturation_note]
    if report.ls is not None:
        rows = report.ls.result.rows
        total = len(kept_indices(len(valid) - report.ls.settings.trim, report.ls.settings.decimation))
        parts.append(f"IDIM-LS uses {rows} of {total} decimated rows ({100.0 * (total - rows) / total:.3g} % masked)")
    if report.ilic is not None and report.ilic.windows:
        touched = sum(1 for w in report.ilic.windows if w.masked_fraction > 0)
        parts.append(f"IDIM-ILIC rows masked in {touched} of {len(report.ilic.windows)} window(s)")
    return "; ".join(parts)


@dataclass(frozen=True)
class IdentifySettings:
    """What ``identify`` runs and how: the ``--method`` value, the model, each method's settings, the PD loop's timing."""

    method: str = "both"
    model: ModelSpec = ModelSpec()
    ls: LSSettings = LSSettings()
    ilic: ILICSettings = ILICSettings()
    closed_loop: Mapping[str, ClosedLoopSettings] | None = None
    """``didim``/``iv`` -> iteration settings (default: each method's own, :data:`ilic_cli.closed_loop_id.DEFAULT_SETTINGS`)."""
    pd_timing: str = "recorded"
    oe: OESettings = OESettings()

    def check(self) -> None:
        """Refuse a method, a model or a timing ``identify`` does not run (before any work)."""
        if self.method not in CHOICES:
            raise ParameterError("method", self.method, f"one of {', '.join(CHOICES)}")
        if self.model.effects and not all(METHODS[m].takes_effects for m in methods_of(self.method)):
            raise ParameterError("method", self.method, f"{effect_methods()} with effect columns (IDIM-ILIC windows identify the structure's own parameters)")
        if self.pd_timing not in parameters.PD_TIMINGS:
            raise ParameterError("pd_timing", self.pd_timing, f"one of {', '.join(parameters.PD_TIMINGS)}")

    def of(self, name: str, start: np.ndarray | None) -> Any:
        """The settings method ``name``'s ``fit`` takes, its start the IDIM-LS estimate ``start``."""
        begin = None if start is None else tuple(float(x) for x in start)
        kind = METHODS[name].settings
        if kind is OutputErrorFitSettings:
            return OutputErrorFitSettings(self.oe, self.ls, begin)
        if kind is ClosedLoopFitSettings:
            return ClosedLoopFitSettings((self.closed_loop or {}).get(name), self.ls, begin)
        return {LSSettings: self.ls, ILICSettings: self.ilic}[kind]


def identify(
    log: RunLog,
    *,
    method: str = "both",
    structure: str = "rigid-offset",
    effects: dict[str, Any] | None = None,
    ls_settings: LSSettings = LSSettings(),
    ilic_settings: ILICSettings = ILICSettings(),
    validate: list[RunLog] | None = None,
    closed_loop_settings: Mapping[str, ClosedLoopSettings] | None = None,
    pd_timing: str = "recorded",
    oe_settings: OESettings = OESettings(),
    loop: LoopSimulator = PLANT_LOOP,
) -> IdentifyReport:
    """Run the methods ``method`` names (:mod:`ilic_cli.methods`) on ``log`` and validate on other logs.

    Parameters
    ----------
    log : RunLog
        Needs ``t``, ``q``, ``tau``; IDIM-ILIC also needs ``q_ref``
        (``qd_ref``/``qdd_ref`` are derived from it when absent).
    method : {"ls", "ilic", "both", "didim", "iv", "all", "oe", "cloe"}
        :data:`ilic_cli.methods.CHOICES`. ``both``: IDIM-LS and IDIM-ILIC; ``didim``, ``iv``: DIDIM or IDIM-IV
        (:mod:`ilic_cli.closed_loop_id`) started from IDIM-LS, which is
        reported beside them; ``all``: every method (IDIM-ILIC when usable);
        ``oe``, ``cloe``: open- or closed-loop output error from IDIM-LS
        (:mod:`ilic_cli.output_error`), with the benchmark's open-loop
        figure on each validation log.
    structure : {"rigid", "rigid-offset", "asymmetric"}
    effects : dict, optional
        Effects identified with the structure as further regressor columns
        (IDIM-LS, DIDIM, IDIM-IV, OE, CLOE): effect id -> its nonlinear value, ``None`` for a
        linear effect (:mod:`ilic_cli.effects`).
    validate : list of RunLog
        Logs to apply the estimates to (same processing).
    closed_loop_settings : dict, optional
        ``didim``/``iv`` -> iteration settings (default: each method's own,
        :data:`ilic_cli.closed_loop_id.DEFAULT_SETTINGS`).
    pd_timing : {"recorded", "documented"}
        How the closed-loop methods' replays time a PD log's command: as read from
        the recording with the IDIM-LS estimate
        (:func:`ilic_cli.simulation.timing.recorded_loop`), or as the log's
        metadata states it.
    loop : LoopSimulator
        The loop simulation handed to the closed-loop methods (default the plant's).
    """
    settings = IdentifySettings(method, ModelSpec(structure, dict(effects or {})), ls_settings, ilic_settings, closed_loop_settings, pd_timing, oe_settings)
    return identify_with(log, settings, validate=validate, loop=loop)


def identify_with(log: RunLog, settings: IdentifySettings, *, validate: list[RunLog] | None = None, loop: LoopSimulator = PLANT_LOOP) -> IdentifyReport:
    """:func:`identify` with its settings in one object (:class:`IdentifySettings`)."""
    prepared = prepare_log(log)
    settings = replace(settings, ls=settings.ls.at_rate(prepared.fs_hz))  # the decimation of the log's rate, for every method
    prepared = with_rest(prepared, settings.ls)  # the samples every method fits (no saturated drive, no standstill)
    log = prepared.log  # an irregularly sampled log is on a uniform grid now
    spec = settings.model
    model = spec.regressor(prepared.fs_hz)
    settings.check()
    runs = methods_of(settings.method)
    report = IdentifyReport(
        source=prepared.source,
        model=spec.structure,
        fs_hz=prepared.fs_hz,
        samples=len(log),
        warnings=list(prepared.warnings),
        effects=dict(spec.effects),
        joint=log.sensor.joint,
        joint_type=log.sensor.joint_type,
        method=settings.method,
        usable=usable_rows(prepared, settings.ls),
    )
    if force_timing_unknown(prepared):
        report.warnings.append(UNKNOWN_FORCE_TIMING)
    if settings.pd_timing == "recorded" and (inside := _law_inside(prepared, settings, loop)) is not None:  # before the hold is used
        prepared, log = inside, inside.log
        report.usable = usable_rows(prepared, settings.ls)
        report.warnings.append(f"loop: {LAW_INSIDE}")
    closed = [label(m) for m in runs if METHODS[m].closed_loop]
    report.drive_lag = _drive_lag(prepared, spec, model, settings.ls) if "ls" in runs else None
    if report.drive_lag is not None and report.drive_lag.applied:  # the model's lag from here, as if stated: every fit, replay, validation
        settings = replace(settings, model=replace(spec, effects={**spec.effects, "delay": -report.drive_lag.value_s}))
    if closed:  # refuse before any work
        require_closed_loop(log, prepared.source, " and ".join(closed))
    for m in runs:
        if METHODS[m].output_error:
            prepared.require_contiguous(label(m))
    _run_fits(report, prepared, runs, settings, loop)
    if (ls := report.ls) is not None and ls.robust is not None:
        report.friction_shape = shape_of(prepared, settings.model.regressor(prepared.fs_hz), ls.settings, ls.hold_s, ls.robust.std)
        if report.friction_shape is not None and report.friction_shape.material:
            report.warnings.append(report.friction_shape.warning(unit_on("m/s", report.joint_type), {n: report.unit(n) for n in ("Fv", "Fc")}))
    report.fits.sort(key=lambda f: list(METHODS).index(f.name))
    if prepared.saturated is not None:
        report.warnings.append(_masked_summary(report, prepared.saturated, str(prepared.saturation_note())))
    _validate(report, model, validate or [], settings)
    return report


def _drive_lag(prepared: PreparedLog, spec: ModelSpec, model: Model, ls: LSSettings) -> DriveLag | None:
    """The drive's lag estimated on ``prepared`` (:data:`ilic_cli.drive_lag.LAG_RULE`) where IDIM-LS's regressor is evaluated half
    a period late for the drive's held command (rows at rest left out: :func:`identification_hold_s`) and the model states no lag
    (:func:`states_lag`; ``model``: its regressor); ``None`` elsewhere: a log without standstill keeps the published procedure."""
    hold = identification_hold_s(prepared)
    if hold == 0.0 or states_lag(spec.effects):
        return None
    log, fs = prepared.log, prepared.fs_hz
    ls = lag_rows(ls, fs)
    v, seg, noise = prepared.valid, prepared.segments, identification_speed_noise(prepared)
    try:
        return drive_lag(lambda lag: decimated_systems(log.t, log["q"], log["tau"], fs, model, ls, v, seg, hold + lag, noise)[:2], 1.0 / fs)
    except ValueError as exc:  # as IDIM-LS's own fit says it (estimators.inverse.IDIMLS.run)
        raise IdentificationError(prepared.source, str(exc)) from None


LAW_INSIDE = (
    "the recorded command follows the PD law on the plant's velocity at its sample, and the law inside the dynamics (on the state at "
    "every integration step, as a solver's right-hand side) replays the recording clearly closer than the law held over the period: "
    "every fit takes the force at a sample as the force there, not a command held half a period"
)
"""What ``identify`` says when it reads a PD law inside the dynamics (:func:`_law_inside`)."""


def _law_inside(prepared: PreparedLog, settings: IdentifySettings, loop: LoopSimulator) -> PreparedLog | None:
    """``prepared`` with its PD law inside the dynamics when the recording says so (:func:`ilic_cli.simulation.pd_law.inside_is_closer`:
    IDIM-LS fitted under each hypothesis's hold, each replayed with its own loop), else ``None``; a log whose command does not follow
    the law on the plant's velocity at its sample is not asked (no replay)."""
    if not follows_the_law_on_the_state(prepared.log):  # read without a replay: most logs stop here, the plant not imported
        return None
    from ilic_cli.simulation.timing import with_pd_law  # deferred: the plant pulls in numba

    ls, spec = METHODS["ls"].bind(loop), settings.model
    errors = []
    hypotheses = [replace(prepared, log=with_pd_law(prepared.log, continuous)) for continuous in (False, True)]
    for p in hypotheses:
        fit = ls.fit(p, spec, settings.of("ls", None))
        try:
            errors.append(relative_errors(p.log, loop.replay(p.log, *plant_of(fit.names, fit.theta, spec.effects)), settings.ls))
        except IlicError:  # a fit that does not replay: the held law stays
            return None
    return hypotheses[1] if inside_is_closer(*errors) else None


def _run_fits(report: IdentifyReport, prepared: PreparedLog, runs: tuple[str, ...], settings: IdentifySettings, loop: LoopSimulator) -> None:
    """Each method of ``runs`` in turn, IDIM-LS first (the others' start), each fit's warnings after it."""
    start: np.ndarray | None = None
    timed = prepared
    for m in runs:
        entry = METHODS[m]
        if entry.closed_loop and timed is prepared and settings.pd_timing == "recorded":  # the loop that ran, its timing read with the IDIM-LS start
            timed = _recorded_timing(report, prepared, settings)
        if m == "ilic" and len(runs) > 1:
            reason = ilic_unusable(prepared.log, prepared.fs_hz, settings.ilic)
            if reason is not None:
                only = "IDIM-LS only" if set(runs) == {"ls", "ilic"} else "the other methods only"
                report.warnings.append(f"IDIM-ILIC not run: {reason}; {only}")
                continue
        fit = entry.bind(loop).fit(timed if entry.starts_from_ls else prepared, settings.model, settings.of(m, start))
        report.fits.append(fit)
        report.warnings.extend(fit.warnings)
        if m == "ls":
            start = fit.theta
            assert report.ls is not None
            r = report.ls.result
            if (why := opposed_force(r.names, r.theta, r.std, report.joint_type)) is not None:  # before a method starts from it
                raise IdentificationError(prepared.source, why)


def _recorded_timing(report: IdentifyReport, prepared: PreparedLog, settings: IdentifySettings) -> PreparedLog:
    """The prepared log whose controller carries the timing read from the recording with the IDIM-LS start (:func:`recorded_loop`)."""
    from ilic_cli.simulation.timing import recorded_loop  # deferred: with the replay (the plant pulls in numba)

    assert report.ls is not None  # IDIM-LS runs first
    timed_log, report.timing = recorded_loop(prepared.log, *plant_of(report.ls.result.names, report.ls.result.theta, settings.model.effects), settings.ls)
    sentence = report.timing.sentence() if report.timing is not None else ""
    if sentence:
        report.warnings.append(f"loop timing: {sentence}")
    return replace(prepared, log=timed_log)


def _validate(report: IdentifyReport, model: Any, others: list[RunLog], settings: IdentifySettings) -> None:
    """Each estimate applied to each validation log (the inverse model's errors; with OE / CLOE, the open-loop figure too)."""
    ls_settings, effects = settings.ls, dict(settings.model.effects)
    estimates: list[tuple[str, np.ndarray]] = []  # (method, theta) applied to each validation log
    if report.ls is not None:
        estimates.append((label("ls"), report.ls.result.theta))
    if report.ilic is not None and report.ilic.windows and np.all(np.isfinite(report.ilic.windows[-1].result.theta)):
        estimates.append((f"{label('ilic')} (k={report.ilic.windows[-1].k})", report.ilic.windows[-1].result.theta))
    estimates += [(cl.method, cl.result.theta) for cl in report.closed_loop()]
    plants: dict[str, Any] = {}
    if any(METHODS[m].output_error for m in methods_of(report.method)):  # OE / CLOE runs: each validated estimate's plant, for its open-loop figure
        inverse = {label("ls")} | {cl.method for cl in report.closed_loop()}
        plants = {lbl: plant_of(model.names, theta, effects) for lbl, theta in estimates if lbl in inverse}
    for other in others:
        osrc = str(other.provenance.source or "")
        op = with_rest(prepare_log(other, prefix=f"validation log {osrc}"), ls_settings)
        vlog = op.log  # an irregularly sampled log is on a uniform grid now
        report.warnings.extend(op.warnings)
        if op.saturated is not None:
            report.warnings.append(f"validation log {osrc}: {op.saturation_note()}")
        hold = identification_hold_s(op) + settings.model.lag_s  # the hold, and the drive lag the model states
        noise = identification_speed_noise(op)  # the validation log's own
        for lbl, theta in estimates:
            res = cross_validate(
                theta, vlog.t, vlog["q"], vlog["tau"], op.fs_hz, model, ls_settings, valid=op.valid, segments=op.segments, hold_s=hold, speed_noise=noise
            )
            report.validation.append(Validation(osrc, lbl, res, _open_loop_figure(vlog, plants.get(lbl), settings.oe, report.warnings)))
        for oe in report.output_errors():
            oe_res = inverse_model_error(oe, vlog, op, effects, ls_settings)
            report.validation.append(Validation(osrc, oe.method, oe_res, _open_loop_figure(vlog, oe.plant(), settings.oe, report.warnings)))


def _open_loop_figure(log: RunLog, plant: Any, settings: OESettings, warnings: list[str]) -> dict[str, Any] | None:
    """The benchmark's open-loop figure of ``plant`` on ``log`` (``None`` without a plant, or a log without ``vir`` and a drive gain)."""
    if plant is None:
        return None
    if "vir" not in log or not log.sensor.drive_gain:
        warnings.append(f"validation log {log.provenance.source}: no open-loop figure (it needs the drive command vir and a drive gain)")
        return None
    from plant.replay import simulate_open_loop  # deferred: the plant pulls in numba

    try:
        return simulate_open_loop(log, *plant, init_samples=settings.init_samples, substeps=10)[1].to_dict()
    except IlicError as exc:
        warnings.append(f"validation log {log.provenance.source}: no open-loop figure: {exc.problem}")
        return None
