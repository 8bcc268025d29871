"""``ilic identify`` logic: IDIM-LS and per-window IDIM-ILIC on a run log.

Takes a :class:`~ilic_cli.runlog.RunLog`, returns an :class:`IdentifyReport`
(no file I/O here); renderers live in :mod:`ilic_cli.identify_report` and plots in
:mod:`ilic_cli.plotting`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.closed_loop_id import METHODS as CLOSED_LOOP_METHODS
from ilic_cli.closed_loop_id import ClosedLoopResult, ClosedLoopSettings, closed_loop_identify, plant_of, require_closed_loop
from ilic_cli.effects import get, unit_of
from ilic_cli.errors import IdentificationError, IlicError, ParameterError
from ilic_cli.filtering import kept_indices
from ilic_cli.idim_ilic import ILICResult, ILICSettings, identify_ilic, tracking_error_ratio
from ilic_cli.idim_ls import IDIMLSResult, LSSettings, UsableRows, cross_validate, identification_hold_s, idim_ls, usable_rows, with_rest
from ilic_cli.lsq import LSResult
from ilic_cli.output_error import OEResult, OESettings
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import Column, Model, get_model
from ilic_cli.runlog import RunLog

if TYPE_CHECKING:
    from ilic_cli.simulation.timing import ControlTiming


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
    """Everything ``ilic identify`` found on one log."""

    source: str
    model: str
    fs_hz: float
    samples: int
    ls: IDIMLSResult | None = None
    ilic: ILICResult | None = None
    validation: list[Validation] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    effects: dict[str, Any] = field(default_factory=dict)
    """Effects identified as regressor columns: id -> nonlinear value (``None`` for a linear one)."""
    joint: str | None = None
    """The joint's name, when the log names it."""
    joint_type: str = "prismatic"
    """``prismatic`` or ``revolute`` (from the position's unit): the parameters' units."""
    didim: ClosedLoopResult | None = None
    iv: ClosedLoopResult | None = None
    method: str = "both"
    """The ``method`` asked for: its estimate goes to the model file (:meth:`primary`)."""
    timing: ControlTiming | None = None
    """The PD loop's timing read from the recording for DIDIM / IDIM-IV, if read."""
    usable: UsableRows | None = None
    """The rows every method fits and the rule for samples at rest (:func:`ilic_cli.idim_ls.with_rest`)."""
    oe: OEResult | None = None
    cloe: OEResult | None = None
    """Output-error estimates (:mod:`ilic_cli.output_error`); the model file takes the one asked for."""

    def output_error(self) -> OEResult | None:
        """The OE or CLOE estimate the model file takes (``method`` ``oe`` / ``cloe``), if run."""
        return {"oe": self.oe, "cloe": self.cloe}.get(self.method)

    def model_method(self) -> str:
        """The name of the method whose estimate the model file takes."""
        oe = self.output_error()
        if oe is not None:
            return oe.method
        primary = self.primary()
        return primary[0] if primary is not None else "IDIM-ILIC"

    def closed_loop(self) -> list[ClosedLoopResult]:
        """The DIDIM and IDIM-IV results that were run, in that order."""
        return [r for r in (self.didim, self.iv) if r is not None]

    def primary(self) -> tuple[str, LSResult] | None:
        """The method and estimate a model file takes: DIDIM for ``didim`` and ``all``, IDIM-IV for ``iv``, else IDIM-LS."""
        if self.didim is not None and self.method in ("didim", "all"):
            return self.didim.method, self.didim.result
        if self.iv is not None and self.method == "iv":
            return self.iv.method, self.iv.result
        if self.ls is not None:
            return "IDIM-LS", self.ls.result
        return None

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "model": self.model,
            "joint": self.joint,
            "joint_type": self.joint_type,
            "units": {
                n: parameters.unit(n, self.joint_type) or unit_of(n) for n in (self.ls.result.names if self.ls else self.ilic.names if self.ilic else ())
            },
            "effects": {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.effects.items()},
            "sample_rate_hz": self.fs_hz,
            "samples": self.samples,
            "ls": None if self.ls is None else self.ls.to_dict(),
            "ilic": None if self.ilic is None else self.ilic.to_dict(),
            "didim": None if self.didim is None else self.didim.to_dict(),
            "iv": None if self.iv is None else self.iv.to_dict(),
            "oe": None if self.oe is None else self.oe.to_dict(),
            "cloe": None if self.cloe is None else self.cloe.to_dict(),
            "validation": [v.to_dict() for v in self.validation],
            "loop_timing": None if self.timing is None else self.timing.to_dict(),
            "usable_rows": None if self.usable is None else self.usable.to_dict(),
            "warnings": list(self.warnings),
        }

    def to_frame(self) -> Any:
        """Tidy table: one row per method, window and parameter (``k``: the window, or DIDIM / IDIM-IV's iterations)."""
        import pandas as pd

        rows: list[dict[str, Any]] = []
        whole: list[tuple[str, int | None, LSResult | OEResult]] = []
        whole += ([("IDIM-LS", None, self.ls.result)] if self.ls is not None else []) + [(c.method, c.n_iterations, c.result) for c in self.closed_loop()]
        whole += [(o.method, o.iterations, o) for o in (self.oe, self.cloe) if o is not None]
        for method, k, r in whole:  # one estimate on the whole log (k: a closed-loop or output-error method's iterations)
            rel_err = r.force_error_pct if isinstance(r, OEResult) else r.relative_error_pct
            for n, v, s, p in zip(r.names, r.theta, r.std, r.rel_std_pct, strict=True):
                rows.append(
                    {
                        "method": method,
                        "k": k,
                        "t_start": None,
                        "t_end": None,
                        "parameter": n,
                        "value": v,
                        "std": s,
                        "rel_std_pct": p,
                        "essential": None,
                        "relative_error_pct": rel_err,
                        "tracking_error_ratio": None,
                    }
                )
        if self.ilic is not None:
            for w in self.ilic.windows:
                r = w.result
                for n, v, s, p, e in zip(r.names, r.theta, r.std, r.rel_std_pct, w.essential, strict=True):
                    rows.append(
                        {
                            "method": "IDIM-ILIC",
                            "k": w.k,
                            "t_start": w.t_start,
                            "t_end": w.t_end,
                            "parameter": n,
                            "value": v,
                            "std": s,
                            "rel_std_pct": p,
                            "essential": bool(e),
                            "relative_error_pct": r.relative_error_pct,
                            "tracking_error_ratio": w.tracking_error_ratio,
                        }
                    )
        return pd.DataFrame(rows)

    def model_parameters(self) -> dict[str, float]:
        """Rigid parameters for a model file: the output-error or :meth:`primary` estimate when run, else the last window's essential estimates."""
        oe = self.output_error()
        if oe is not None:
            return oe.plant()[0]
        primary = self.primary()
        if primary is not None:
            return plant_of(primary[1].names, primary[1].theta)[0]
        if self.ilic is not None and self.ilic.windows:
            w = self.ilic.windows[-1]
            return {n: float(v) for n, v, e in zip(w.result.names, w.result.theta, w.essential, strict=True) if e}
        return {}

    def model_effects(self) -> dict[str, dict[str, float]]:
        """Plant effects of the output-error or :meth:`primary` fit, for a model file (:func:`ilic_cli.closed_loop_id.plant_of`)."""
        oe = self.output_error()
        if oe is not None:
            return oe.plant()[1]
        primary = self.primary()
        if primary is None:
            return {}
        return plant_of(primary[1].names, primary[1].theta, self.effects)[1]


