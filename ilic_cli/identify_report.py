"""Renderers: identification results as Markdown, CSV and JSON text.

Pure functions from result objects to strings; the CLI decides where they go.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.closed_loop_id import STD_SOURCE
from ilic_cli.drive_lag import LAG_MIN_T, DriveLag
from ilic_cli.effects import unit_of
from ilic_cli.estimators.base import stated_lag_s
from ilic_cli.filtering import DECIMATION_RULE
from ilic_cli.idim_ls import IDIMLSResult
from ilic_cli.jointlog import position_unit
from ilic_cli.lsq import NOT_WHITE_WIDENING

if TYPE_CHECKING:
    from ilic_cli.identify import IdentifyReport

MAX_WINDOW_COLUMNS = 8


def fmt(x: float | None, decimals: int = 4) -> str:
    """Fixed-point number, or an em dash for a missing or infinite value."""
    if x is None or not math.isfinite(float(x)):
        return "—"
    return f"{float(x):.{decimals}f}"


def fmt_sig(x: float | None, digits: int = 4) -> str:
    """Number with ``digits`` significant digits (paper-table style)."""
    if x is None or not math.isfinite(float(x)):
        return "—"
    x = float(x)
    if x == 0:
        return "0"
    if abs(x) >= 1e5 or abs(x) < 1e-3:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}" if abs(x) >= 10 ** (digits - 1) else f"{x:.{max(digits - 1 - int(math.floor(math.log10(abs(x)))), 0)}f}"


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(" --- " for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return lines


def _label(name: str, joint_type: str = "prismatic") -> str:
    """``name (unit)``: the unit on the report's joint (:mod:`ilic_cli.parameters`) or of an effect's column."""
    unit = unit_of(name, joint_type)
    return f"{name} ({unit})" if unit else name


def to_markdown(report: IdentifyReport) -> str:
    """The report as Markdown: IDIM-LS table, Table II layout, validation."""
    out: list[str] = [f"# Identification of {report.source or 'log'}", ""]
    joint = f"joint `{report.joint}` ({report.joint_type})" if report.joint else f"a {report.joint_type} joint"
    out.append(f"Model `{report.model}` of {joint}; {report.samples} samples at {report.fs_hz:g} Hz.")
    out.append("")
    if report.ls is not None:
        r = report.ls.result
        out += ["## IDIM-LS", ""]
        out += _table(
            ["parameter", "value", "std", "rel. std %"],
            [[_label(n, report.joint_type), fmt(v), fmt(s), fmt(p)] for n, v, s, p in zip(r.names, r.theta, r.std, r.rel_std_pct, strict=True)],
        )
        out += [
            "",
            f"Condition number {fmt(r.condition_number)}; error norm {fmt(r.error_norm)}; relative error {fmt(r.relative_error_pct)} %; "
            f"error std {fmt(r.sigma_rho)}.",
            "",
        ]
        out += _robust_lines(report.ls)
        out += _correlated_lines(report.ls)
        out += _rows_lines(report, report.ls)
    out += _closed_loop_markdown(report)
    out += _output_error_markdown(report)
    if report.ilic is not None:
        wins = report.ilic.windows
        shown = wins[:MAX_WINDOW_COLUMNS]
        s = report.ilic.settings
        out += ["## IDIM-ILIC per window" + (" next to IDIM-LS" if report.ls is not None else ""), ""]
        lag = f" delayed by {report.ilic.ref_lag} samples to line up with the measured motion" if report.ilic.ref_lag else ""
        out.append(
            f"Windows of {s.window_s:g} s on the reference trajectory{lag}; force low-pass {s.cutoff_hz:g} Hz and decimated; "
            f"%σ_max = {s.sigma_max_pct:g} (a † marks a parameter that is not essential and would not be updated)."
        )
        out.append("")
        header = ["parameter"]
        for w in shown:
            header += [f"χ̂{_sup(w.k)}", "%σ"]
        if report.ls is not None:
            header += ["IDIM-LS", "%σ"]
        rows: list[list[str]] = []
        names = report.ilic.names
        for i, n in enumerate(names):
            row = [_label(n, report.joint_type)]
            for w in shown:
                mark = "" if w.essential[i] else " †"
                row += [fmt_sig(w.result.theta[i]) + mark, fmt_sig(w.result.rel_std_pct[i], 2)]
            if report.ls is not None:
                row += [fmt_sig(report.ls.result.theta[i]), fmt_sig(report.ls.result.rel_std_pct[i], 2)]
            rows.append(row)
        err = ["‖Y−Wχ̂‖/‖Y‖"]
        for w in shown:
            err += [fmt_sig(w.result.relative_error_pct, 2) + " %", ""]
        if report.ls is not None:
            err += [fmt_sig(report.ls.result.relative_error_pct, 2) + " %", ""]
        rows.append(err)
        track = ["‖e_q‖/‖q−q̄‖"]
        for w in shown:
            track += [fmt_sig(w.tracking_error_ratio, 2), ""]
        if report.ls is not None:
            track += ["", ""]
        rows.append(track)
        out += _table(header, rows)
        if len(wins) > len(shown):
            out += ["", f"({len(wins) - len(shown)} more windows: use --format csv or json.)"]
        if report.ilic.dropped_s > 0:
            out += ["", f"The last {report.ilic.dropped_s:.3g} s (shorter than a window) were not used."]
        out.append("")
    if report.validation:
        out += ["## Cross-test validation", ""]
        opened = any(v.open_loop is not None for v in report.validation)
        header = ["log", "estimates", "relative error %", "error norm", "error std", "condition number"]
        header += [f"open-loop RMSE {position_unit(report.joint_type, 'm')}", "fit %"] if opened else []
        rows = []
        for v in report.validation:
            vr = v.result
            measures = ["—"] * 4 if vr is None else [fmt(vr.relative_error_pct), fmt(vr.error_norm), fmt(vr.sigma_rho), fmt(vr.condition_number)]
            row = [v.source, v.method] + measures
            if opened:
                row += ["—", "—"] if v.open_loop is None else [fmt(v.open_loop["rmse_mm"], 3), fmt(v.open_loop["fit_pct"], 2)]
            rows.append(row)
        out += _table(header, rows)
        if opened:
            out += [
                "",
                "Open loop: the EMPS benchmark's figure, u = vir (times the drive gain) into the model without feedback, "
                "the state from the first 20 samples, RMSE of the position after them.",
            ]
        out.append("")
    if report.warnings:
        out += ["## Warnings", ""] + [f"- {w}" for w in report.warnings] + [""]
    return "\n".join(out)


def _closed_loop_markdown(report: IdentifyReport) -> list[str]:
    """DIDIM / IDIM-IV: estimates beside IDIM-LS, then each method's convergence and residual history."""
    results = report.closed_loop()
    if not results:
        return []
    out = ["## Closed-loop estimates" + (" beside IDIM-LS" if report.ls is not None else ""), ""]
    columns = ([("IDIM-LS", report.ls.result)] if report.ls is not None else []) + [(r.method, r.result) for r in results]
    header = ["parameter"] + [h for name, _ in columns for h in (name, "%σ")]
    names = results[0].result.names
    rows = [[_label(n, report.joint_type)] + [x for _, r in columns for x in (fmt_sig(r.theta[i]), fmt_sig(r.rel_std_pct[i], 2))] for i, n in enumerate(names)]
    rows.append(["‖Y−Wθ̂‖/‖Y‖"] + [x for _, r in columns for x in (fmt_sig(r.relative_error_pct, 3) + " %", "")])
    out += _table(header, rows)
    out += [
        "",
        "DIDIM's relative error is its criterion, the force of the simulated closed loop against the measured one (filtered and decimated "
        "as IDIM-LS); IDIM-IV's and IDIM-LS's are the inverse model's on the measured regressor. "
        "The replay of the log with each estimate (same reference, same controller) against the recording, at the full rate:",
        "",
    ]
    out += _table(
        ["estimates", "force error %", "position error %", "velocity error %", "iterations", "converged"],
        [
            [
                r.method,
                fmt(r.closed_loop_error_pct.get("force")),
                fmt(r.closed_loop_error_pct.get("position")),
                fmt(r.closed_loop_error_pct.get("velocity")),
                str(r.n_iterations),
                "yes" if r.converged else "no",
            ]
            for r in results
        ],
    )
    out.append("")
    for r in results:
        out += [f"### {r.method}", "", f"{'Converged' if r.converged else 'Not converged'}: {r.stop_reason}. Standard deviations: {STD_SOURCE[r.method]}.", ""]
        out += _table(
            ["k", "relative error %", "largest parameter change %", "residual change %"],
            [[str(it.k), fmt(it.relative_error_pct), fmt(it.parameter_change_pct), fmt(it.error_change_pct)] for it in r.iterations],
        )
        out.append("")
    return out


