"""``ilic diagnose`` logic: the stages propose -> decide -> refit -> report, as one pipeline (:func:`diagnose` -> :class:`Diagnosis`).

Takes run logs (no file I/O here) and returns a :class:`Diagnosis`; the
command module renders it (:mod:`ilic_cli.diagnosis.report`) and plots it
(:mod:`ilic_cli.diagnosis.plots`). The stages: :mod:`~ilic_cli.diagnosis.propose`,
:mod:`~ilic_cli.diagnosis.decide`, :mod:`~ilic_cli.diagnosis.refit`; here the findings and the model file
are assembled from their typed results.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.compare import SimulationComparison, compare_simulation
from ilic_cli.diagnosis.decide import Decision, ReplayVerdict, decide, proposal_plant, replay_drift, without_last
from ilic_cli.diagnosis.drift import DriftResult, GivenDrift, fitted_with, with_drift
from ilic_cli.diagnosis.drift import evaluation as drift_evaluation
from ilic_cli.diagnosis.fold_plant import fitted_plant
from ilic_cli.diagnosis.friction_law import FrictionLaw
from ilic_cli.diagnosis.law_refit import refit_with_the_law
from ilic_cli.diagnosis.locate import Region, force_lag, locate
from ilic_cli.diagnosis.loop_read import Model as Model_
from ilic_cli.diagnosis.loop_read import lag_if_inside, read_the_loop
from ilic_cli.diagnosis.model_values import effect_fit, model_parameters, model_std, steps_from_effects
from ilic_cli.diagnosis.propose import Proposal, base_model, propose
from ilic_cli.diagnosis.propose import prepare_system as _prepare
from ilic_cli.diagnosis.refit import NOT_REFITTED, FinalFit, Refit, drift_on, final_fit, refit_at_dwells, with_std
from ilic_cli.diagnosis.refit import refit as refit_stage
from ilic_cli.diagnosis.refit import segment_refit as _segment_refit
from ilic_cli.diagnosis.rivals import finding_title, indistinct_note
from ilic_cli.diagnosis.select import Evaluation, Selection, validation_error
from ilic_cli.diagnosis.settings import DiagnoseSettings, DiagnosisSettings, replay_alpha
from ilic_cli.diagnosis.stats import folds_either_side, heldout_errors
from ilic_cli.diagnosis.strategies import strategy_of
from ilic_cli.diagnosis.system import change_time, system
from ilic_cli.diagnosis.verdicts import Verdict
from ilic_cli.effects import EFFECTS, Effect, Estimate, unit_of
from ilic_cli.errors import ParameterError
from ilic_cli.lsq import LSResult, relative_error_pct, robust_covariance
from ilic_cli.modelfile import model_document
from ilic_cli.parameters import PARAMETERS, weight
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import DRIVE_LAGS
from ilic_cli.simulation.timing import ControlTiming
from ilic_cli.usable import UsableRows, usable_rows

__all__ = [  # the pipeline, and the names its callers import from here as before the stages were split out
    "NOT_REFITTED",
    "DiagnoseSettings",
    "DiagnosisSettings",
    "Diagnosis",
    "Finding",
    "Refit",
    "_prepare",
    "_segment_refit",
    "base_model",
    "diagnose",
    "effect_fit",
    "model_parameters",
    "model_std",
    "replay_alpha",
    "steps_from_effects",
    "without_last",
]


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
    if_inside: dict[str, float] = field(default_factory=dict)  # the values were the PD law inside the dynamics (loop_read.lag_if_inside)

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
            **({"indistinct_from": self.evidence.indistinct_from} if self.evidence.indistinct_from is not None else {}),
            **({"if_the_pd_law_acts_inside_the_dynamics": self.if_inside} if self.if_inside else {}),
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
    settings: DiagnosisSettings
    simulation: SimulationComparison | None = None
    refit: Refit | None = None
    validation_source: str | None = None
    warnings: list[str] = field(default_factory=list)
    residual: dict[str, np.ndarray] = field(default_factory=dict)
    timing: ControlTiming | None = None
    friction_law: FrictionLaw | None = None
    """The friction law near zero speed the replays ran (:mod:`ilic_cli.diagnosis.friction_law`), ``None`` when nothing was replayed."""
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
    def unjudged(self) -> list[str]:
        """Effects proposed past the inverse model's tests and materiality that no replay could judge, since their fit is no
        plant (:attr:`~ilic_cli.diagnosis.verdicts.Verdict.NO_PLANT`: a flexibility's load above the axis's inertia on the
        folds), and that are not findings: neither named nor ruled out (corpus s21512, a flexibility of F-test p = 1e-125)."""
        named = {f.effect.id for f in self.findings}
        return [v.effect for v in self.decisions if v.verdict is Verdict.NO_PLANT and v.effect not in named]

    @property
    def unjudged_titles(self) -> list[str]:
        """The catalogue's titles of :attr:`unjudged` (an id the catalogue does not have, as it is)."""
        return [EFFECTS[e].title if e in EFFECTS else e for e in self.unjudged]

    @property
    def conclusion(self) -> str:
        pending = "; not judged (its fit is no plant): " + ", ".join(self.unjudged_titles) if self.unjudged else ""
        if not self.findings:
            return ("undecided" if self.unjudged else "no significant mismatch") + pending
        return "left out: " + ", ".join(finding_title(f.effect, f.evidence) for f in self.findings) + pending

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "model": self.model,
            "sample_rate_hz": self.fs_hz,
            "joint_type": self.joint,
            "units": {n: unit_of(n, self.joint) for n in dict.fromkeys((*self.base.names, *self.augmented.names))},
            "rows_used": self.rows_used,
            "rows_total": self.rows_total,
            "usable_rows": None if self.usable is None else self.usable.to_dict(),
            "conclusion": self.conclusion,
            "not_judged": self.unjudged,
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
            "friction_law": None if self.friction_law is None else self.friction_law.to_dict(),
            "drift": None if self.drift is None else self.drift.to_dict(),
            "weight": None if self.weight is None else {k: v.to_dict() for k, v in self.weight.items()},
        }


