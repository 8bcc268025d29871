"""Markdown of the n-joint commands: the identification's tables and robot-sim's per-window convergence (paper Table I pattern)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any


def _num(value: Any, digits: int = 6) -> str:
    return "" if value is None else f"{value:.{digits}g}"


def _combines(combination: Mapping[str, float]) -> str:
    terms = list(combination.items())
    if not terms:
        return ""
    text = terms[0][0]
    for name, c in terms[1:]:
        text += f" {'-' if c < 0 else '+'} {abs(c):.4g} {name}"
    return text


def identify_markdown(doc: Mapping[str, Any]) -> str:
    """The identification of an arm: one table per method (base parameter, what it combines, value, std, %σ)."""
    joints = ", ".join(f"{j['name']} ({j['type']})" for j in doc["joints"])
    lines = [f"# {doc['log']}", "", f"- URDF: {doc['urdf']} (sha256 {doc['sha256'][:12]}); joints: {joints}"]
    lines.append(f"- {doc['samples']} samples at {doc['sample_rate_hz']:.6g} Hz; {len(doc['base_parameters'])} base parameters")
    if "parts" in doc:
        lines.append(f"- {doc['parts']['count']} parts between gaps: {doc['parts']['rule']}")
    combines = {b["name"]: _combines(b["combines"]) for b in doc["base_parameters"]}
    truth = doc.get("true_base_parameters")
    for name, m in doc["methods"].items():
        lines += ["", f"## {name}", ""]
        essential = set(m.get("essential", ()))
        head = "| base parameter | combines | value | std | %σ | essential |" + (" true |" if truth else "")
        lines += [head, "| --- " * (head.count("|") - 1) + "|"]
        for p, v in m["parameters"].items():
            row = (
                f"| {p} | {combines.get(p, '')} | {_num(v['value'])} | {_num(v['std'], 3)} | {_num(v['rel_std_pct'], 3)} | {'yes' if p in essential else ''} |"
            )
            lines.append(row + (f" {_num(truth[p])} |" if truth else ""))
        if "sigma_max_pct" in m:
            lines += ["", _essential_line(m)]
        if m.get("relative_error_pct") is not None:
            lines += ["", f"Relative error: {m['relative_error_pct']:.4g} %"]
        if "validation" in m:
            truth_error = doc.get("true_validation_relative_error_pct")
            yardstick = "" if truth_error is None else f" (the true parameters: {_num(truth_error, 4)} %)"
            lines += ["", f"Validation on {m['validation']['log']}: relative error {_num(m['validation']['relative_error_pct'], 4)} %{yardstick}"]
        if "stop_reason" in m:
            state = "converged" if m["converged"] else "not converged"
            lines += ["", f"{len(m['iterations']) - 1} iterations from the IDIM-WLS start, {state}: {m['stop_reason']}."]
        if "windows" in m:
            lines += ["", f"{len(m['windows'])} windows of {m['window_s']:g} s; the table holds the last window's estimate."]
    return "\n".join(lines) + "\n"


def _essential_line(m: Mapping[str, Any]) -> str:
    """How many base parameters are essential, and (IDIM-WLS) the fit without the others."""
    text = f"Essential (%σ ≤ {m['sigma_max_pct']:g} %, the ones IDIM-ILIC updates): {len(m['essential'])} of {len(m['parameters'])}."
    fit = m.get("essential_fit")
    if fit:
        text += f" Fit with only them: relative error {_num(fit['relative_error_pct'], 4)} % (all: {_num(fit['all_relative_error_pct'], 4)} %)."
    return text


def convergence_markdown(
    names: Sequence[str],
    truth: Sequence[float],
    estimates: Sequence[Sequence[float]],
    errors: Sequence[Sequence[float]],
    essential: Sequence[Sequence[bool]],
    sigma_max_pct: float,
) -> str:
    """Per base parameter, the estimate of each window k (``†``: not essential, not updated) and its relative error (%) against the truth of that window."""
    k = len(estimates)
    head = "| base parameter | true | " + " | ".join(f"k={i + 1}" for i in range(k)) + " | error k=last (%) |"
    lines = [head, "| --- " * (k + 3) + "|"]
    for i, name in enumerate(names):
        values = " | ".join(_num(e[i], 5) + ("" if s[i] else " †") for e, s in zip(estimates, essential, strict=True))
        lines.append(f"| {name} | {_num(truth[i], 5)} | {values} | {_num(errors[-1][i], 3)} |")
    count = sum(essential[-1]) if essential else 0
    lines += ["", f"† not essential in that window (%σ > {sigma_max_pct:g} %): the controller keeps its value. Essential at k={k}: {count} of {len(names)}."]
    return "\n".join(lines) + "\n"
