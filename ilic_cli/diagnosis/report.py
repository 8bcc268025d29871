"""Render a :class:`~ilic_cli.diagnosis.core.Diagnosis` as JSON or Markdown in plain words."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

import ilic_cli.diagnosis.dwell as dwell
import ilic_cli.diagnosis.segments as segments
from ilic_cli.diagnosis.compare import SimulationComparison
from ilic_cli.diagnosis.core import Diagnosis, Finding
from ilic_cli.diagnosis.fits import CLOSED_LOOP_SPREAD, INVERSE_METHOD, METHOD, OE_METHOD
from ilic_cli.diagnosis.locate import Region
from ilic_cli.diagnosis.rivals import finding_title, indistinct_note
from ilic_cli.diagnosis.verdicts import PROPOSED_BY_DRIFT, PROPOSED_BY_INVERSE, RefitOutcome
from ilic_cli.effects import Estimate
from ilic_cli.jointlog import position_unit
from ilic_cli.parameters import PARAMETERS


def to_json(diag: Diagnosis) -> str:
    """The JSON document (``findings``, ``fit``, ...), strict JSON (no NaN)."""
    return json.dumps(_clean(diag.to_dict()), indent=2, allow_nan=False)


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if hasattr(x, "item") and callable(x.item):
        return _clean(x.item())
    return x


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3g} %" if x < 0.1 else f"{x:.2f} %"


def _num(x: float, unit: str = "") -> str:
    s = f"{x:.4g}"
    return f"{s} {unit}".strip()


def _region_words(r: Region, force_unit: str = "N") -> str:
    if r.kind in ("velocity", "position", "time", "acceleration", "reversal"):
        u = force_unit
        return f"{r.label}: mean residual {r.mean:+.3g} {u} (standard error {r.se:.2g} {u}, {r.rows} rows, p = {r.p_value:.2g})"
    if r.kind == "drift":
        return f"{r.label} (F = {r.statistic:.3g}, p = {r.p_value:.2g})"
    if r.kind == "frequency":
        return f"{r.label} ({r.statistic:.3g} times the background, p = {r.p_value:.2g})"
    return f"{r.label} (correlation {r.statistic:.4f}, p = {r.p_value:.2g})"


def _where(label: str) -> str:
    """``decelerating`` -> ``while decelerating``; ``velocity in [..]`` -> ``at velocity in [..]``."""
    return f"while {label}" if label in ("accelerating", "decelerating", "at constant velocity", "constant velocity") else f"at {label}"


def _std(est: Estimate) -> str:
    return "" if est.std is None or not math.isfinite(est.std) else f"{est.std:.3g}"


def _undetermined(params: dict[str, Estimate]) -> str:
    """The estimates the log does not determine (:attr:`Estimate.determined`), said after the finding; ``""``: none."""
    loose = [
        f"{n} = {e.value:.4g} ± {_num(e.std, e.unit)}" if e.std is not None and math.isfinite(e.std) else f"{n} (no finite std)"
        for n, e in params.items()
        if not e.determined
    ]
    if not loose:
        return ""
    return f"; not determined by this log, its 95 % interval holding 0: {', '.join(loose)}"


def _estimates_table(params: dict[str, Estimate], inverse: dict[str, Estimate], method: str, at_dwells: bool = True) -> list[str]:
    """The finding's estimates: the method's, and the inverse model's beside them when the method is another.

    ``at_dwells``: a closed-loop proposal's (:data:`ilic_cli.diagnosis.dwell.METHOD`) was made at the reference's dwells,
    where the inverse model's estimate is outside the effect's physics; else the inverse model's held-out test did not confirm its own.
    """
    if method == "IDIM-LS" or not inverse:
        none = "has no estimate of it inside its physics" if at_dwells else "has one that its held-out test did not confirm"
        by = "the inverse model (IDIM-LS)" if method == "IDIM-LS" else f"the {method} (the inverse model {none})"
        if method == dwell.METHOD:
            by += f"; std: {dwell.SPREAD}"
        elif method == segments.METHOD:
            by += f"; std: {segments.SPREAD}"
        lines = [f"Estimated by {by}.", "", "| parameter | value | std |", "| --- | --- | --- |"]
        return lines + [f"| {n} | {_num(e.value, e.unit)} | {_std(e)} |" for n, e in params.items()] + [""]
    spread = f"; std: {CLOSED_LOOP_SPREAD}" if method in (METHOD, OE_METHOD) else ""
    lines = [
        f"Estimated by the {method} (the inverse model's estimate beside it){spread}.",
        "",
        "| parameter | closed loop | std | inverse model | std |",
        "| --- | --- | --- | --- | --- |",
    ]
    for n, e in params.items():
        i = inverse.get(n)
        lines.append(f"| {n} | {_num(e.value, e.unit)} | {_std(e)} | {'' if i is None else _num(i.value, i.unit)} | {'' if i is None else _std(i)} |")
    return [*lines, ""]


def _on_loop(diag: Diagnosis, f: Finding) -> bool:
    """Whether ``f`` was proposed on the closed loop (:mod:`ilic_cli.diagnosis.dwell`), not by the inverse model nor the drift test."""
    return any(v.effect == f.effect.id and v.proposed_by not in (PROPOSED_BY_INVERSE, PROPOSED_BY_DRIFT) for v in diag.decisions)


def _at_dwells(diag: Diagnosis, f: Finding) -> bool:
    """Whether ``f`` was proposed on the closed loop at the reference's dwells (not for want of the inverse model's held-out test at
    :attr:`~ilic_cli.diagnosis.select.SelectSettings.alpha_confirm`: :func:`ilic_cli.diagnosis.propose.closed_loop_proposal`)."""
    return _on_loop(diag, f) and not f.evidence.unconfirmed_at(diag.settings.select.alpha_confirm)


def to_markdown(diag: Diagnosis) -> str:
    """A report in plain words, then the tables."""
    force_unit = PARAMETERS["Fc"].unit_for(diag.joint)  # N, or N·m on a revolute joint
    at_dwells = any(_at_dwells(diag, f) for f in diag.findings)  # Stribeck found by the closed loop at the dwells
    lines = [f"# Diagnosis of {diag.source or 'the log'}", ""]
    lines += _summary(diag, force_unit, at_dwells)
    lines += _estimates_and_simulation(diag, at_dwells)
    lines += [_rows_sentence(diag), "", "## Findings", ""]
    if not diag.findings:
        lines += ["None.", ""]
    for i, f in enumerate(diag.findings, 1):
        lines += _finding_section(diag, i, f, force_unit)
    lines += ["## Where the rigid model's residual is structured", ""]
    sig = [r for r in diag.located if r.significant]
    lines += [f"- {_region_words(r, force_unit)}" for r in sorted(sig, key=lambda r: r.p_value)[:12]] or ["- nowhere (no significant region)"]
    lines.append("")
    sim = diag.simulation
    if sim is not None and sim.located:
        s_sig = [r for r in sim.located if r.significant]
        lines += ["## Where the simulation differs from the recording (force)", ""]
        lines += [f"- {_region_words(r, force_unit)}" for r in sorted(s_sig, key=lambda r: r.p_value)[:8]] or ["- nowhere (no significant region)"]
        lines.append("")
    if diag.decisions:
        lines += _decisions_table(diag)
    lines += ["## Candidates tried", "", "| step | effect | F | p (adjusted) | held out before -> after | decision |", "| --- | --- | --- | --- | --- | --- |"]
    for k, step in enumerate(diag.tried, 1):
        for ev in step:
            ho_s = "" if ev.heldout_before_pct is None else f"{_pct(ev.heldout_before_pct)} -> {_pct(ev.heldout_after_pct)}"
            lines.append(f"| {k} | {ev.effect} | {ev.test.F:.3g} | {ev.test.p_adjusted:.2g} | {ho_s} | {ev.reason} |")
    lines.append("")
    if diag.warnings:
        lines += ["## Warnings", ""] + [f"- {w}" for w in diag.warnings] + [""]
    return "\n".join(lines)


def _unjudged(diag: Diagnosis) -> str:
    """What the inverse model proposed that no replay could judge (:attr:`Diagnosis.unjudged`), as a sentence, or ``""``."""
    if not diag.unjudged:
        return ""
    return (
        f"the inverse model proposes {', '.join(diag.unjudged_titles)} (its F-test and held-out test passed: see the candidates "
        "below), but its fit is no plant on the held-out folds, so no replay can judge it: it is neither named nor ruled out"
    )


def _summary(diag: Diagnosis, force_unit: str, at_dwells: bool) -> list[str]:
    """The first paragraph: no mismatch, or what was left out and the fit before and after."""
    fit = diag.fit
    rel = fit["relative_error_pct"]
    ho = fit["heldout_relative_error_pct"]
    unjudged = _unjudged(diag)
    if not diag.findings:
        judged = f" ({len(diag.decisions)} proposed, none material or kept by the replay: see below)" if diag.decisions else ""
        head = (
            f"Undecided: {unjudged}. Nothing else passed the F-test, the held-out test, materiality and the replay"
            if unjudged
            else f"No significant mismatch: none of the {len(diag.tried[0]) if diag.tried else 0} effects of the catalogue passed the "
            f"F-test, the held-out test, materiality and the replay{judged}"
        )
        return [f"{head}. The rigid model ({diag.model}) explains the force to {_pct(rel['before'])} (held out: {_pct(ho['before'])}).", ""]
    lines = [f"- Not judged: {unjudged}."] if unjudged else []
    for f in diag.findings:
        where = ""
        if f.located:
            r = f.located[0]
            structured = f"The residual is structured {_where(r.label)} (mean {r.mean:+.3g} {force_unit}). "
            where = structured if math.isfinite(r.mean) else f"The residual shows a {r.label}. "
        other = f" {indistinct_note(f.effect, f.evidence)}." if f.evidence.indistinct_from is not None else ""
        if f.effect.id == "friction_drift" and diag.drift is not None and (alike := diag.drift.alike) is not None:  # the coefficient the rows cannot tell
            said = alike.cannot_tell(diag.drift.findings[0].parameter)
            other = f" {said[0].upper()}{said[1:]}."
        lines.append(f"- {where}Left out: {f.effect.describe(f.parameters)}{_undetermined(f.parameters)}. {f.effect.explanation}{other}")
    lines += [
        "",
        f"Relative force error {_pct(rel['before'])} -> {_pct(rel['after'])} (held out: {_pct(ho['before'])} -> {_pct(ho['after'])})"
        + (
            ": the inverse model's figures, which Stribeck friction at the dwells need not lower, since its filtered kinematics "
            "do not resolve the stick and break-away there (why the closed loop proposes it; the replay decides)."
            if at_dwells
            else "."
        ),
    ]
    v = fit.get("validation_relative_error_pct") or {}
    if v.get("before") is not None:
        lines.append(f"On the validation log {diag.validation_source}: {_pct(v['before'])} -> {_pct(v['after'])}.")
    lines.append("")
    return lines


def _estimates_and_simulation(diag: Diagnosis, at_dwells: bool) -> list[str]:
    """Whose estimates the report gives (the refit's or the inverse model's, and why), the simulation against the recording,
    a vertical axis's weight and the control timing."""
    lines: list[str] = []
    if diag.refit is not None:
        how = "the closed-loop refit's" if diag.refit.accepted else "the inverse model's (IDIM-LS)"
        if diag.refit.accepted and diag.refit.method == segments.METHOD:
            how = f"the {segments.METHOD}'s"
        if diag.refit.accepted and diag.refit.outcome is RefitOutcome.DRIFT_VALUES:
            how = f"the {INVERSE_METHOD}'s"
        if not diag.refit.accepted and any(f.method == dwell.METHOD for f in diag.findings):
            how = f"Stribeck friction's from the {dwell.METHOD}, the rest the inverse model's (IDIM-LS)"
        meaning = (
            " The closed-loop output error is the replayed force against the recorded one, in the inverse model's band."
            if diag.refit.outcome.quotes_output_error
            else ""
        )
        lines += [f"Estimates: {how}; {diag.refit.reason}.{meaning}", ""]
    sim = diag.simulation
    if sim is not None and sim.before:
        lines += [
            simulation_sentence(sim)
            + (
                " This replay is noise-free, and Stribeck friction at the dwells shows in the creep the sensor noise drives there: "
                "the replays that decided carry that noise (their figures below)."
                if at_dwells
                else ""
            ),
            "",
        ]
    if diag.weight is not None:  # a vertical axis (the log says so): the constant force is a weight
        w, m = diag.weight["weight"], diag.weight["implied_mass"]
        lines += [f"Vertical axis: the constant force is the load's weight, {w.value:.4g} N (std {w.std:.2g} N): an implied mass of {m.value:.4g} kg.", ""]
    timing = diag.timing.sentence() if diag.timing is not None else ""
    if timing:
        lines += [f"Control timing: {timing}.", ""]
    law = diag.friction_law.sentence() if diag.friction_law is not None else ""
    if law:
        lines += [f"Friction near zero speed: {law}.", ""]
    return lines


