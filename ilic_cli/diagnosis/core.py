"""``ilic diagnose`` logic: compare, locate, name, model, and show the fit improve.

Takes run logs (no file I/O here) and returns a :class:`Diagnosis`; the
command module renders it (:mod:`ilic_cli.diagnosis.report`) and plots it
(:mod:`ilic_cli.diagnosis.plots`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cache
from typing import Any

import numpy as np

from ilic_cli.diagnosis import dwell, segments
from ilic_cli.diagnosis.baseline import held, hold_s
from ilic_cli.diagnosis.compare import SimulationComparison, compare_simulation
from ilic_cli.diagnosis.decide import ReplayVerdict, below_period, decision_sensor, materiality, noisy_output_error, replay_decide
from ilic_cli.diagnosis.drift import DriftResult, detect_drift, with_drift
from ilic_cli.diagnosis.drift import evaluation as drift_evaluation
from ilic_cli.diagnosis.locate import Region, force_lag, locate
from ilic_cli.diagnosis.null import MonteCarloNull, NullSettings
from ilic_cli.diagnosis.refit import InverseFit, Refit, closed_loop_refit, plant_problem
from ilic_cli.diagnosis.select import (
    Evaluation,
    SelectionResult,
    SelectSettings,
    Step,
    at_edge,
    fit_system,
    forward_select,
    moving_rows,
    system,
    validation_error,
)
from ilic_cli.diagnosis.sensor import measurement_std, position_noise
from ilic_cli.diagnosis.stats import blocked_folds, gls_covariance, heldout_errors
from ilic_cli.effects import EFFECTS, Effect, Estimate, Fit, applicable
from ilic_cli.errors import IdentificationError, IlicError, ParameterError
from ilic_cli.idim_ls import IDIMData, LSSettings, lsq_rows
from ilic_cli.lsq import LSResult, relative_error_pct, solve
from ilic_cli.modelfile import model_document
from ilic_cli.parameters import PARAMETERS, structure_of, weight
from ilic_cli.prepare import PreparedLog, prepare_log
from ilic_cli.regressor import MODELS, Model, get_model
from ilic_cli.runlog import RunLog, joint_type, vertical
from ilic_cli.simulation.replay import tau_sensor
from ilic_cli.simulation.timing import ControlTiming, recorded_loop
from ilic_cli.usable import UsableRows, usable_rows, with_rest


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of a diagnosis.

    Attributes
    ----------
    model : str
        Rigid model structure identified first (``rigid-offset``).
    ls : LSSettings
        IDIM-LS filtering and decimation (benchmark defaults).
    select : SelectSettings
        Statistics of the forward selection.
    simulate : bool
        Replay the recorded reference through the plant (before/after).
    null : NullSettings
        The test that decides the replay (default: Diebold-Mariano; or a Monte-Carlo null).
    pd_timing : {"recorded", "documented"}
        When a PD log's command acts in every replay (:data:`ilic_cli.parameters.PD_TIMINGS`).
    replay_noise : bool
        The replays that decide carry the recording's position noise (:mod:`ilic_cli.diagnosis.sensor`); ``False``: noise-free.
    """

    model: str = "rigid-offset"
    ls: LSSettings = LSSettings()
    select: SelectSettings = field(default_factory=SelectSettings)
    simulate: bool = True
    null: NullSettings = NullSettings()
    pd_timing: str = "recorded"
    replay_noise: bool = True


@dataclass
class Finding:
    """One effect the model left out, with its estimate and the evidence.

    ``parameters`` and ``plant_effect`` are the estimates of ``method``: the
    closed-loop refit's (:mod:`ilic_cli.diagnosis.refit`) when it was
    accepted, else the inverse model's (IDIM-LS); ``inverse_parameters`` are
    the inverse model's, side by side.
    """

    effect: Effect
    parameters: dict[str, Estimate]
    plant_effect: dict[str, float] | None
    located: list[Region]
    evidence: Evaluation
    note: str = ""
    method: str = "IDIM-LS"
    inverse_parameters: dict[str, Estimate] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        ev = self.evidence.to_dict()
        ev.pop("effect", None)
        # none when the level was the closed loop's (its inverse-model estimate is outside the effect's physics or unconfirmed)
        inverse = self.inverse_parameters or (self.parameters if self.method == "IDIM-LS" else {})
        return {
            "effect": self.effect.id,
            "title": self.effect.title,
            "explanation": self.effect.explanation,
            "form": self.effect.form,
            "signature": self.effect.signature,
            "method": self.method,
            "parameters": {k: v.to_dict() for k, v in self.parameters.items()},
            "inverse_model_parameters": {k: v.to_dict() for k, v in inverse.items()} if inverse else None,
            "plant_effect": self.plant_effect,
            "located": [r.to_dict() for r in self.located],
            "evidence": ev,
            "note": self.note,
        }