@dataclass(frozen=True)
class Baseline:
    """The rigid baseline: the inverse model's fit of ``base + known`` (with standard deviations), and the values replayed as "before"."""

    W: np.ndarray
    y: np.ndarray
    names: tuple[str, ...]
    res: LSResult
    params: dict[str, float]
    effects: dict[str, Any]


def _baseline(prop: Proposal, model_doc: dict[str, Any] | None) -> Baseline:
    W0, y0, names0 = system(prop.data, prop.base, prop.known, prop.rows)
    res0 = prop.rigid  # the least squares of (W0, y0), fitted once by the proposal
    before_params = dict(model_doc["parameters"]) if model_doc else {n: float(v) for n, v in zip(names0, res0.theta, strict=True) if n in PARAMETERS}
    before_effects = dict(model_doc.get("effects", {})) if model_doc else {}
    return Baseline(W0, y0, names0, res0, before_params, before_effects)


def _timing_model(prop: Proposal, base: Baseline, model_doc: dict[str, Any] | None, lags: bool = False) -> tuple[dict[str, float], dict[str, Any]]:
    """The model the loop's timing is read with (:func:`ilic_cli.simulation.timing.recorded_loop`): the model file's, else the
    inverse model's proposal (its effects and drift fitted on the rows) but a drive lag, the rigid fit when it proposes nothing else.
    ``lags``: with a proposed drive lag (the friction law's model: the loop's timing read, the lag replayed at the sample).

    Read with the rigid fit, the timing of a loop acting within its sample absorbed what that fit misses: on logs of a
    12 kg axis and a 0.08 kg·m² joint simulated apart from ``ilic`` (the command acting at its sample), a third of a
    viscous warm-up or Stribeck friction moved the lag read to 0.28-0.53 of a period, and the replay, run with that lag,
    then rejected the warm-up the inverse model had found (held-out 7.4 % -> 7.7 %) and valued Stribeck's speed at a third.
    A proposed drive lag is left out: the timing is the lag a model without one replays with, and a model with one replays
    the loop acting at its sample (:data:`ilic_cli.simulation.replay.LAG_READ`), so the replay judges the lag against the timing.
    """
    steps = [st for st in prop.selection.steps if lags or st.effect.id not in DRIVE_LAGS]
    if model_doc is not None or (not steps and prop.drift is None):
        return base.params, base.effects
    return fitted_plant(prop.data, prop.base, [*prop.known, *steps], prop.rows, proposal_plant(prop), drift=prop.drift)