def _finding_section(diag: Diagnosis, i: int, f: Finding, force_unit: str) -> list[str]:
    """The section of finding ``i``: its physics, its estimates, its evidence, where it is located."""
    ev = f.evidence
    lines = [
        f"### {i}. `{f.effect.id}`: {finding_title(f.effect, ev)}",
        "",
        f"{f.effect.explanation}",
        "",
        f"Form: {f.effect.form}. Signature: {f.effect.signature}.",
        "",
    ]
    lines += _estimates_table(f.parameters, f.inverse_parameters, f.method, _at_dwells(diag, f))
    if _on_loop(diag, f):
        verdict = next((v.reason for v in diag.decisions if v.effect == f.effect.id), "")
        why = (
            "proposed on the closed loop at the reference's dwells, where the inverse model cannot see it (its level there is "
            "outside the effect's physics: see the candidates tried)"
            if _at_dwells(diag, f)
            else (
                f"proposed on the closed loop, since the inverse model's F-test finds it (p = {ev.test.p_adjusted:.2g}) but its held-out test "
                f"does not confirm it at the replay's level (p = {ev.heldout_p_value:.2g}): on closed-loop data the command answers the noise its filtered "
                "kinematics carry, so its estimate there is biased"
            )
        )
        lines += [f"Evidence: {why}; {verdict}.", ""]
        lines += ["Located:", ""] + [f"- {_region_words(r, force_unit)}" for r in f.located[:5]] + [""] if f.located else []
        lines += [f"Note: {f.note}.", ""] if f.note else []
        return lines
    lines += [
        f"Evidence: F = {ev.test.F:.4g} ({ev.test.df1}, {ev.test.df2} dof, AR({ev.test.ar_order})-prewhitened), "
        f"p = {ev.test.p_value:.3g}, Bonferroni x{ev.test.trials} -> {ev.test.p_adjusted:.3g}; "
        f"held-out error {_pct(ev.heldout_before_pct)} -> {_pct(ev.heldout_after_pct)} (Diebold-Mariano p = {ev.heldout_p_value:.3g}).",
        "",
    ]
    if f.located:
        lines += ["Located:", ""] + [f"- {_region_words(r, force_unit)}" for r in f.located[:5]] + [""]
    if f.note:
        lines += [f"Note: {f.note}.", ""]
    return lines