def with_effects(structure: str, effects: dict[str, Any] | None, fs_hz: float) -> Model:
    """The regressor of ``structure`` extended by the columns of ``effects`` (id -> nonlinear value or ``None``)."""
    model = get_model(structure)
    if not effects:
        return model
    columns: list[Column] = []
    for eid, value in effects.items():
        effect = get(eid)
        if not effect.columns:
            raise ParameterError("effect", eid, "an effect with regressor columns (a time shift such as 'delay' is not a column)")
        if effect.scan is not None and value is None:  # nonlinear: its columns depend on the scanned value
            raise ParameterError(f"{eid}.{effect.scan.name}", None, "given: the columns depend on it")
        columns.extend(effect.regressor_columns(value, fs_hz))
    return model.extend(*columns, name=structure + "".join(f"+{e}" for e in effects))


def _masked_summary(report: IdentifyReport, valid: np.ndarray, saturation_note: str) -> str:
    parts = [saturation_note]
    if report.ls is not None:
        rows = report.ls.result.rows
        total = len(kept_indices(len(valid) - report.ls.settings.trim, report.ls.settings.decimation))
        parts.append(f"IDIM-LS uses {rows} of {total} decimated rows ({100.0 * (total - rows) / total:.3g} % masked)")
    if report.ilic is not None and report.ilic.windows:
        touched = sum(1 for w in report.ilic.windows if "rows masked" in w.note)
        parts.append(f"IDIM-ILIC rows masked in {touched} of {len(report.ilic.windows)} window(s)")
    return "; ".join(parts)


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
) -> IdentifyReport:
    """Run IDIM-LS and/or IDIM-ILIC on ``log`` and validate on other logs.

    Parameters
    ----------
    log : RunLog
        Needs ``t``, ``q``, ``tau``; IDIM-ILIC also needs ``q_ref``
        (``qd_ref``/``qdd_ref`` are derived from it when absent).
    method : {"ls", "ilic", "both", "didim", "iv", "all", "oe", "cloe"}
        ``both``: IDIM-LS and IDIM-ILIC; ``didim``, ``iv``: DIDIM or IDIM-IV
        (:mod:`ilic_cli.closed_loop_id`) started from IDIM-LS, which is
        reported beside them; ``all``: every method (IDIM-ILIC when usable);
        ``oe``, ``cloe``: open- or closed-loop output error from IDIM-LS
        (:mod:`ilic_cli.output_error`), with the benchmark's open-loop
        figure on each validation log.
    structure : {"rigid", "rigid-offset", "asymmetric"}
    effects : dict, optional
        Effects identified with the structure as further regressor columns
        (IDIM-LS, DIDIM, IDIM-IV): effect id -> its nonlinear value, ``None`` for a
        linear effect (:mod:`ilic_cli.effects`).
    validate : list of RunLog
        Logs to apply the estimates to (same processing).
    closed_loop_settings : dict, optional
        ``didim``/``iv`` -> iteration settings (default: each method's own,
        :data:`ilic_cli.closed_loop_id.DEFAULT_SETTINGS`).
    pd_timing : {"recorded", "documented"}
        How DIDIM / IDIM-IV's replays time a PD log's command: as read from
        the recording with the IDIM-LS estimate
        (:func:`ilic_cli.simulation.timing.recorded_loop`), or as the log's
        metadata states it.
    """
    prepared = with_rest(prepare_log(log), ls_settings)  # the samples every method fits (no saturated drive, no standstill)
    log = prepared.log  # an irregularly sampled log is on a uniform grid now
    src, fs, valid, hold = prepared.source, prepared.fs_hz, prepared.valid, identification_hold_s(prepared)
    effects = dict(effects or {})
    model = with_effects(structure, effects, fs)
    if method not in IDENTIFY_METHODS:
        raise ParameterError("method", method, f"one of {', '.join(IDENTIFY_METHODS)}")
    if effects and method not in ("ls", "didim", "iv", "oe", "cloe"):
        raise ParameterError(
            "method", method, "'ls', 'didim', 'iv', 'oe' or 'cloe' with effect columns (IDIM-ILIC windows identify the structure's own parameters)"
        )
    if pd_timing not in parameters.PD_TIMINGS:
        raise ParameterError("pd_timing", pd_timing, f"one of {', '.join(parameters.PD_TIMINGS)}")
    report = IdentifyReport(
        source=src,
        model=structure,
        fs_hz=fs,
        samples=len(log),
        warnings=list(prepared.warnings),
        effects=effects,
        joint=log.meta.get("joint"),
        joint_type=log.sensor.joint_type,
        method=method,
        usable=usable_rows(prepared, ls_settings),
    )
    closed = [m for m in ("didim", "iv") if method in (m, "all")]
    if closed:  # refuse before any work
        require_closed_loop(log, src, " and ".join(CLOSED_LOOP_METHODS[m] for m in closed))
    if method == "cloe":
        require_closed_loop(log, src, "CLOE")
    if method in ("oe", "cloe"):
        prepared.require_contiguous(method.upper())
    if method in ("ls", "both", "all", "oe", "cloe") or closed:
        try:
            report.ls = idim_ls(log.t, log["q"], log["tau"], fs, model, ls_settings, valid=valid, segments=prepared.segments, hold_s=hold)
        except ValueError as exc:
            raise IdentificationError(src, str(exc)) from None
        if not report.ls.result.full_rank:
            report.warnings.append("IDIM-LS: the observation matrix is rank-deficient; the trajectory does not excite every parameter")
    timed = prepared
    if (closed or method == "cloe") and pd_timing == "recorded":  # the loop that ran: its timing read with the IDIM-LS start
        from ilic_cli.simulation.timing import recorded_loop  # deferred: with the replay

        assert report.ls is not None
        timed_log, report.timing = recorded_loop(log, *plant_of(model.names, report.ls.result.theta, effects), ls_settings)
        timed = replace(prepared, log=timed_log)
        sentence = report.timing.sentence() if report.timing is not None else ""
        if sentence:
            report.warnings.append(f"loop timing: {sentence}")
    for m in closed:
        assert report.ls is not None
        result = closed_loop_identify(
            m, log, model, report.ls.result.theta, effects=effects, ls_settings=ls_settings, settings=(closed_loop_settings or {}).get(m), prepared=timed
        )
        setattr(report, m, result)
        if not result.converged:
            report.warnings.append(f"{result.method} did not converge: {result.stop_reason}; the last iterate is reported")
    if method in ("oe", "cloe"):
        _output_error(report, method, timed.log, model, effects, oe_settings, ls_settings)
    run_ilic = method in ("ilic", "both", "all")
    if method in ("both", "all"):
        reason = ilic_unusable(log, fs, ilic_settings)
        if reason is not None:
            report.warnings.append(f"IDIM-ILIC not run: {reason}; " + ("IDIM-LS only" if method == "both" else "the other methods only"))
            run_ilic = False
    elif method == "ilic":
        reason = ilic_unusable(log, fs, ilic_settings)
        if reason is not None:
            raise IdentificationError(src, f"IDIM-ILIC cannot run: {reason}")
    if run_ilic:
        try:
            report.ilic = identify_ilic(
                log.t,
                log["q_ref"],
                log["tau"],
                fs,
                model,
                ilic_settings,
                qd_ref=log.channels.get("qd_ref"),
                qdd_ref=log.channels.get("qdd_ref"),
                q=log["q"],
                valid=valid,
            )
        except ValueError as exc:
            raise IdentificationError(src, str(exc)) from None
        report.ilic = _without_cut_windows(report.ilic, prepared.gap_samples, fs, report.warnings)
        if prepared.rest is not None and prepared.rest.count:  # the windows' masked rows: at rest too, not only a saturated drive
            why = "(saturated drive, or at rest)" if prepared.saturated is not None else "(at rest)"
            report.ilic = replace(report.ilic, windows=[replace(w, note=w.note.replace("(saturated drive)", why)) for w in report.ilic.windows])
        not_essential: dict[str, list[int]] = {}
        for w in report.ilic.windows:
            if w.note and not w.note.startswith("not essential"):
                report.warnings.append(f"IDIM-ILIC window k={w.k}: {w.note}")
            elif w.note:
                for name, ok in zip(w.result.names, w.essential, strict=True):
                    if not ok:
                        not_essential.setdefault(name, []).append(w.k)
        for name, ks in not_essential.items():
            report.warnings.append(
                f"IDIM-ILIC: {name} not essential (%σ > {ilic_settings.sigma_max_pct:g}) in {len(ks)} of {len(report.ilic.windows)} windows "
                f"(k = {_ranges(ks)}); it would not be updated"
            )
    if prepared.saturated is not None:
        report.warnings.append(_masked_summary(report, prepared.saturated, str(prepared.saturation_note())))
    estimates: list[tuple[str, np.ndarray]] = []  # (method, theta) applied to each validation log
    if report.ls is not None:
        estimates.append(("IDIM-LS", report.ls.result.theta))
    if report.ilic is not None and report.ilic.windows and np.all(np.isfinite(report.ilic.windows[-1].result.theta)):
        estimates.append((f"IDIM-ILIC (k={report.ilic.windows[-1].k})", report.ilic.windows[-1].result.theta))
    estimates += [(cl.method, cl.result.theta) for cl in report.closed_loop()]
    plants = _validation_plants(report, model, effects, estimates)
    for other in validate or []:
        osrc = str(other.meta.get("source", ""))
        op = with_rest(prepare_log(other, prefix=f"validation log {osrc}"), ls_settings)
        vlog = op.log  # an irregularly sampled log is on a uniform grid now
        report.warnings.extend(op.warnings)
        if op.saturated is not None:
            report.warnings.append(f"validation log {osrc}: {op.saturation_note()}")
        for label, theta in estimates:
            res = cross_validate(
                theta, vlog.t, vlog["q"], vlog["tau"], op.fs_hz, model, ls_settings, valid=op.valid, segments=op.segments, hold_s=identification_hold_s(op)
            )
            report.validation.append(Validation(osrc, label, res, _open_loop_figure(vlog, plants.get(label), oe_settings, report.warnings)))
        for oe in (report.oe, report.cloe):
            if oe is not None:
                oe_res = _inverse_model_error(oe, vlog, op, effects, ls_settings)
                report.validation.append(Validation(osrc, oe.method, oe_res, _open_loop_figure(vlog, oe.plant(), oe_settings, report.warnings)))
    return report