@dataclass
class Diagnosis:
    """Everything ``ilic diagnose`` found on one log."""

    source: str
    model: str
    fs_hz: float
    rows_used: int
    rows_total: int
    base: LSResult
    augmented: LSResult
    findings: list[Finding]
    fit: dict[str, dict[str, float | None]]
    located: list[Region]
    tried: list[list[Evaluation]]
    decisions: list[ReplayVerdict]
    model_file: dict[str, Any]
    settings: DiagnoseSettings
    simulation: SimulationComparison | None = None
    refit: Refit | None = None
    validation_source: str | None = None
    warnings: list[str] = field(default_factory=list)
    residual: dict[str, np.ndarray] = field(default_factory=dict)
    timing: ControlTiming | None = None
    drift: DriftResult | None = None
    """Friction drift read from per-window estimates (:mod:`ilic_cli.diagnosis.drift`)."""
    weight: dict[str, Estimate] | None = None
    """A vertical axis's constant force as the load's weight and implied mass (:func:`ilic_cli.parameters.weight`), else ``None``."""
    replay_sensor: dict[str, Any] | None = None
    """The sensor noise every deciding replay carried (:func:`ilic_cli.diagnosis.decide.decision_sensor`); ``None``: none replayed, or noise-free."""
    usable: UsableRows | None = None
    """The rows every fit of the log uses (the rule for samples at rest, as ``identify``'s); ``rows_total`` of them, ``rows_used`` beyond the timing rows."""
    joint: str = "prismatic"
    """``prismatic`` or ``revolute`` (:func:`ilic_cli.runlog.joint_type`): the units the report writes."""

    @property
    def conclusion(self) -> str:
        if not self.findings:
            return "no significant mismatch"
        return "left out: " + ", ".join(f.effect.title for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "model": self.model,
            "sample_rate_hz": self.fs_hz,
            "rows_used": self.rows_used,
            "rows_total": self.rows_total,
            "usable_rows": None if self.usable is None else self.usable.to_dict(),
            "conclusion": self.conclusion,
            "findings": [f.to_dict() for f in self.findings],
            "fit": self.fit,
            "base": self.base.to_dict(),
            "augmented": self.augmented.to_dict(),
            "located": [r.to_dict() for r in self.located],
            "selection": [[e.to_dict() for e in step] for step in self.tried],
            "decisions": [v.to_dict() for v in self.decisions],
            "simulation": None if self.simulation is None else self.simulation.to_dict(),
            "refit": None if self.refit is None else self.refit.to_dict(),
            "validation_source": self.validation_source,
            "model_file": self.model_file,
            "settings": {
                "model": self.settings.model,
                "ls": self.settings.ls.to_dict(),
                "selection": self.settings.select.to_dict(),
                "replay_test": self.settings.null.to_dict(),
                "pd_timing": self.settings.pd_timing,
                "replay_noise": self.settings.replay_noise,
            },
            "replay_sensor_noise": self.replay_sensor,
            "warnings": list(self.warnings),
            "timing": None if self.timing is None else self.timing.to_dict(),
            "drift": None if self.drift is None else self.drift.to_dict(),
            "weight": None if self.weight is None else {k: v.to_dict() for k, v in self.weight.items()},
        }


# ---------------------------------------------------------------------------
# parameters in the plant's vocabulary
# ---------------------------------------------------------------------------
def effect_fit(
    step: Step, names: tuple[str, ...], theta: np.ndarray, cov: np.ndarray, value_std: float | None, hold_s: float = 0.0
) -> tuple[dict[str, Estimate], dict[str, float] | None, str]:
    """Reported estimates, plant parameters and a note of one accepted effect (:meth:`ilic_cli.effects.Effect.fit_to_plant`).

    ``hold_s``: half a sample period when the logged force is the held drive
    command; the baseline already evaluates the regressor that much later
    (:mod:`ilic_cli.diagnosis.baseline`), so a found ``delay`` is a lag beyond
    the hold and is the plant's ``delay`` as it is (the plant holds its force
    itself).
    """
    if step.level is not None:  # held at a closed-loop estimate: its coefficients join the fit's, with their own spread
        m = len(step.level)
        names = (*names, *step.effect.column_names)
        theta = np.r_[theta, step.level]
        cov = np.pad(cov, ((0, m), (0, m)))
        cov[-m:, -m:] = np.diag(np.square(step.level_std or (0.0,) * m))
    return step.effect.fit_to_plant(Fit(names, theta, cov, step.value, value_std, hold_s))


def steps_from_effects(effects: dict[str, Any], M: float) -> list[Step]:
    """Known effects of a model file as fixed steps (their nonlinear values)."""
    out = []
    for eid, prm in effects.items():
        e = EFFECTS.get(eid)
        if e is None or not e.identifiable or not isinstance(prm, dict):
            continue
        out.append(Step(e, e.value_from_plant(e.values(prm), M)))
    return out


def _inverse_fit(data: IDIMData, base: Model, steps: list[Step], rows: np.ndarray) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """The inverse model's fit of ``base + steps`` on ``rows``: names, estimate, autocorrelation-aware covariance."""
    fit = fit_system(data, base, steps, rows)
    return fit.names, fit.theta, gls_covariance(fit.W, fit.y, fit.theta)