def _rows_lines(report: IdentifyReport, ls_result: IDIMLSResult) -> list[str]:
    """The rows IDIM-LS fitted (the rule for samples at rest, stated where it acted) and when it evaluated its regressor."""
    u = report.usable
    lag = report.drive_lag
    held = _regressor_timing(ls_result.hold_s, stated_lag_s(report.effects), lag.words() if lag is not None and lag.applied else "")
    if u is not None and u.at_rest and u.rest is not None:
        ls = ls_result.settings
        rule = f"; rows decimated by {ls.decimation} ({DECIMATION_RULE if ls.band_hz is not None else 'as given'})"
        timing = f"; {held}" if held else ""
        sign = f"; {words}" if (words := u.sign_words(position_unit(report.joint_type))) else ""
        rest = f"{u.at_rest} at rest left out ({u.rest.dwells} dwells: {u.rest.rule}){u.gap_words()}"
        return [f"{u.usable} of {u.decimated} decimated rows fitted: {rest}{timing}{sign}{rule}.", "", *_suggested_lag(lag)]
    return [f"{held[0].upper()}{held[1:]}.", ""] if held else []


def _suggested_lag(lag: DriveLag | None) -> list[str]:
    """A drive lag the rows suggest and ``identify`` does not apply (:attr:`DriveLag.suggested`), and how to state it; ``[]``: none."""
    if lag is None or not lag.suggested:
        return []
    return [
        f"The rows suggest a drive lag of {lag.words()} ({lag.value_s / lag.std_s:.2g} σ), short of the {LAG_MIN_T:g} σ at which it "
        "is applied: the loop's response to the position noise makes a timing of its own up to about 5 σ. Not applied; if the "
        f"drive lags its command, state it: `--effect delay:delay={-lag.value_s:.3g}`.",
        "",
    ]


