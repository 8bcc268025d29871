"""Plots of identification results (matplotlib, Agg backend, imported lazily)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ilic_cli.closed_loop_id import RESIDUAL
from ilic_cli.io.atomic import atomic_path
from ilic_cli.jointlog import UNITS
from ilic_cli.lsq import norm_pct

if TYPE_CHECKING:
    from ilic_cli.identify import IdentifyReport
    from ilic_cli.runlog import RunLog


def _pyplot():
    # deferred: matplotlib takes about half a second to import, and only writing a plot needs it
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: matplotlib (above), after its backend is chosen

    return plt


GAP_FACTOR = 1.5
"""A step of the time axis longer than this many times its median step is a gap: the plotted lines break there."""


def gap_starts(t: np.ndarray) -> np.ndarray:
    """Index of the first sample after each gap of ``t``: a step longer than :data:`GAP_FACTOR` times its median step."""
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 3:
        return np.zeros(0, dtype=np.intp)
    dt = np.diff(t)
    return np.flatnonzero(dt > GAP_FACTOR * float(np.median(dt))) + 1


def broken_at_gaps(t: np.ndarray, *series: np.ndarray) -> tuple[np.ndarray, ...]:
    """``t`` and each of ``series`` with a NaN put in every gap of ``t`` (:data:`GAP_FACTOR`), so a line is not drawn across it.

    A log with gaps is fitted by its contiguous parts (the rows of each part stacked): joined, its lines would draw
    samples that do not exist. Each series has ``len(t)`` samples.
    """
    t = np.asarray(t, dtype=np.float64)
    out = [np.asarray(y, dtype=np.float64) for y in series]
    at = gap_starts(t)
    if not len(at):
        return (t, *out)
    mid = 0.5 * (t[at - 1] + t[at])
    return (np.insert(t, at, mid), *(np.insert(y, at, np.nan) for y in out))


def _save(fig, path: Path) -> Path:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip("."), dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    return path


def plot_identify(report: IdentifyReport, log: RunLog, outdir: Path, image_format: str = "png") -> list[Path]:
    """Write the identification plots into ``outdir``; return their paths.

    ``parameters``: IDIM-ILIC estimates per window with ±σ bands and the
    IDIM-LS value as a line; ``force``: measured vs reconstructed (decimated)
    force with the error; ``tracking``: tracking error over time with the
    per-window ratio ‖e_q‖/‖q − q̄‖; ``convergence`` (DIDIM / IDIM-IV): each
    method's residual norm at each iteration, from the IDIM-LS start, one
    panel per method (:data:`ilic_cli.closed_loop_id.RESIDUAL`: DIDIM's is an
    output error, IDIM-IV's an inverse-model residual).
    """
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator  # deferred: matplotlib (see _pyplot)

    written: list[Path] = []
    pos, force = UNITS[report.joint_type]  # a revolute joint's rad and N·m, a prismatic one's m and N
    recorded = log.provenance.true_parameters
    true = dict(recorded) if isinstance(recorded, Mapping) else {}
    if report.ilic is not None and report.ilic.windows:
        names = report.ilic.names
        fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.2 * len(names)), sharex=True, squeeze=False)
        ks = np.array([w.k for w in report.ilic.windows])
        for i, (n, ax) in enumerate(zip(names, axes[:, 0], strict=True)):
            v = np.array([w.result.theta[i] for w in report.ilic.windows])
            s = np.array([w.result.std[i] for w in report.ilic.windows])
            s = np.where(np.isfinite(s), s, np.nan)
            ax.plot(ks, v, "o-", label="IDIM-ILIC χ̂ᵏ")
            ax.fill_between(ks, v - s, v + s, alpha=0.3, label="±σ")
            shown = [v, v - s, v + s]
            if report.ls is not None and i < len(report.ls.result.theta):
                ax.axhline(report.ls.result.theta[i], color="k", ls="--", lw=1, label="IDIM-LS")
                shown.append(np.array([report.ls.result.theta[i]]))
            if n in true:
                ax.axhline(float(true[n]), color="tab:green", ls=":", lw=1.5, label="true (simulated)")
                shown.append(np.array([float(true[n])]))
            scale_y(ax, np.concatenate(shown))
            ax.set_ylabel(f"{n} ({report.unit(n)})")
            ax.grid(alpha=0.3)
        axes[0, 0].legend(loc="best", fontsize=8)
        axes[-1, 0].set_xlabel("window k (-)")
        axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
        if len(ks) == 1:  # one window: its number the one tick, not fractions of a window around it
            axes[-1, 0].set_xticks(ks)
        fig.suptitle("Parameter estimates per window")
        written.append(_save(fig, outdir / f"parameters.{image_format}"))
    if report.ls is not None and report.ls.y is not None and report.ls.y_hat is not None:
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
        t_rows = report.ls.t if report.ls.t is not None else np.arange(len(report.ls.y))
        error = report.ls.y - report.ls.y_hat
        models = [(i, cl.method, cl.y_hat) for i, cl in enumerate(report.closed_loop()) if cl.y_hat is not None and len(cl.y_hat) == len(t_rows)]
        t, y_hat, y, error_b, *cl_hats = broken_at_gaps(t_rows, report.ls.y_hat, report.ls.y, error, *(hat for _, _, hat in models))
        ax1.plot(t, y_hat, lw=1.4, color="C1", label="IDIM-LS model")
        for (i, method, _), cl_hat in zip(models, cl_hats, strict=True):
            ax1.plot(t, cl_hat, lw=1.0, ls="--", color=f"C{i + 4}", label=f"{method} model")
        ax1.plot(t, y, lw=0.6, color="C0", label="measured (decimated)")
        ax1.set_ylabel(f"force ({force})")
        ax1.legend(fontsize=8)
        ax2.plot(t, error_b, lw=0.8, color="C3")
        edges = edge_rows(len(error))
        scale_y(ax2, error[scaled_rows(t_rows, edges)])
        mark_edges(ax2, t_rows, edges)
        ax2.set_ylabel(f"error ({force})")
        ax2.set_xlabel("t (s)")
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
        fig.suptitle(f"Measured vs reconstructed force (relative error {report.ls.result.relative_error_pct:.4f} %)")
        written.append(_save(fig, outdir / f"force.{image_format}"))
    if report.closed_loop():
        runs = report.closed_loop()
        # DIDIM's residual is an output error, IDIM-IV's an inverse-model residual: one panel each
        fig, axes = plt.subplots(len(runs), 1, figsize=(7, 2.6 * len(runs) + 0.6), squeeze=False)
        for i, (cl, ax) in enumerate(zip(runs, axes[:, 0], strict=True)):
            iteration_ks = [it.k for it in cl.iterations]
            ax.plot(iteration_ks, [it.relative_error_pct for it in cl.iterations], "o-", color=f"C{i + 4}")
            ax.set_title(f"{cl.method} ({'converged' if cl.converged else 'not converged'}): {RESIDUAL[cl.method]}", fontsize=9)
            ax.set_ylabel("relative to ‖y‖ (%)")
            ax.ticklabel_format(axis="y", useOffset=False)  # IV moves in the 5th digit: an offset label would hide the level
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.grid(alpha=0.3)
        axes[-1, 0].set_xlabel("iteration k (0: IDIM-LS start)")
        fig.tight_layout()
        written.append(_save(fig, outdir / f"convergence.{image_format}"))
    if "q_ref" in log:
        fig, ax = plt.subplots(figsize=(9, 3))
        ax.plot(*broken_at_gaps(log.t, log["q_ref"] - log["q"]), lw=0.6)
        ax.set_xlabel("t (s)")
        ax.set_ylabel(f"e_q = q_ref − q ({pos})")
        ax.grid(alpha=0.3)
        if report.ilic is not None:
            for w in report.ilic.windows:
                ax.axvline(w.t_start, color="k", lw=0.4, alpha=0.4)
            ratios = ", ".join(f"{w.tracking_error_ratio:.2g}" for w in report.ilic.windows[:6] if w.tracking_error_ratio is not None)
            ax.set_title(f"Tracking error (‖e_q‖/‖q−q̄‖ per window: {ratios}{', …' if len(report.ilic.windows) > 6 else ''})")
        written.append(_save(fig, outdir / f"tracking.{image_format}"))
    return written


EDGE_FRACTION = 0.02
"""Share of the rows at each end left out of an error axis's scale (the zero-phase filters' edge transients)."""


def edge_rows(n: int) -> int:
    """Rows at each end of ``n`` left out of an error axis's scale (:data:`EDGE_FRACTION`)."""
    return int(EDGE_FRACTION * n)