def _prepare(prepared: PreparedLog, model: Model, settings: LSSettings) -> IDIMData:
    """The IDIM system of ``prepared``, its regressor evaluated like the logged force (:func:`ilic_cli.diagnosis.baseline.held`)."""
    log = prepared.log
    try:
        data = lsq_rows(log.t, log["q"], log["tau"], prepared.fs_hz, model, settings, valid=prepared.valid)
    except ValueError as exc:
        raise IdentificationError(prepared.source, str(exc)) from None
    data = held(data, model, hold_s(tau_sensor(log), prepared.fs_hz))
    return data


def base_model(model_doc: dict[str, Any] | None, default: str) -> Model:
    """The rigid structure: the model file's (by name, or by its parameter names), else ``default``."""
    if model_doc is None:
        return get_model(default)
    name = model_doc.get("model")
    if name in MODELS:
        return MODELS[name]
    found = structure_of(set(model_doc["parameters"]))
    return get_model(found or default)


def diagnose(
    log: RunLog,
    *,
    settings: DiagnoseSettings | None = None,
    model_doc: dict[str, Any] | None = None,
    against: RunLog | None = None,
    validate: RunLog | None = None,
) -> Diagnosis:
    """Diagnose ``log``: what does the rigid model leave out?

    Parameters
    ----------
    log : RunLog
        The recording (``t``, ``q``, ``tau``; ``q_ref`` for the simulation comparison).
    settings : DiagnoseSettings, optional
        Default :class:`DiagnoseSettings` (every effect of the catalogue).
    model_doc : dict, optional
        A parsed model file (:func:`ilic_cli.modelfile.parse_model`): its
        structure is the starting model, its values are replayed as "before",
        and its effects are kept and not searched again.
    against : RunLog, optional
        A simulated log to compare the recording with (instead of replaying).
    validate : RunLog, optional
        Another recording: candidates must not raise the error there.
    """
    settings = settings or DiagnoseSettings()
    settings.null.check(replay_alpha(settings))
    prepared = with_rest(prepare_log(log), settings.ls)  # the samples every fit uses, as identify's
    log = prepared.log  # an irregularly sampled log is on a uniform grid now
    prepared.require_contiguous("diagnosis")
    fs = prepared.fs_hz
    src = prepared.source
    warnings: list[str] = list(prepared.warnings)
    base = base_model(model_doc, settings.model)
    data = _prepare(prepared, base, settings.ls)
    vprepared = with_rest(prepare_log(validate, prefix=f"validation log {validate.meta.get('source', '')}"), settings.ls) if validate is not None else None
    if vprepared is not None:
        validate = vprepared.log
        vprepared.require_contiguous("diagnosis")
    vdata = _prepare(vprepared, base, settings.ls) if vprepared is not None else None
    for p in (prepared, vprepared):
        if p is not None and p.saturation_note() is not None:
            warnings.append(f"{p.source}: {p.saturation_note()}")
    known = steps_from_effects(model_doc.get("effects", {}), float(model_doc["parameters"].get("M", 95.0))) if model_doc else []
    sel_settings = settings.select
    joint = joint_type(log.units.get("q"))  # gravity is proposed on a revolute joint only (Effect.joints)
    sel_settings = replace(sel_settings, effects=tuple(e for e in sel_settings.effects if e not in EFFECTS or joint in EFFECTS[e].joints))
    if known:
        sel_settings = replace(sel_settings, effects=tuple(e for e in sel_settings.effects if e not in {s.effect.id for s in known}))
    selection = forward_select(data, base, fs, sel_settings, validation=vdata, known=known)
    rows = moving_rows(data)
    hold = hold_s(tau_sensor(log), fs)
    W0, y0, names0 = system(data, base, known, rows)
    res0 = solve(W0, y0, names0, sigma=settings.ls.sigma)
    before_params = dict(model_doc["parameters"]) if model_doc else {n: float(v) for n, v in zip(names0, res0.theta, strict=True) if n in PARAMETERS}
    before_effects = dict(model_doc.get("effects", {})) if model_doc else {}
    timing = None
    if settings.simulate and against is None and settings.pd_timing == "recorded":  # the replays run the loop that ran: its timing read from the recording
        log, timing = recorded_loop(log, before_params, before_effects, settings.ls)
        if validate is not None:
            validate, _ = recorded_loop(validate, before_params, before_effects, settings.ls)
    kept, verdicts, replay_sensor = _decide(log, data, base, known, selection, rows, settings, hold, validate, against)
    replayed = settings.simulate and against is None and "q_ref" in log
    held = [i for i, st in enumerate(kept) if st.level is not None]
    segment_refit = None
    if held == [len(kept) - 1] and replayed and dwell.dwells(np.asarray(log["q_ref"]), log.fs_hz):
        # Stribeck friction found at the dwells: the open-loop segments estimate it, and may refute it
        segment_refit, refuted = _segment_refit(log, data, base, rows, settings.ls, known, kept, hold)
        if refuted is not None:
            kept, verdicts = without_last(kept, verdicts, refuted)
            held, segment_refit = [], None
    steps = [*known, *kept]
    W1, y1, names1 = system(data, base, steps, rows)
    if not len(y0) > 4 * W1.shape[1]:
        raise IdentificationError(src, f"only {len(y0)} usable rows after leaving out standstill: too few to diagnose")
    res1 = solve(W1, y1, names1, sigma=settings.ls.sigma)
    cov1 = gls_covariance(W1, y1, res1.theta)
    res1 = _with_std(res1, cov1)
    res0 = _with_std(res0, gls_covariance(W0, y0, res0.theta))
    folds = blocked_folds(len(y0), sel_settings.folds, sel_settings.guard)
    h0 = heldout_errors(W0, y0, folds)
    h1 = heldout_errors(W1, y1, folds)
    fit: dict[str, dict[str, float | None]] = {
        "relative_error_pct": {"before": res0.relative_error_pct, "after": res1.relative_error_pct},
        "heldout_relative_error_pct": {"before": relative_error_pct(y0, y0 - h0), "after": relative_error_pct(y1, y1 - h1)},
        "validation_relative_error_pct": {"before": None, "after": None},
        "simulation_force_relative_error_pct": {"before": None, "after": None},
    }
    if vdata is not None:
        fit["validation_relative_error_pct"] = {"before": validation_error(data, vdata, base, known), "after": validation_error(data, vdata, base, steps)}
    # locate on the rigid residual (decimated rows) and the force lag
    dec = data.decimate
    kin = data.kin
    assert kin.q is not None  # the residual's kinematics carry the position (located against it)
    td, qd_d, qdd_d, q_d = data.t_dec[rows], dec(kin.qd)[rows], dec(kin.qdd)[rows], dec(kin.q)[rows]
    e0 = y0 - W0 @ res0.theta
    e1 = y1 - W1 @ res1.theta
    fs_dec = fs / settings.ls.decimation
    alpha = sel_settings.alpha
    located = locate(e0, t=td, q=q_d, qd=qd_d, qdd=qdd_d, W=W0, fs_hz=fs_dec, alpha=alpha, q_unit="rad" if joint == "revolute" else "m")
    full = np.asarray(base.matrix(kin)) @ res0.theta[: len(base.names)]
    located.append(force_lag(data.tau, full, fs))
    findings = []
    accepted = {ev.effect: ev for ev in selection.accepted}
    for st in kept:
        if st.level is not None:  # proposed on the closed loop: the evidence is the inverse model's last word on it, and the replay's verdict
            last = selection.last_word(st.effect.id)
            assert last is not None
            accepted[st.effect.id] = last
    refit = None
    # a level held at the closed loop's estimate (the last candidate judged) joins the refit as a column, the estimate its start,
    # with no search of its value with the inverse model's linear parameters: theirs is the level the closed loop replaced.
    # Not at dwells: there Stribeck friction shows in the creep the sensor noise drives, and the refit replays noise-free
    # (measured, refitted so: the two Stribeck trapezoids with the current loop 13 and 10 % -> 37 and 44 % off)
    if held and not (held == [len(kept) - 1] and replayed and not dwell.dwells(np.asarray(log["q_ref"]), log.fs_hz)):
        refit = segment_refit or Refit(False, NOT_REFITTED, list(kept), names1)
    elif kept and replayed:
        grids = {s.effect.id: s.effect.scan.grid(data.kin, fs) for s in kept if s.effect.scan is not None}
        inverse_fit: InverseFit | None = lambda s: _inverse_fit(data, base, s, rows)
        columns, theta0 = kept, res1.theta
        if held:
            level = kept[-1].level
            assert level is not None
            columns, theta0, inverse_fit = [*kept[:-1], Step(kept[-1].effect, kept[-1].value)], np.r_[res1.theta, level], None
        confirm: Callable[[Refit], str | None] | None = None
        if noise := replay_sensor:
            # the inverse model's estimate replayed with the noise: once, whichever refits (an output-error fit, then a search) are judged
            before = cache(
                lambda: noisy_output_error(
                    log, settings.ls, *model_parameters([*known, *kept], names1, res1.theta, np.zeros((len(res1.theta),) * 2), hold), noise
                )
            )
            confirm = lambda r: _noise_objection(r, log, settings.ls, noise, before(), known, hold)  # noqa: E731
        refit = closed_loop_refit(log, prepared, base, known, columns, theta0, grids, ls=settings.ls, inverse_fit=inverse_fit, hold_s=hold, confirm=confirm)
    final = refit.steps if refit is not None and refit.accepted else kept
    for st, st_final in zip(kept, final, strict=True):
        ev = accepted[st.effect.id]
        # a closed-loop proposal's vs is the folds' median, its spread theirs: the inverse model's standard deviation is not its own
        params, plant, note = effect_fit(st, names1, res1.theta, cov1, st.value_std if st.level is not None else ev.value_std, hold)
        inverse = {} if st.level is not None else params  # a level held at a closed-loop estimate is no inverse-model estimate
        method = dwell.METHOD if st.level is not None else "IDIM-LS"
        notes = [s.reason for s in (refit.searches if refit is not None else []) if s.effect == st.effect.id]
        if refit is not None and refit.accepted and refit.theta is not None and refit.cov is not None:
            std = refit.value_std.get(st.effect.id) if st_final.value != st.value else st.value_std if st.level is not None else ev.value_std
            params, plant, note = effect_fit(st_final, refit.names, refit.theta, refit.cov, std, hold)
            method = refit.method
        regs = sorted([r for r in located if r.kind in st.effect.signature_kinds and r.significant], key=lambda r: r.p_value)
        findings.append(Finding(st.effect, params, plant, regs, ev, "; ".join(n for n in [note, *notes] if n), method, inverse))
    if refit is not None and refit.accepted and refit.theta is not None and refit.cov is not None:
        rigid, effects_doc = model_parameters([*known, *final], refit.names, refit.theta, refit.cov, hold)
        std_doc = model_std([*known, *final], refit.names, refit.theta, refit.cov, hold, refit.value_std)
        doc = model_document(base.name, rigid, method=f"{refit.method} + ilic diagnose", effects=effects_doc, source=src or None, std=std_doc)
    else:
        rigid, effects_doc = model_parameters(steps, names1, res1.theta, cov1, hold)
        doc = model_document(base.name, rigid, method="IDIM-LS + ilic diagnose", effects=effects_doc, source=src or None)
    drift_found = detect_drift(td, W1, y1, names1)  # friction that changes over time, from per-window estimates
    if drift_found.found:
        findings.append(Finding(EFFECTS["friction_drift"], drift_found.estimates(), drift_found.plant_effect(), [], drift_evaluation(drift_found)))
        doc = with_drift(doc, drift_found)
        fit["relative_error_pct"]["after"], fit["heldout_relative_error_pct"]["after"] = drift_found.relative_error_after_pct, drift_found.heldout_after_pct
    diag = Diagnosis(
        drift=drift_found,
        source=src,
        model=base.name,
        fs_hz=fs,
        rows_used=int(rows.sum()),
        rows_total=len(rows),
        base=res0,
        augmented=res1,
        findings=findings,
        fit=fit,
        located=located,
        tried=selection.tried,
        decisions=verdicts,
        model_file=doc,
        settings=settings,
        refit=refit,
        validation_source=None if validate is None else str(validate.meta.get("source", "")),
        warnings=warnings,
        usable=replace(usable_rows(prepared, settings.ls), hold_s=hold),
        joint=joint,
        residual={"t": td, "q": q_d, "qd": qd_d, "before": e0, "after": e1, "y": y0, "y_before": W0 @ res0.theta, "y_after": W1 @ res1.theta},
    )
    if vertical(log.meta) and "offset" in names1:  # a vertical axis: its constant force is the load's weight, not an offset
        i = names1.index("offset")
        diag.weight = {k: Estimate(*v) for k, v in weight(float(res1.theta[i]), float(np.sqrt(max(cov1[i, i], 0.0)))).items()}
        for f in (f for f in findings if f.effect.id == "offset"):
            f.parameters, f.note = dict(diag.weight), "a vertical axis: the constant force is the load's weight"
    if timing is not None:
        timing.negative_flexibility = any(ev.effect == "flexibility" and "negative mass" in ev.reason for step in selection.tried for ev in step)
    diag.timing = timing
    if any(v.force_before is not None for v in verdicts):
        diag.replay_sensor = replay_sensor
    if settings.simulate or against is not None:
        try:
            diag.simulation = compare_simulation(
                log,
                data,
                rows,
                before_params,
                before_effects,
                doc["parameters"],
                doc["effects"] if findings else None,
                against=against,
                ls=settings.ls,
                alpha=alpha,
                after_sim=None if refit is None else refit.simulated,  # the replay of the model file's plant, when the refit made it
            )
        except ParameterError as exc:
            warnings.append(f"no simulation comparison: the fitted model is not a valid plant ({exc.problem})")
        if diag.simulation is not None:
            fit["simulation_force_relative_error_pct"] = {"before": diag.simulation.before.get("force"), "after": (diag.simulation.after or {}).get("force")}
            if diag.simulation.note:
                warnings.append(diag.simulation.note)
    return diag