def _decisions_table(diag: Diagnosis) -> list[str]:
    """The table of the decisions by materiality and the replay, with the replay's test and the sensor noise its replays carried."""
    lines = ["## Proposed by the inverse model, decided by materiality and the replay", ""]
    ns = diag.settings.null
    if ns.kind == "montecarlo":
        lines += [
            f"The replay's test: a Monte-Carlo null, B = {ns.replicates} replicates of the kept model simulated in closed loop with the log's "
            f"noise model (seed {ns.seed}); p = (1 + #{{T_b >= T_obs}}) / (B + 1), T the Diebold-Mariano z of the held-out errors.",
            "",
        ]
    if diag.replay_sensor is not None:
        noise = _sensor_words(diag.replay_sensor, diag.joint)
        lines += [f"Every replay here carries the recording's sensor noise, estimated from its position (less what the loop adds to it): {noise}.", ""]
    lines += [
        "| effect | held-out simulated force | held-out simulated position | p | decision |",
        "| --- | --- | --- | --- | --- |",
    ]
    for dv in diag.decisions:
        force = "" if dv.force_before is None else f"{_pct(dv.force_before)} -> {_pct(dv.force_after)}"
        pos = "" if dv.position_before is None else f"{dv.position_before:.3g} % -> {dv.position_after:.3g} %"
        p = "" if dv.p_value is None else f"{dv.p_value:.2g}"
        if dv.null is not None:
            n = dv.null.noise
            p += (
                f" (Monte-Carlo, B = {len(dv.null.t_null)}: T_obs {dv.null.t_obs:.3g}, null median {np.nanmedian(dv.null.t_null):.3g}, "
                f"max {np.nanmax(dv.null.t_null):.3g}; noise: position {1e6 * n.q_std:.3g} {_micro(diag.joint)}, "
                f"disturbance {n.disturbance_std:.3g} {PARAMETERS['Fc'].unit_for(diag.joint)} "
                f"at {n.bandwidth_hz:.3g} Hz)"
            )
        lines.append(f"| {dv.effect} | {force} | {pos} | {p} | {dv.reason} |")
    lines.append("")
    return lines