def scale_y(ax, values: np.ndarray, margin: float = 0.08) -> None:
    """Scale ``ax``'s y axis on the finite ``values`` with a margin (no empty band, no line on the frame)."""
    finite = values[np.isfinite(values)]
    if not len(finite):
        return
    lo, hi = float(finite.min()), float(finite.max())
    pad = margin * (hi - lo) if hi > lo else max(abs(hi), 1e-12) * margin
    ax.set_ylim(lo - pad, hi + pad)


def edge_spans(t: np.ndarray, edges: int) -> list[tuple[int, int]]:
    """The rows ``[a, b)`` left out of an error axis's scale: ``edges`` at both ends of each contiguous part of ``t`` (split at
    :func:`gap_starts`), where each part's filters start and end (a log with gaps is fitted part by part)."""
    bounds = [0, *gap_starts(t).tolist(), len(t)]
    return [span for a, b in zip(bounds[:-1], bounds[1:]) if edges > 0 and b - a > 2 * edges for span in ((a, a + edges), (b - edges, b))]


def scaled_rows(t: np.ndarray, edges: int) -> np.ndarray:
    """True for the rows an error axis is scaled on: every row but :func:`edge_spans`'."""
    keep = np.ones(len(t), dtype=bool)
    for a, b in edge_spans(t, edges):
        keep[a:b] = False
    return keep