def _decide(
    log: RunLog,
    data: IDIMData,
    base: Model,
    known: list[Step],
    selection: SelectionResult,
    rows: np.ndarray,
    settings: DiagnoseSettings,
    hold: float,
    validate: RunLog | None,
    against: RunLog | None,
) -> tuple[list[Step], list[ReplayVerdict], dict[str, Any] | None]:
    """The proposed steps that are material and, when the log can be replayed, that the replay keeps (:mod:`ilic_cli.diagnosis.decide`).

    Every evaluation the inverse model accepted gets the verdict as its decision
    (``selection.tried`` is updated in place). Also returned: the sensor noise the
    replays carried (:func:`~ilic_cli.diagnosis.decide.decision_sensor`), ``None``
    when none ran or they were noise-free.
    """
    material: list[Step] = []
    sensor = None
    verdicts: list[ReplayVerdict] = []
    kept_so_far = list(known)
    replayable = settings.simulate and against is None and "q_ref" in log
    for st in selection.steps:
        # without a replay the inverse model's value is the estimate: a delay too short for a finding goes now
        why = materiality(data, base, kept_so_far, st, rows) or (None if replayable else below_period(st, data.fs_hz))
        if why:
            verdicts.append(ReplayVerdict(st.effect.id, None, None, None, None, None, None, None, False, why))
        else:
            material.append(st)
            kept_so_far.append(st)
    if replayable and (on_loop := _closed_loop_proposal(log, data, base, [*known, *selection.steps], rows, settings, selection)) is not None:
        material.append(on_loop)
    if replayable and material:

        def plant_of(steps: list[Step], names: tuple[str, ...], theta: np.ndarray) -> tuple[dict[str, float], dict[str, Any]]:
            return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))), hold)

        v = (validate, settings.ls) if validate is not None and "q_ref" in validate else None
        ns = settings.null
        null = None
        if ns.kind == "montecarlo":
            null = MonteCarloNull(
                ns.replicates, ns.seed, settings.ls, lambda lg: _prepare(with_rest(prepare_log(lg), settings.ls), base, settings.ls), settings.replay_noise
            )
        if settings.replay_noise:
            sensor = decision_sensor(log, settings.ls, data, base, known, rows, plant_of)
        kept, judged = replay_decide(
            log,
            data,
            base,
            known,
            material,
            rows,
            plant_of,
            folds=settings.select.folds,
            alpha=replay_alpha(settings),
            validate=v,
            null=null,
            sensor_noise=settings.replay_noise,
            sensor=sensor,
        )
        verdicts += judged
        kept = kept[len(known) :]
    else:
        kept = material
    by_effect = {v.effect: v for v in verdicts}
    for step in selection.tried:
        for i, ev in enumerate(step):
            if ev.accepted and ev.effect in by_effect and not by_effect[ev.effect].accepted:
                step[i] = replace(ev, accepted=False, reason=f"{ev.reason}; {by_effect[ev.effect].reason}")
            elif ev.accepted and ev.effect in by_effect:
                step[i] = replace(ev, reason=f"{ev.reason}; {by_effect[ev.effect].reason}")
    for st in material:
        if st.level is not None and st.effect.id in by_effect:  # the closed loop's proposal: its verdict beside the inverse model's last word on it
            if (at := selection.last_at(st.effect.id)) is not None:
                k, i = at
                ev = selection.tried[k][i]
                selection.tried[k][i] = replace(ev, reason=f"{ev.reason}; proposed on the closed loop instead: {by_effect[st.effect.id].reason}")
    order = [s.effect.id for s in selection.steps] + [s.effect.id for s in material if s.level is not None]
    verdicts.sort(key=lambda v: order.index(v.effect))
    return kept, verdicts, sensor


