"""Plots of identification results (matplotlib, Agg backend, imported lazily)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ilic_cli.io.atomic import atomic_path

if TYPE_CHECKING:
    from ilic_cli.identify import IdentifyReport
    from ilic_cli.runlog import RunLog


def _pyplot():  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:  # type: ignore[no-untyped-def]
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=path.suffix.lstrip("."), dpi=120, bbox_inches="tight")
    _pyplot().close(fig)
    return path


def plot_identify(report: IdentifyReport, log: RunLog, outdir: Path, image_format: str = "png") -> list[Path]:
    """Write the identification plots into ``outdir``; return their paths.

    ``parameters``: IDIM-ILIC estimates per window with ±σ bands and the
    IDIM-LS value as a line; ``force``: measured vs reconstructed (decimated)
    force with the error; ``tracking``: tracking error over time with the
    per-window ratio ‖e_q‖/‖q − q̄‖.
    """
    plt = _pyplot()
    written: list[Path] = []
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
            if report.ls is not None:
                ax.axhline(report.ls.result.theta[i], color="k", ls="--", lw=1, label="IDIM-LS")
            ax.set_ylabel(n)
            ax.grid(alpha=0.3)
        axes[0, 0].legend(loc="best", fontsize=8)
        axes[-1, 0].set_xlabel("window k")
        from matplotlib.ticker import MaxNLocator

        axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
        fig.suptitle("Parameter estimates per window")
        written.append(_save(fig, outdir / f"parameters.{image_format}"))
    if report.ls is not None and report.ls.y is not None and report.ls.y_hat is not None:
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
        t = report.ls.t if report.ls.t is not None else np.arange(len(report.ls.y))
        ax1.plot(t, report.ls.y, lw=0.8, label="measured (decimated)")
        ax1.plot(t, report.ls.y_hat, lw=0.8, label="IDIM-LS model")
        ax1.set_ylabel("force (N)")
        ax1.legend(fontsize=8)
        ax2.plot(t, report.ls.y - report.ls.y_hat, lw=0.8, color="C3")
        ax2.set_ylabel("error (N)")
        ax2.set_xlabel("t (s)")
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
        fig.suptitle(f"Measured vs reconstructed force (relative error {report.ls.result.relative_error_pct:.4f} %)")
        written.append(_save(fig, outdir / f"force.{image_format}"))
    if "q_ref" in log:
        fig, ax = plt.subplots(figsize=(9, 3))
        ax.plot(log.t, log["q_ref"] - log["q"], lw=0.6)
        ax.set_xlabel("t (s)")
        ax.set_ylabel("e_q = q_ref − q")
        ax.grid(alpha=0.3)
        if report.ilic is not None:
            for w in report.ilic.windows:
                ax.axvline(w.t_start, color="k", lw=0.4, alpha=0.4)
            ratios = ", ".join(f"{w.tracking_error_ratio:.2g}" for w in report.ilic.windows[:6] if w.tracking_error_ratio is not None)
            ax.set_title(f"Tracking error (‖e_q‖/‖q−q̄‖ per window: {ratios}{', …' if len(report.ilic.windows) > 6 else ''})")
        written.append(_save(fig, outdir / f"tracking.{image_format}"))
    return written