def _output_error(
    report: IdentifyReport, method: str, log: RunLog, model: Model, effects: dict[str, Any], settings: OESettings, ls_settings: LSSettings
) -> None:
    """OE or CLOE from the IDIM-LS estimate's plant (:mod:`ilic_cli.output_error`), with its force error on the log."""
    from ilic_cli.output_error import closed_loop_oe, open_loop_oe

    assert report.ls is not None
    rigid, eff = plant_of(model.names, report.ls.result.theta, effects)
    names = parameters.structure_names(report.model)
    name = model.name
    if method == "oe":
        result = open_loop_oe(log, rigid, eff, names, model_name=name, settings=settings, warnings=report.warnings)
    else:
        result = closed_loop_oe(log, rigid, eff, names, model_name=name, settings=settings, trim=ls_settings.trim)
    prepared = prepare_log(log)
    result = replace(result, force_error_pct=_finite_pct(_inverse_model_error(result, log, prepared, effects, ls_settings)))
    setattr(report, method, result)
    if "offset" in result.names and "Fc_pos" in result.names:
        report.warnings.append(
            f"{result.method}: the offset and the asymmetric Coulomb levels are one plant (Fc_pos + offset, Fc_neg - offset move the axis alike, "
            "break-away included): a simulation cannot tell them apart, and their standard deviations say so"
        )
    if not result.converged:
        report.warnings.append(f"{result.method} did not converge: {result.stop_reason}; the last iterate is reported")