def _noise_objection(refit: Refit, log: RunLog, ls: LSSettings, sensor: dict[str, Any], before: float, known: list[Step], hold: float) -> str | None:
    """Why ``refit`` is not kept: replayed with the deciding replays' sensor noise, it does not beat the inverse model's estimate
    (its output error so, ``before`` %); else ``None``.

    The refit itself replays noise-free (a value estimated on noisy replays is pulled by the replay's own answer to
    its noise: a 1.0 ms lag to 0.71-0.84 ms, the corpus's lags 14-17 % off against 0.1-5 %); whether its estimate
    is kept is decided as the replay decides effects. Measured on the corpus's trapezoid spring with a force
    disturbance: DIDIM lowered the noise-free output error 2.74 % -> 2.65 % with the spring 21 % off; replayed with
    the noise, the inverse model's estimate gives 2.25 % and DIDIM's 2.33 %, and the inverse model's spring (0.7 %
    off) is kept.
    """
    assert refit.theta is not None
    after = noisy_output_error(log, ls, *model_parameters([*known, *refit.steps], refit.names, refit.theta, np.zeros((len(refit.theta),) * 2), hold), sensor)
    if after < before:
        return None
    return f"replayed with the recording's sensor noise, as the decisions are, its output error does not fall ({before:.3g} % -> {after:.3g} %)"