NOISE_BAND_RATIO = 2.0
"""A replay's full-band force error above this multiple of its error in the inverse model's band is said to be the sensor
noise's (the loop's answer to it): on the clean logs beyond the corpus's design, 59.7 % in full for 4.3 % in band at 4 kHz."""


def simulation_sentence(sim: SimulationComparison) -> str:
    """The replay against the recording in words: the force error in full and in the inverse model's band (and, when the
    full-band figure is over :data:`NOISE_BAND_RATIO` times the band's, whose it is), position and velocity."""
    after = f" -> {_pct(sim.after['force'])}" if sim.after else ""
    band, noise_words = "", ""
    if "force_in_band" in sim.before:
        band_after = f" -> {_pct(sim.after['force_in_band'])}" if sim.after and "force_in_band" in sim.after else ""
        band = f" (in the inverse model's band {_pct(sim.before['force_in_band'])}{band_after})"
        if sim.before["force"] > NOISE_BAND_RATIO * sim.before["force_in_band"]:
            noise_words = (
                " The full-band figure is mostly the loop's answer to the sensor noise above that band, which a noise-free"
                " replay does not have; the band's is what the model explains."
            )
    return (
        f"Simulation against recording ({sim.source}): force error {_pct(sim.before['force'])}{after}{band}, "
        f"position {_pct(sim.before['position'])}, velocity {_pct(sim.before['velocity'])}.{noise_words}"
    )