def _finite_pct(res: LSResult | None) -> float | None:
    return None if res is None else float(res.relative_error_pct)


def _inverse_model_error(oe: OEResult, log: RunLog, prepared: Any, effects: dict[str, Any], ls_settings: LSSettings) -> LSResult | None:
    """The inverse model's force error with an output-error estimate (IDIM-LS's processing; effects' columns at the fitted values)."""
    rigid, eff = oe.plant()
    values = {**rigid, **{k: v for params in eff.values() for k, v in params.items()}}
    try:
        fitted = {eid: get(eid).value_from_plant(eff.get(eid, {}), float(rigid["M"])) for eid in effects}
        m = with_effects(oe.model.split("+")[0], fitted, prepared.fs_hz)
        theta = np.array([values[n] for n in m.names], dtype=np.float64)
    except (KeyError, IlicError):
        return None  # the fitted plant has no inverse model of this form
    hold = identification_hold_s(prepared)
    return cross_validate(theta, log.t, log["q"], log["tau"], prepared.fs_hz, m, ls_settings, valid=prepared.valid, segments=prepared.segments, hold_s=hold)


def _validation_plants(report: IdentifyReport, model: Model, effects: dict[str, Any], estimates: list[tuple[str, np.ndarray]]) -> dict[str, Any]:
    """OE / CLOE runs: each validated estimate's plant, for its open-loop figure (none otherwise)."""
    if report.method not in ("oe", "cloe"):
        return {}
    return {label: plant_of(model.names, theta, effects) for label, theta in estimates if label == "IDIM-LS" or label in CLOSED_LOOP_METHODS.values()}