def without_last(kept: list[Step], verdicts: list[ReplayVerdict], why: str) -> tuple[list[Step], list[ReplayVerdict]]:
    """``kept`` without its last effect, and ``verdicts`` with that effect's accepting verdict turned into a rejection that says ``why``."""
    gone = kept[-1].effect.id
    return kept[:-1], [replace(v, accepted=False, reason=f"{v.reason}; {why}") if v.effect == gone and v.accepted else v for v in verdicts]


NOT_REFITTED = (
    "not refitted on the closed loop: the Stribeck level and vs found at the dwells are closed-loop estimates already, of the creep "
    "the sensor noise drives there, which the refit's noise-free replays do not have "
    "(the other parameters: the inverse model's, with that friction taken off the force)"
)
"""Why a Stribeck friction found at the dwells keeps its closed-loop search's estimate (when the open-loop segments' fit is not used)."""


def _segment_refit(
    log: RunLog, data: IDIMData, base: Model, rows: np.ndarray, ls: LSSettings, known: list[Step], kept: list[Step], hold: float
) -> tuple[Refit, str | None]:
    """The Stribeck friction found at the dwells (the last of ``kept``, its level held), refitted on the open-loop segments.

    Every linear parameter of the model, the Stribeck level, and the nonlinear value of each kept effect searched on a
    log scale (Stribeck ``vs``, a ripple's period, ...; a pair of values, or one on a linear scale, is held) are fitted
    by :func:`ilic_cli.diagnosis.segments.fit_segments`, the recorded force driving the plant
    (:func:`plant.closed_loop.simulate_segments`); started from the inverse model's fit and the closed-loop search's
    level and ``vs``. The fit replaces those when its residual is the sensor's noise
    (:attr:`~ilic_cli.diagnosis.segments.SegmentFit.consistent`), the model it gives is a plant of the effects it
    names, and no value is on the edge of its effect's grid; else the search's estimate is kept, and the reason says
    which failed. Only a log whose force is the drive's held command is fitted so.

    Returns the refit and, when the fit's residual is the sensor's noise but its Stribeck level is not
    :data:`~ilic_cli.diagnosis.segments.LEVEL_Z` standard deviations above zero, why the recording refutes the
    friction the closed-loop search found (else ``None``).
    """
    from plant.closed_loop import simulate_segments
    from plant.dynamics import plant_model
    from plant.replay import measured_state

    st = kept[-1]
    assert st.level is not None
    W, y, names = system(data, base, [*known, *kept], rows)
    theta = solve(W, y, names, sigma=ls.sigma).theta
    if tau_sensor(log) != "command":
        return Refit(False, NOT_REFITTED + "; the recorded force is not the drive's command, so no open-loop fit", list(kept), names), None
    fs = log.fs_hz
    model = [*kept[:-1], Step(st.effect, st.value)]
    free = [k for k, s in enumerate(model) if s.effect.scan is not None and s.effect.scan.log and isinstance(s.value, float)]
    names_fit = (*names, *st.effect.column_names)
    n_lin = len(names_fit)
    p0 = np.r_[theta, st.level, [np.log(float(model[k].value)) for k in free]]
    tau = np.asarray(log["tau"], dtype=np.float64)
    zero = np.zeros((n_lin, n_lin))

    def model_at(p: np.ndarray) -> list[Step]:
        values = dict(zip(free, np.exp(p[n_lin:]), strict=True))
        return [*known, *(Step(s.effect, float(values[k])) if k in values else s for k, s in enumerate(model))]

    q = np.asarray(log["q"], dtype=np.float64)
    noise = measurement_std(*position_noise(q, fs, ls))
    length = int(round(segments.SEGMENT_S * fs))
    starts = segments.segment_starts(len(q), length, ls.trim)

    def simulate(p: np.ndarray, states: np.ndarray) -> np.ndarray:
        rigid, effects = model_parameters(model_at(p), names_fit, p[:n_lin], zero, hold)
        params, eff = plant_model(rigid, effects)
        return simulate_segments(params=params, effects=eff, command=tau, fs_hz=fs, starts=starts, length=length, x0=states, substeps=segments.SUBSTEPS)

    try:
        fit = segments.fit_segments(
            q,
            np.column_stack(measured_state(q, fs)),
            simulate,
            p0,
            np.r_[1e-3 * np.maximum(np.abs(p0[:n_lin]), 1.0), np.full(len(free), 0.01)],
            (*names_fit, *(f"log_{scan.name}" for k in free if (scan := model[k].effect.scan) is not None)),
            noise,
            starts=starts,
            length=length,
            max_step=np.r_[np.full(n_lin, np.inf), np.full(len(free), 0.5)],
        )
    except IlicError as exc:  # a sensitivity's step that gives no plant, a segment that diverges: the search's estimate stands
        return Refit(False, f"{NOT_REFITTED}; the {segments.METHOD} failed: {exc.problem}", list(kept), names), None
    what = (
        f"{fit.segments} segments of {segments.SEGMENT_S:g} s driven by the recorded force, residual {1e6 * fit.rms_m:.3g} um RMS "
        f"for a sensor noise of {1e6 * noise:.3g} um (from {1e6 * fit.rms_start_m:.3g} um), {fit.iterations} iterations"
    )
    final = model_at(fit.values)
    theta_fit = fit.values[:n_lin]
    at = names_fit.index(st.effect.column_names[0])
    level, level_std = float(theta_fit[at]), float(fit.std[at])
    if fit.consistent and not level > segments.LEVEL_Z * level_std:
        refuted = (
            f"refuted by the {segments.METHOD} ({what}): the residual is the sensor's noise, "
            f"and the level it gives Stribeck friction, {level:.3g} +- {level_std:.2g} N, "
            f"is not {segments.LEVEL_Z:g} standard deviations above zero (the closed-loop search's {st.level[0]:.3g} N is not the recording's)"
        )
        return Refit(False, refuted, list(kept), names, segments=fit), refuted
    problem = plant_problem(final[len(known) :], names_fit, theta_fit)
    edges = [e for k in free if (e := _edge_of(final[len(known) + k], data, fs))]
    why = (
        "it did not converge"
        if not fit.converged
        else f"its residual is more than {segments.NOISE_FACTOR:g} times the sensor's noise (the recorded force does not explain the motion alone)"
        if not fit.consistent
        else f"its model is no plant ({problem})"
        if problem
        else "; ".join(edges)
        if edges
        else None
    )
    if why is not None:
        return Refit(False, f"{NOT_REFITTED}; the {segments.METHOD} ({what}) is not used: {why}", list(kept), names, segments=fit), None
    std = fit.std[n_lin:]
    return Refit(
        True,
        f"{what}: the residual is the sensor's noise, so the estimate is the recording's",
        final[len(known) :],
        names_fit,
        theta_fit,
        fit.cov[:n_lin, :n_lin],
        value_std={model[k].effect.id: float(final[len(known) + k].value) * float(s) for k, s in zip(free, std, strict=True)},
        method=segments.METHOD,
        segments=fit,
    ), None


