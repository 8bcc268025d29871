"""Plots of a diagnosis (matplotlib Agg, imported only here): residual against velocity, position
and time with the located regions marked, residual spectrum, before/after force fit."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ilic_cli.diagnosis.core import Diagnosis
from ilic_cli.diagnosis.locate import Region
from ilic_cli.io.atomic import atomic_path
from ilic_cli.jointlog import UNITS
from ilic_cli.plotting import broken_at_gaps, edge_rows, mark_edges, scale_y, scaled_rows
from ilic_cli.spectra import welch_psd

if TYPE_CHECKING:
    from matplotlib.figure import Figure


SHADED_KINDS = ("velocity", "position", "time", "drift")
"""The located regions the residual plot shades (a ``frequency`` one is marked on the spectrum)."""


def residual_title(located: list[Region]) -> str:
    """The residual plot's title: it names the shading only when a significant region is shaded (a drift's finding alone, or
    a spectral line, locates none there)."""
    if any(g.significant and g.kind in SHADED_KINDS for g in located):
        return "IDIM residual; shaded: located regions (significant)"
    return "IDIM residual (no region located)"


def write_plots(diag: Diagnosis, out_dir: Path) -> list[Path]:
    """Write the PNG figures into ``out_dir`` atomically; return their paths."""
    import matplotlib  # deferred: matplotlib is slow to import, and only --out draws

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # deferred: after the Agg backend is chosen

    r = diag.residual
    written: list[Path] = []

    def save(fig: Figure, name: str) -> None:
        path = out_dir / name
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=90)
        plt.close(fig)
        written.append(path)

    pos, force = UNITS[diag.joint]  # a revolute joint's rad and N·m, a prismatic one's m and N
    sig = [g for g in diag.located if g.significant]
    fig, axes = plt.subplots(3, 1, figsize=(10, 10))
    for ax, key, unit, kind in ((axes[0], "qd", f"{pos}/s", "velocity"), (axes[1], "q", pos, "position"), (axes[2], "t", "s", "time")):
        ax.plot(r[key], r["before"], ".", ms=2, alpha=0.5, label="rigid model")
        ax.plot(r[key], r["after"], ".", ms=2, alpha=0.5, label="augmented model")
        for g in sig:
            if g.kind == kind or (kind == "time" and g.kind == "drift"):
                ax.axvspan(g.bounds[0], g.bounds[1], color="tab:red", alpha=0.12)
        ax.set_xlabel(f"{kind} ({unit})")
        ax.set_ylabel(f"force residual ({force})")
    axes[0].legend(loc="upper right")
    axes[0].set_title(residual_title(sig))
    fig.tight_layout()
    save(fig, "residual.png")

    fs = diag.fs_hz / diag.settings.ls.decimation
    fig, ax = plt.subplots(figsize=(10, 4))
    for key, label in (("before", "rigid model"), ("after", "augmented model")):
        e = r[key]
        f, P = welch_psd(e - e.mean(), fs, min(len(e), 256))
        ax.loglog(f[1:], P[1:], label=label)
    for g in sig:
        if g.kind == "frequency":
            centre = 0.5 * (g.bounds[0] + g.bounds[1])
            ax.axvline(centre, color="tab:red", alpha=0.4)
            ax.annotate(
                f"{centre:.3g} Hz", (centre, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12), textcoords="offset points", color="tab:red", fontsize=8
            )
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"residual PSD (({force})^2/Hz)")
    ax.legend()
    fig.tight_layout()
    save(fig, "spectrum.png")

    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    axes[0].plot(r["t"], r["y_before"], lw=1.2, ls="--", label="rigid IDIM model")
    axes[0].plot(r["t"], r["y_after"], lw=1.2, ls=":", label="augmented IDIM model")
    axes[0].plot(r["t"], r["y"], lw=0.5, color="k", label="recorded (decimated)")
    axes[0].set_ylabel(f"force ({force})")
    axes[0].legend(loc="upper right")
    sim = diag.simulation
    if sim is not None and "tau_before" in sim.signals:
        s = sim.signals
        t, diffs = s["t"], [s["tau_before"] - s["tau"]]
        axes[1].plot(t, diffs[0], lw=0.4, alpha=0.5, label="simulation - recording, rigid")
        if "tau_after" in s:
            diffs.append(s["tau_after"] - s["tau"])
            axes[1].plot(t, diffs[1], lw=0.4, alpha=0.5, label="simulation - recording, augmented")
        # the same in the inverse model's band (decimated as the rows, broken where the rows skip the dwells): at a high rate
        # the full band is mostly the loop's answer to the sensor noise
        for key, color, who in (("before_band", "k", "rigid"), ("after_band", "tab:red", "augmented")):
            if key in s:
                axes[1].plot(*broken_at_gaps(s["t_band"], s[key]), lw=1.2, color=color, label=f"{who}, in the inverse model's band")
        axes[1].set_ylabel(f"force difference ({force})")
    else:
        t, diffs = r["t"], [r["before"], r["after"]]
        axes[1].plot(t, diffs[0], lw=0.5, label="rigid")
        axes[1].plot(t, diffs[1], lw=0.5, label="augmented")
        axes[1].set_ylabel(f"IDIM residual ({force})")
    edges = edge_rows(len(t))
    keep = scaled_rows(t, edges)
    scale_y(axes[1], np.concatenate([d[keep] for d in diffs]))
    mark_edges(axes[1], t, edges)
    axes[1].legend(loc="upper right")
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    save(fig, "force_fit.png")
    return written