def _open_loop_figure(log: RunLog, plant: Any, settings: OESettings, warnings: list[str]) -> dict[str, Any] | None:
    """The benchmark's open-loop figure of ``plant`` on ``log`` (``None`` without a plant, or a log without ``vir`` and a drive gain)."""
    if plant is None:
        return None
    if "vir" not in log or not log.meta.get("drive_gain"):
        warnings.append(f"validation log {log.meta.get('source')}: no open-loop figure (it needs the drive command vir and a drive gain)")
        return None
    from plant.replay import simulate_open_loop  # deferred: the plant pulls in numba

    try:
        return simulate_open_loop(log, *plant, init_samples=settings.init_samples, substeps=10)[1].to_dict()
    except IlicError as exc:
        warnings.append(f"validation log {log.meta.get('source')}: no open-loop figure: {exc.problem}")
        return None


IDENTIFY_METHODS = ("ls", "ilic", "both", "didim", "iv", "all", "oe", "cloe")
"""Values of ``identify(method=...)``."""


TRACKING_LIMIT = 0.5
"""A reference whose tracking error ratio ``||q_ref - q|| / ||q - mean(q)||`` exceeds this does not
track the measured joint (a well-tuned loop is near 1e-3; another joint's reference is near 1 or above)."""


def ilic_unusable(log: RunLog, fs_hz: float, settings: ILICSettings) -> str | None:
    """Why IDIM-ILIC cannot run on ``log`` (no reference, shorter than one window, a reference that does not track), else ``None``."""
    if "q_ref" not in log:
        return "the log has no reference position (q_ref)"
    if len(log) < int(round(settings.window_s * fs_hz)):
        return f"the log ({len(log) / fs_hz:.3g} s) is shorter than one window ({settings.window_s:g} s)"
    ratio = float(tracking_error_ratio(log["q_ref"], log["q"]))
    if not ratio <= TRACKING_LIMIT:
        return (
            f"the reference does not track the measured joint (tracking error ratio {ratio:.3g}, above {TRACKING_LIMIT:g}): "
            "check that the reference is this joint's"
        )
    return None


def _without_cut_windows(ilic: ILICResult, gap_samples: np.ndarray, fs_hz: float, warnings: list[str]) -> ILICResult:
    """``ilic`` without the windows a gap of the time stamps cuts (their filtered rows would span it), said in ``warnings``."""
    if not len(gap_samples) or not ilic.windows:
        return ilic
    n = int(round(ilic.settings.window_s * fs_hz))
    cut = {int(i) // n for i in gap_samples if (int(i) % n) < n - 1}
    kept = [w for i, w in enumerate(ilic.windows) if i not in cut]
    dropped = [w.k for i, w in enumerate(ilic.windows) if i in cut]
    if dropped:
        warnings.append(f"IDIM-ILIC: window(s) k = {_ranges(dropped)} dropped: a gap in the time stamps cuts them")
    return replace(ilic, windows=kept)


def _ranges(ks: list[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"``."""
    parts: list[str] = []
    start = prev = ks[0]
    for k in ks[1:] + [None]:
        if k is not None and k == prev + 1:
            prev = k
            continue
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
        if k is not None:
            start = prev = k
    return ", ".join(parts)