def _edge_of(step: Step, data: IDIMData, fs: float) -> str | None:
    """Why ``step``'s value is on the edge of its effect's grid (:func:`ilic_cli.diagnosis.select.at_edge`), else ``None``."""
    assert step.effect.scan is not None
    return at_edge(step.effect, step.effect.scan.grid(data.kin, fs), step.value)


def _closed_loop_proposal(
    log: RunLog, data: IDIMData, base: Model, proposed: list[Step], rows: np.ndarray, settings: DiagnoseSettings, selection: SelectionResult
) -> Step | None:
    """Stribeck friction proposed on the closed loop (:mod:`ilic_cli.diagnosis.dwell`), or ``None``.

    Only when neither the model file nor the inverse model has it (``proposed`` are the model file's effects and
    the inverse model's proposals, material or not), and either the reference dwells or the inverse model's last
    word on it was that its F-test passed and its held-out test did not confirm it
    (:meth:`~ilic_cli.diagnosis.select.SelectionResult.unconfirmed`).
    """
    effect = EFFECTS["stribeck"]
    if effect.id not in settings.select.effects or effect.scan is None or any(s.effect.id == effect.id for s in proposed):
        return None
    if not selection.unconfirmed(effect.id) and not dwell.dwells(np.asarray(log["q_ref"]), log.fs_hz):
        return None
    fit = fit_system(data, base, [], rows)  # the rigid Coulomb level: the scale of the levels searched (each fold's own, there)
    fc = dwell.coulomb_N(fit.names, fit.theta)
    if fc is None or not applicable(effect, fit.names):
        return None
    return dwell.proposal(effect.scan.grid(data.kin, data.fs_hz), fc)