def _micro(joint: str) -> str:
    """A millionth of the ``joint``'s position unit, as the report writes it (um, urad)."""
    return position_unit(joint, "u")


def _sensor_words(sensor: dict[str, Any], joint: str) -> str:
    """The sensor noise of a replay in words (:func:`ilic_cli.diagnosis.sensor.sensor_effects`), in the ``joint``'s units."""
    parts = []
    if "noise" in sensor:
        parts.append(f"white position noise {1e6 * sensor['noise']['q_std']:.3g} {_micro(joint)}")
    if "quantization" in sensor:
        parts.append(f"encoder step {1e6 * sensor['quantization']['resolution']:.3g} {_micro(joint)}")
    words = ", ".join(parts) or "none (no noise above the position filter's cut-off, no grid)"
    return f"{words} (one realisation, the same in every replay)"


def _rows_sentence(diag: Any) -> str:
    """How many decimated rows the diagnosis used, and the rule for those at rest (the one ``identify`` fits by)."""
    u = diag.usable
    if u is None:
        return f"{diag.rows_used} of {diag.rows_total} decimated rows used (velocity reversals and the filter's edge left out)."
    rest = f"{u.at_rest} at rest left out ({u.rest.dwells} dwells: {u.rest.rule})" if u.rest is not None and u.at_rest else "none at rest"
    if words := u.sign_words(position_unit(diag.joint)):
        rest += f"; {words}"
    saturated = f", {u.saturated} of a saturated drive" if u.saturated else ""
    return (
        f"{diag.rows_used} of {u.decimated} decimated rows used: {rest}{saturated}; of the {u.usable} rows every fit uses "
        "(identify's too), velocity reversals and the filter's edge left out."
    )