def diagnose(
    log: RunLog,
    *,
    settings: DiagnosisSettings | None = None,
    model_doc: dict[str, Any] | None = None,
    against: RunLog | None = None,
    validate: RunLog | None = None,
) -> Diagnosis:
    """Diagnose ``log``: what does the rigid model leave out?

    Parameters
    ----------
    log : RunLog
        The recording (``t``, ``q``, ``tau``; ``q_ref`` for the simulation comparison).
    settings : DiagnosisSettings, optional
        Default :class:`~ilic_cli.diagnosis.settings.DiagnosisSettings` (every effect of the catalogue, the measured tuning).
    model_doc : dict, optional
        A parsed model file (:func:`ilic_cli.modelfile.parse_model`): its
        structure is the starting model, its values are replayed as "before",
        and its effects are kept and not searched again.
    against : RunLog, optional
        A simulated log to compare the recording with (instead of replaying).
    validate : RunLog, optional
        Another recording: candidates must not raise the error there.
    """
    settings = settings or DiagnosisSettings()
    settings = replace(settings, ls=settings.ls.at_rate(log.fs_hz))  # the decimation of the log's rate, in every stage
    settings.null.check(replay_alpha(settings))
    prop = propose(log, settings, model_doc, validate)  # 1. propose
    log, validate = prop.log, prop.validate
    base = _baseline(prop, model_doc)
    res0 = base.res
    timing, law = None, None
    if settings.simulate and against is None and settings.pd_timing == "recorded":  # the replays run the loop that ran: its timing read from the recording
        given, bases = validate, [(prop, base)]  # each proposal's baseline, fitted once

        def baseline_of(p: Proposal) -> Baseline:
            b = next((b for q, b in bases if q is p), None)
            if b is None:
                b = _baseline(p, model_doc)
                bases.append((p, b))
            return b

        def models(p: Proposal) -> tuple[Model_, Model_, Model_]:
            b = baseline_of(p)
            return _timing_model(p, b, model_doc), _timing_model(p, b, model_doc, lags=True), (b.params, b.effects)

        prop, log, validate, timing, law = read_the_loop(prop, settings, log, validate, models, lambda lg: propose(lg, settings, model_doc, given))
        base = baseline_of(prop)  # proposed again under the loop read (a law inside the dynamics: no hold; a friction law: its sign)
        res0 = base.res
    decision = decide(log, prop, settings, validate, against)  # 2. decide
    replayed = settings.simulate and against is None and "q_ref" in log
    decision, at_dwells = refit_at_dwells(log, prop, decision, settings, replayed)  # 3. refit
    final = final_fit(prop, decision.kept, settings.ls, len(base.y))
    final = replace(final, drift=drift_on(prop, final, settings, decision))  # tested once: the refit's plant and the findings read it
    refit = refit_stage(log, prop, decision, final, at_dwells, settings, replayed)
    if law is not None:  # a smoothed law's speed and a Stribeck friction beside it, fitted at once
        refit, law, log = refit_with_the_law(log, prop, decision, final, refit, law, settings, replayed)
    res0 = with_std(res0, robust_covariance(base.W, base.y - base.W @ res0.theta))
    findings = _findings(prop, decision, final, refit)  # 4. the findings, the model file and the figures the report renders
    doc = _model_file(prop, decision, final, refit)
    if law is not None:  # the friction law the replays ran (none for stick/slip): ilic replay of the model file runs it too
        doc = law.in_model_file(doc)
    kept = [*prop.known, *decision.kept]
    judge = (lambda drift: replay_drift(log, prop, kept, drift, settings, decision.sensor)) if replayed else None
    diag = _assembled(prop, replace(base, res=res0), decision, final, refit, findings, doc, settings, timing, judge)
    diag.friction_law = law
    if settings.simulate or against is not None:
        _simulated(diag, log, prop, base, refit, against, settings)
    return diag