def replay_alpha(settings: DiagnoseSettings) -> float:
    """Level of the replay's test: ``settings.null.alpha``, else the selection's held-out level."""
    return settings.null.alpha if settings.null.alpha is not None else settings.select.alpha_heldout


def _with_std(res: LSResult, cov: np.ndarray) -> LSResult:
    """``res`` with standard deviations from the autocorrelation-aware covariance."""
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(res.theta != 0, 100.0 * std / np.abs(res.theta), np.inf)
    return replace(res, std=std, rel_std_pct=rel)


def model_parameters(
    steps: list[Step], names: tuple[str, ...], values: np.ndarray, cov: np.ndarray, hold_s: float = 0.0
) -> tuple[dict[str, float], dict[str, Any]]:
    """Rigid parameters (every rigid column of the fit, whatever the structure) and plant effects, for the model file.

    ``hold_s``: see :func:`effect_fit`.
    """
    rigid = {n: float(v) for n, v in zip(names, values, strict=True) if n in PARAMETERS}
    effects: dict[str, Any] = {}
    for st in steps:
        _, plant, _ = effect_fit(st, names, values, cov, None, hold_s)
        if st.effect.plant and plant is not None:
            effects.update(st.effect.plant_entries(plant, hold_s))
    return rigid, effects


def model_std(
    steps: list[Step], names: tuple[str, ...], values: np.ndarray, cov: np.ndarray, hold_s: float, value_std: dict[str, float | None]
) -> dict[str, Any]:
    """Standard deviations of the model file's values (rigid parameters, and each effect's plant parameters that have one).

    ``value_std``: effect id -> standard deviation of its nonlinear value.
    """
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    rigid = {n: float(s) for n, s in zip(names, std, strict=True) if n in PARAMETERS}
    effects: dict[str, Any] = {}
    for st in steps:
        est, plant, _ = effect_fit(st, names, values, cov, value_std.get(st.effect.id), hold_s)
        if st.effect.plant and plant is not None and st.effect.id in st.effect.plant_entries(plant, hold_s):  # a realisation's own values have none
            effects[st.effect.id] = {k: est[k].std for k in plant if k in est and est[k].std is not None}
    return {"parameters": rigid, "effects": effects}
