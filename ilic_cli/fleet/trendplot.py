"""Trend plots: each machine's parameters against time with ±σ bands and the fitted change; the fleet's friction."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ilic_cli.fleet.trend import Series, is_friction
from ilic_cli.plotting import _pyplot, _save

if TYPE_CHECKING:
    from ilic_cli.fleet.trend import TrendReport


def _dates(ns: list[int] | np.ndarray) -> np.ndarray:
    return np.asarray(ns, dtype="datetime64[ns]")


def _safe(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text) or "unnamed"


def _fitted(s: Series) -> tuple[np.ndarray, np.ndarray]:
    """The line or the step through the series' times."""
    t = np.asarray(s.times_ns, dtype=np.int64)
    if s.kind == "step" and s.step_index is not None:
        return t, np.where(np.arange(len(t)) < s.step_index, s.before, s.after)
    days = (t - t[0]) / 86400e9
    span = days[-1] if days[-1] > 0 else 1.0
    return t, s.before + (s.after - s.before) * days / span


def plot_machine(series: list[Series], path: Path) -> Path:
    """One machine's joint: a panel per parameter, estimates ±σ as a band, the fitted change in red when flagged."""
    plt = _pyplot()
    fig, axes = plt.subplots(len(series), 1, figsize=(7.5, 1.9 * len(series) + 0.6), sharex=True, squeeze=False)
    for ax, s in zip(axes[:, 0], series):
        t = _dates(s.times_ns)
        v, sd = np.asarray(s.values), np.asarray(s.stds)
        ax.fill_between(t, v - sd, v + sd, color="tab:blue", alpha=0.25, linewidth=0, label="±σ")
        ax.plot(t, v, "o-", color="tab:blue", markersize=3, linewidth=0.8, label="estimate")
        if s.kind != "untested":
            ft, fv = _fitted(s)
            ax.plot(
                _dates(ft), fv, color="tab:red" if s.flagged else "0.5", linewidth=1.5, drawstyle="steps-post" if s.kind == "step" else "default", label=s.kind
            )
        ax.set_ylabel(f"{s.parameter} ({s.unit})" if s.unit else s.parameter)
        if s.flagged:
            ax.set_title(s.label, fontsize=8, loc="left", color="tab:red")
    axes[0, 0].legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel("log start (UTC)")
    name = series[0].machine + (f" / {series[0].joint}" if series[0].joint else "")
    fig.suptitle(f"{name}: parameters against time", fontsize=10)
    fig.autofmt_xdate()
    return _save(fig, path)


def plot_fleet(report: TrendReport, parameter: str, path: Path) -> Path:
    """Every machine's ``parameter`` relative to its first level (%), worn ones in red."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.0))
    for s in (s for s in report.series if s.parameter == parameter and s.values):
        t = _dates(s.times_ns)
        base = s.level if np.isfinite(s.level) and s.level != 0 else s.values[0]
        rel = 100.0 * (np.asarray(s.values) / base - 1.0)
        ax.plot(t, rel, "-", color="tab:red" if s.flagged else "0.6", linewidth=1.2 if s.flagged else 0.8)
        if s.flagged:
            ax.annotate(s.machine, (t[-1], rel[-1]), fontsize=7, xytext=(2, 0), textcoords="offset points")
    ax.axhline(report.settings.min_change_pct, color="k", linestyle=":", linewidth=0.8, label=f"{report.settings.min_change_pct:g} %")
    ax.set_ylabel(f"{parameter} change from the first level (%)")
    ax.set_xlabel("log start (UTC)")
    ax.set_title(f"{parameter} per machine ({report.settings.method}); red: flagged ({report.settings.correction}, p < {report.settings.alpha:g})", fontsize=9)
    ax.legend(fontsize=7)
    fig.autofmt_xdate()
    return _save(fig, path)


def write_plots(report: TrendReport, out_dir: Path, image_format: str = "png") -> list[Path]:
    """``trend_MACHINE[_JOINT].FORMAT`` per machine and joint, and ``fleet_P.FORMAT`` per friction parameter."""
    groups: dict[tuple[str, str], list[Series]] = {}
    for s in report.series:
        if s.values:
            groups.setdefault((s.machine, s.joint), []).append(s)
    written = []
    for (machine, joint), ss in groups.items():
        written.append(plot_machine(ss, out_dir / f"trend_{_safe(machine)}{'_' + _safe(joint) if joint else ''}.{image_format}"))
    for name in sorted({s.parameter for s in report.series if is_friction(s.parameter)}):
        written.append(plot_fleet(report, name, out_dir / f"fleet_{_safe(name)}.{image_format}"))
    return written