def _findings(prop: Proposal, decision: Decision, final: FinalFit, refit: Refit | None) -> list[Finding]:
    """One finding per kept effect: its estimates (the refit's when accepted), where the residual is structured, its evidence."""
    kept, selection, hold = decision.kept, prop.selection, prop.hold
    accepted = {ev.effect: ev for ev in selection.accepted}
    for st in kept:
        if st.level is not None:  # proposed on the closed loop: the evidence is the inverse model's last word on it, and the replay's verdict
            last = selection.last_word(st.effect.id)
            assert last is not None
            accepted[st.effect.id] = last
    refitted = refit is not None and refit.accepted and refit.theta is not None and refit.cov is not None
    final_steps = refit.steps if refit is not None and refit.accepted else kept
    findings = []
    for st, st_final in zip(kept, final_steps, strict=True):
        ev = accepted[st.effect.id]
        # a closed-loop proposal's vs is the folds' median, its spread theirs: the inverse model's standard deviation is not its own
        params, plant, note = effect_fit(st, final.names, final.res.theta, final.cov, st.value_std if st.level is not None else ev.value_std, hold, prop.joint)
        inverse = {} if st.level is not None else params  # a level held at a closed-loop estimate is no inverse-model estimate
        method = _proposer(st.effect) if st.level is not None else "IDIM-LS"
        notes = [s.reason for s in (refit.searches if refit is not None else []) if s.effect == st.effect.id]
        if refitted:
            assert refit is not None and refit.theta is not None and refit.cov is not None
            std = refit.value_std.get(st.effect.id) if st_final.value != st.value else st.value_std if st.level is not None else ev.value_std
            params, plant, note = effect_fit(st_final, refit.names, refit.theta, refit.cov, std, hold, prop.joint)
            if st_final.value != st.value or st.effect.columns:  # a value alone the refit held (a lag beside the segments' fit) is not its estimate
                method = refit.method
        params, inverse = st.effect.on_joint(params, prop.joint), st.effect.on_joint(inverse, prop.joint)  # in the joint's units
        findings.append(Finding(st.effect, params, plant, [], ev, "; ".join(n for n in [note, *notes, indistinct_note(st.effect, ev)] if n), method, inverse))
    return findings


def _proposer(effect: Effect) -> str:
    """The method of the identification strategy that proposed ``effect`` on the closed loop (:mod:`ilic_cli.diagnosis.strategies`)."""
    strategy = strategy_of(effect)
    assert strategy is not None  # a level is held only for a strategy's proposal
    return strategy.method


def _model_file(prop: Proposal, decision: Decision, final: FinalFit, refit: Refit | None) -> dict[str, Any]:
    """The model file of the diagnosis: the refit's estimates when accepted, else the inverse model's."""
    known, hold, src = prop.known, prop.hold, prop.prepared.source
    if refit is not None and refit.accepted and refit.theta is not None and refit.cov is not None:
        steps = [*known, *refit.steps]
        rigid, effects_doc = model_parameters(steps, refit.names, refit.theta, refit.cov, hold)
        std_doc = model_std(steps, refit.names, refit.theta, refit.cov, hold, refit.value_std)
        return model_document(prop.base.name, rigid, method=f"{refit.method} + ilic diagnose", effects=effects_doc, source=src or None, std=std_doc)
    rigid, effects_doc = model_parameters([*known, *decision.kept], final.names, final.res.theta, final.cov, hold)
    return model_document(prop.base.name, rigid, method="IDIM-LS + ilic diagnose", effects=effects_doc, source=src or None)