def _regressor_timing(shift_s: float, lag_s: float, estimated: str = "") -> str:
    """When IDIM-LS evaluated its regressor (``shift_s`` after each sample: the hold, and the model's stated drive ``lag_s`` or
    the drive lag ``estimated`` on the log, in words); ``""`` at the samples themselves."""
    if shift_s == 0.0:
        return ""
    if estimated:
        why = f"the drive's held command and the drive's lag, {estimated}, estimated on the log"
    elif lag_s == 0.0:
        why = "the drive's held command"
    elif abs(shift_s - lag_s) < 1e-12:  # no hold (no rows at rest, or a force that is no held command): the lag alone
        why = f"the stated drive lag of {1e3 * lag_s:.4g} ms"
    else:
        why = f"the drive's held command and the stated drive lag of {1e3 * lag_s:.4g} ms"
    return f"the regressor evaluated {1e3 * shift_s:.4g} ms later ({why})"


def _output_error_markdown(report: IdentifyReport) -> list[str]:
    """OE / CLOE: the estimate beside its IDIM-LS start, the criterion and the stopping rule."""
    out: list[str] = []
    milli, micro = position_unit(report.joint_type, "m"), position_unit(report.joint_type, "µ")
    force = unit_of("Fc", report.joint_type)
    for r in report.output_errors():
        what = "open loop, the recorded drive command in" if r.method == "OE" else "closed loop, the log's reference through its controller"
        out += [f"## {r.method} (output error, {what})", ""]
        out += _table(
            ["parameter", "start (IDIM-LS)", r.method, "std", "%σ"],
            [
                [_label(n.split(".")[-1], report.joint_type) if "." not in n else n, fmt_sig(s0), fmt_sig(v), fmt_sig(sd), fmt_sig(p, 2)]
                for n, s0, v, sd, p in zip(r.names, r.start, r.theta, r.std, r.rel_std_pct, strict=True)
            ],
        )
        out.append("")
        if r.method == "OE":
            shots = "one shot" if len(r.starts) == 1 else f"{len(r.starts)} stretches of {r.length} samples (multiple shooting)"
            out.append(
                f"Position RMSE {fmt(1e3 * r.rmse_start_m, 3)} {milli} at the start, {fmt(1e3 * r.rmse_m, 3)} {milli} at the estimate ({shots}, "
                f"from sample {r.starts[0]})."
            )
        else:
            out.append(
                f"Closed-loop position RMSE {fmt(1e6 * r.rmse_start_m, 3)} {micro} at the start, {fmt(1e6 * r.rmse_m, 3)} {micro} at the estimate; "
                f"force RMSE {fmt(r.extra.get('force_rmse_start'), 3)} → {fmt(r.extra.get('force_rmse'), 3)} {force} (criterion: {r.extra.get('output')})."
            )
        if r.force_error_pct is not None:
            out.append(f"Inverse-model force error with these parameters: {fmt(r.force_error_pct)} % (IDIM-LS's own criterion).")
        out += ["", f"{'Converged' if r.converged else 'Not converged'} after {r.iterations} iterations ({r.evaluations} simulations): {r.stop_reason}.", ""]
    return out