def mark_edges(ax, t: np.ndarray, edges: int) -> None:
    """Shade the rows left out of the scale (:func:`edge_spans`)."""
    spans = edge_spans(t, edges)
    for k, ((a, b), (c, d)) in enumerate(zip(spans[::2], spans[1::2], strict=True)):  # a part's start, then its end
        ax.axvspan(t[a], t[b], color="0.85", zorder=0, label="edges (not scaled)" if k == 0 else None)
        ax.axvspan(t[c - 1], t[d - 1], color="0.85", zorder=0)


def plot_joint_torques(
    t: np.ndarray,
    joints: list[str],
    units: list[str],
    measured: list[np.ndarray],
    model: list[np.ndarray],
    title: str,
    outdir: Path,
    image_format: str = "png",
) -> list[Path]:
    """One figure per joint of an arm, ``torque_<joint>``: measured vs model torque, and the residual, against time.

    ``measured`` and ``model`` are each joint's decimated rows (times ``t``), in
    the joint's effort unit (``units``: N·m for a revolute joint, N for a prismatic one).
    """
    plt = _pyplot()
    written: list[Path] = []
    for joint, unit, y, y_hat in zip(joints, units, measured, model, strict=True):
        tj = t[: len(y)]
        residual = y - y_hat
        tb, yb, y_hatb, residualb = broken_at_gaps(tj, y, y_hat, residual)
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        ax1.plot(tb, yb, lw=0.7, color="C0", label="measured (filtered, decimated)")
        ax1.plot(tb, y_hatb, lw=1.0, ls="--", color="C1", label="model W·θ̂")
        ax1.set_ylabel(f"torque ({unit})")
        ax1.legend(fontsize=8, loc="upper right")
        ax2.plot(tb, residualb, lw=0.7, color="C3", label="residual (measured − model)")
        edges = edge_rows(len(residual))
        scale_y(ax2, residual[scaled_rows(tj, edges)])
        mark_edges(ax2, tj, edges)
        ax2.set_ylabel(f"residual ({unit})")
        ax2.set_xlabel("t (s)")
        ax2.legend(fontsize=8, loc="upper right")
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
        rel = norm_pct(float(np.linalg.norm(residual)), float(np.linalg.norm(y)))
        fig.suptitle(f"{joint}: measured vs model torque (relative error {rel:.3g} %)\n{title}", fontsize=10)
        written.append(_save(fig, outdir / f"torque_{joint}.{image_format}"))
    return written