def _assembled(
    prop: Proposal,
    base: Baseline,
    decision: Decision,
    final: FinalFit,
    refit: Refit | None,
    findings: list[Finding],
    doc: dict[str, Any],
    settings: DiagnosisSettings,
    timing: ControlTiming | None,
    judge_drift: Callable[[GivenDrift], tuple[ReplayVerdict, dict[str, Any] | None]] | None = None,
) -> Diagnosis:
    """The :class:`Diagnosis`: the fit's figures before and after, where the rigid residual is structured, the drift, the weight.

    ``judge_drift``: the replay's word on a drift found on the rows (:func:`~ilic_cli.diagnosis.decide.replay_drift`), added to the
    decisions; a drift it does not keep is no finding, its reason the replay's. ``None``: the log is not replayed."""
    data, rows, fs, sel = prop.data, prop.rows, prop.prepared.fs_hz, prop.select
    W0, y0, res0, W1, y1, res1 = base.W, base.y, base.res, final.W, final.y, final.res
    folds = folds_either_side(data.t_dec[rows], change_time([*prop.known, *decision.kept]), sel.folds, sel.guard)
    h0, h1 = heldout_errors(W0, y0, folds), heldout_errors(W1, y1, folds)
    fit: dict[str, dict[str, float | None]] = {
        "relative_error_pct": {"before": res0.relative_error_pct, "after": res1.relative_error_pct},
        "heldout_relative_error_pct": {"before": relative_error_pct(y0, y0 - h0), "after": relative_error_pct(y1, y1 - h1)},
        "validation_relative_error_pct": {"before": None, "after": None},
        "simulation_force_relative_error_pct": {"before": None, "after": None},
    }
    if prop.vdata is not None:
        before, after = (validation_error(data, prop.vdata, prop.base, s) for s in (prop.known, [*prop.known, *decision.kept]))
        fit["validation_relative_error_pct"] = {"before": before, "after": after}
    # locate on the rigid residual (decimated rows) and the force lag
    dec, kin = data.decimate, data.kin
    assert kin.q is not None  # the residual's kinematics carry the position (located against it)
    td, qd_d, qdd_d, q_d = data.t_dec[rows], dec(kin.qd)[rows], dec(kin.qdd)[rows], dec(kin.q)[rows]
    e0, fitted = y0 - W0 @ res0.theta, W1 @ res1.theta
    q_unit = "rad" if prop.joint == "revolute" else "m"
    located = locate(e0, t=td, q=q_d, qd=qd_d, qdd=qdd_d, W=W0, fs_hz=fs / settings.ls.decimation, alpha=sel.alpha, q_unit=q_unit)
    located.append(force_lag(data.tau, np.asarray(prop.base.matrix(kin)) @ res0.theta[: len(prop.base.names)], fs))
    for f in findings:
        f.located = sorted([r for r in located if r.kind in f.effect.signature_kinds and r.significant], key=lambda r: r.p_value)
    # friction that changes over time, from per-window estimates
    origin = float(prop.log.t[0])  # the plant's drift starts with the log, not with its first row in motion
    assert final.drift is not None  # tested by diagnose once the final model is fitted
    drift_found = final.drift
    if drift_found.found and judge_drift is not None:
        verdict, sensor = judge_drift(GivenDrift(list(drift_found.findings), origin))
        decision = replace(decision, verdicts=[*decision.verdicts, verdict], sensor=sensor)
        if not verdict.accepted:
            drift_found = replace(drift_found, findings=[], reason=verdict.reason)
    if drift_found.found:  # the model after is the effects' and the drift's: its fitted force and residual too, as its figures
        fitted = fitted_with(td, W1, y1, final.names, drift_found.findings, origin)
        alike = "" if drift_found.alike is None else drift_found.alike.words(drift_found.findings[0].parameter)
        findings.append(
            Finding(EFFECTS["friction_drift"], drift_found.estimates(prop.joint), drift_found.plant_effect(), [], drift_evaluation(drift_found), alike)
        )
        doc = with_drift(doc, drift_found)
        fit["relative_error_pct"]["after"], fit["heldout_relative_error_pct"]["after"] = drift_found.relative_error_after_pct, drift_found.heldout_after_pct
    diag = Diagnosis(
        drift=drift_found,
        source=prop.prepared.source,
        model=prop.base.name,
        fs_hz=fs,
        rows_used=int(rows.sum()),
        rows_total=len(rows),
        base=res0,
        augmented=res1,
        findings=findings,
        fit=fit,
        located=located,
        tried=prop.selection.tried,
        decisions=decision.verdicts,
        model_file=doc,
        settings=settings,
        refit=refit,
        validation_source=None if prop.validate is None else str(prop.validate.provenance.source or ""),
        warnings=prop.warnings,
        usable=replace(usable_rows(prop.prepared, settings.ls), hold_s=prop.hold),
        joint=prop.joint,
        residual={"t": td, "q": q_d, "qd": qd_d, "before": e0, "after": y1 - fitted, "y": y0, "y_before": W0 @ res0.theta, "y_after": fitted},
    )
    _weighed(diag, prop, final)
    if timing is not None:  # a flexibility refused for its negative mass (its only impossibility) says what the drive lag is
        timing.negative_flexibility = any(ev.effect == "flexibility" and ev.outcome is Selection.IMPOSSIBLE for step in prop.selection.tried for ev in step)
        timing.lag_found = any(st.effect.id in DRIVE_LAGS for st in decision.kept)  # its replays act at the sample (replay.LAG_READ)
        for f in (f for f in diag.findings if f.effect.id == "delay"):  # the lag a law inside the dynamics would have instead
            if (inside := lag_if_inside(timing, prop.data.fs_hz, f.parameters["delay"].value)) is not None:
                f.if_inside, f.note = {"delay": inside[0]}, "; ".join(n for n in (f.note, inside[1]) if n)
    diag.timing = timing
    if any(v.force_before is not None for v in decision.verdicts):
        diag.replay_sensor = decision.sensor
    return diag