def _sup(k: int) -> str:
    return str(k).translate(str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹"))


def to_json(doc: Any) -> str:
    """JSON text (non-finite numbers already mapped to null by ``to_dict``)."""
    return json.dumps(doc, indent=2, allow_nan=False, default=_default) + "\n"


def _default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def to_csv(report: IdentifyReport) -> str:
    """Tidy CSV: one row per method, window and parameter."""
    return str(report.to_frame().to_csv(index=False, float_format="%.10g"))


def _correlated_lines(ls: IDIMLSResult) -> list[str]:
    """The two estimates whose errors lean together most (:meth:`ilic_cli.idim_ls.IDIMLSResult.most_correlated`)."""
    pair = ls.most_correlated()
    if pair is None:
        return []
    a, b, r = pair
    return [
        f"Most correlated estimates: {a} and {b}, r = {r:+.2f}: the rows determine a combination of the two better than either "
        "alone (a trajectory that excites them differently separates them; for friction, moves at several speeds).",
        "",
    ]


def _robust_lines(ls: IDIMLSResult) -> list[str]:
    """The autocorrelation-robust standard deviations beside eq. 9's (:data:`ilic_cli.lsq.ROBUST_RULE`), when they differ by half."""
    rob, r = ls.robust, ls.result
    if rob is None or rob.widening(r.std) <= NOT_WHITE_WIDENING:
        return []
    stds = ", ".join(f"{n} {fmt(v)}" for n, v in zip(r.names, rob.std, strict=True))
    return [
        f"The residual is not white (lag-1 autocorrelation {rob.lag1:.2f}): autocorrelation-robust std (Newey-West, {rob.lags} lags) {stds}, "
        f"up to {rob.widening(r.std):.2g}x eq. 9's above (the published convention, which assumes a white residual).",
        "",
    ]