def _weighed(diag: Diagnosis, prop: Proposal, final: FinalFit) -> None:
    """A vertical axis: its constant force is the load's weight, not an offset (in place)."""
    if prop.log.sensor.vertical and "offset" in final.names:
        i = final.names.index("offset")
        diag.weight = {k: Estimate(*v) for k, v in weight(float(final.res.theta[i]), float(np.sqrt(max(final.cov[i, i], 0.0)))).items()}
        for f in (f for f in diag.findings if f.effect.id == "offset"):
            f.parameters, f.note = dict(diag.weight), "a vertical axis: the constant force is the load's weight"


def _simulated(diag: Diagnosis, log: RunLog, prop: Proposal, base: Baseline, refit: Refit | None, against: RunLog | None, settings: DiagnosisSettings) -> None:
    """The simulation against the recording, before and after (in place): the replay, or the log ``against``."""
    doc = diag.model_file
    try:
        diag.simulation = compare_simulation(
            log,
            prop.data,
            prop.rows,
            base.params,
            base.effects,
            doc["parameters"],
            doc["effects"] if diag.findings else None,
            against=against,
            ls=settings.ls,
            alpha=prop.select.alpha,
            after_sim=None if refit is None else refit.simulated,  # the replay of the model file's plant, when the refit made it
        )
    except ParameterError as exc:
        diag.warnings.append(f"no simulation comparison: the fitted model is not a valid plant ({exc.problem})")
    if diag.simulation is not None:
        diag.fit["simulation_force_relative_error_pct"] = {"before": diag.simulation.before.get("force"), "after": (diag.simulation.after or {}).get("force")}
        if diag.simulation.note:
            diag.warnings.append(diag.simulation.note)
