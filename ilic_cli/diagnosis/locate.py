"""Where a force residual is structured rather than noise: in state, in time, in frequency.

Pure functions on arrays. Every region reports its size (number of rows),
its mean residual with a standard error that accounts for the residual's
autocorrelation (effective sample size ``n (1 - rho)/(1 + rho)`` from the
lag-1 autocorrelation), the z statistic and a two-sided p-value with a
Bonferroni correction over the regions of its family. A region is
*significant* below ``alpha`` after that correction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.diagnosis.stats import chi2_sf, effective_size, f_sf, lag1_autocorrelation, normal_sf
from ilic_cli.lsq import lstsq
from ilic_cli.spectra import local_maxima, welch_psd


@dataclass(frozen=True)
class Region:
    """One located region of the residual.

    Attributes
    ----------
    kind : str
        Family: ``velocity``, ``position``, ``acceleration``, ``reversal``,
        ``time``, ``drift``, ``frequency``, ``lag``.
    label : str
        Plain words (e.g. ``qd in [-0.13, -0.08] m/s``).
    bounds : tuple of float
        Interval in the family's unit (m/s, m, s, Hz); ``lag``: the lag (s).
    rows : int
        Rows of the residual in the region.
    mean, se : float
        Mean residual (N) and its autocorrelation-corrected standard error;
        ``frequency``: the peak's power ratio to the background (mean,
        se = nan); ``drift``: the RMS of the segment's apparent parameter
        change projected on the force.
    statistic : float
        z (bins), F (drift), power ratio (frequency), correlation (lag).
    p_value : float
        Bonferroni-corrected over the family.
    significant : bool
    """

    kind: str
    label: str
    bounds: tuple[float, float]
    rows: int
    mean: float
    se: float
    statistic: float
    p_value: float
    significant: bool

    def to_dict(self) -> dict[str, Any]:
        f = lambda x: None if not np.isfinite(x) else float(x)  # noqa: E731
        return {
            "kind": self.kind,
            "label": self.label,
            "bounds": [f(self.bounds[0]), f(self.bounds[1])],
            "rows": self.rows,
            "mean_residual": f(self.mean),
            "std_error": f(self.se),
            "statistic": f(self.statistic),
            "p_value": f(self.p_value),
            "significant": self.significant,
        }


def _bins(kind: str, e: np.ndarray, x: np.ndarray, edges: list[tuple[float, float]], unit: str, alpha: float, rho: float) -> list[Region]:
    out = []
    sd = float(np.std(e, ddof=1)) if len(e) > 1 else float("nan")
    fam = max(len(edges), 1)
    for i, (a, b) in enumerate(edges):
        m = (x >= a) & ((x < b) if i < len(edges) - 1 else (x <= b))
        n = int(m.sum())
        if n < 3:
            continue
        mean = float(e[m].mean())
        se = sd / np.sqrt(effective_size(n, rho))
        z = mean / se if se > 0 else 0.0
        p = min(1.0, 2.0 * float(normal_sf(abs(z))) * fam)
        out.append(Region(kind, f"{kind} in [{a:.4g}, {b:.4g}] {unit}", (float(a), float(b)), n, mean, float(se), float(z), p, p < alpha))
    return out


def velocity_bins(e: np.ndarray, qd: np.ndarray, n_per_sign: int = 3, alpha: float = 0.001, rho: float | None = None, unit: str = "m/s") -> list[Region]:
    """Bins of velocity: ``n_per_sign`` speed quantile bins on each side of zero."""
    rho = lag1_autocorrelation(e) if rho is None else rho
    edges: list[tuple[float, float]] = []
    for sign in (-1, 1):
        v = qd[np.sign(qd) == sign]
        if len(v) < 3 * n_per_sign:
            continue
        qs = np.quantile(np.abs(v), np.linspace(0, 1, n_per_sign + 1))
        pairs = [(sign * qs[i + (sign < 0)], sign * qs[i + (sign > 0)]) for i in range(n_per_sign)]
        edges.extend(sorted(pairs))
    edges.sort()
    return _bins("velocity", e, qd, edges, unit, alpha, rho)


def position_bins(e: np.ndarray, q: np.ndarray, n: int = 8, alpha: float = 0.001, rho: float | None = None, unit: str = "m") -> list[Region]:
    """Equal-width bins of position."""
    rho = lag1_autocorrelation(e) if rho is None else rho
    x = np.linspace(float(q.min()), float(q.max()), n + 1)
    return _bins("position", e, q, list(zip(x[:-1], x[1:], strict=True)), unit, alpha, rho)


def acceleration_phases(e: np.ndarray, qd: np.ndarray, qdd: np.ndarray, alpha: float = 0.001, rho: float | None = None) -> list[Region]:
    """Accelerating, decelerating and constant-velocity rows (|qdd| below 10 % of its top)."""
    rho = lag1_autocorrelation(e) if rho is None else rho
    top = float(np.percentile(np.abs(qdd), 99)) or 1.0
    phase = np.where(np.abs(qdd) < 0.1 * top, 0.0, np.where(qd * qdd > 0, 1.0, -1.0))
    regions = _bins("acceleration", e, phase, [(-1.0, -0.5), (-0.5, 0.5), (0.5, 1.0)], "", alpha, rho)
    names = {-1.0: "decelerating", 0.0: "constant velocity", 1.0: "accelerating"}
    return [
        Region(r.kind, names[round((r.bounds[0] + r.bounds[1]) / 2)], r.bounds, r.rows, r.mean, r.se, r.statistic, r.p_value, r.significant) for r in regions
    ]


def reversal_windows(e: np.ndarray, t: np.ndarray, qd: np.ndarray, half_width_s: float = 0.1, alpha: float = 0.001, rho: float | None = None) -> list[Region]:
    """Mean residual with the sign of the motion within ``half_width_s`` of velocity reversals, and elsewhere."""
    rho = lag1_autocorrelation(e) if rho is None else rho
    zc = t[1:][np.diff(np.sign(qd)) != 0]
    near = np.zeros(len(t), dtype=bool)
    for tz in zc:
        near |= np.abs(t - tz) <= half_width_s
    ev = e * np.sign(qd)
    regs = _bins("reversal", ev, near.astype(float), [(0.0, 0.5), (0.5, 1.0)], "", alpha, rho)
    return [
        Region(
            r.kind,
            ("near velocity reversals" if r.bounds[0] > 0 else "away from reversals") + " (residual x sign(qd))",
            r.bounds,
            r.rows,
            r.mean,
            r.se,
            r.statistic,
            r.p_value,
            r.significant,
        )
        for r in regs
    ]


def time_segments(e: np.ndarray, t: np.ndarray, W: np.ndarray, n: int = 8, alpha: float = 0.001) -> list[Region]:
    """Per time segment: mean residual, and a drift test (residual regressed on the model's columns, F-test)."""
    rho = lag1_autocorrelation(e)
    edges = np.linspace(float(t[0]), float(t[-1]), n + 1)
    out = _bins("time", e, t, list(zip(edges[:-1], edges[1:], strict=True)), "s", alpha, rho)
    sd2 = float(np.var(e, ddof=1))
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        m = (t >= a) & (t <= b)
        k = W.shape[1]
        if m.sum() <= 3 * k:
            continue
        theta, rss = lstsq(W[m], e[m])
        ss = float(e[m] @ e[m]) - rss
        neff = effective_size(int(m.sum()), rho)
        F = (ss / k) / sd2 * (neff / m.sum()) if sd2 > 0 else 0.0
        p = min(1.0, float(f_sf(F, k, max(neff - k, 1))) * n)
        out.append(
            Region(
                "drift",
                f"parameters drift in t in [{a:.4g}, {b:.4g}] s",
                (float(a), float(b)),
                int(m.sum()),
                float(np.sqrt(ss / m.sum())),
                float("nan"),
                float(F),
                p,
                p < alpha,
            )
        )
    return out


def spectrum_peaks(e: np.ndarray, fs_hz: float, alpha: float = 0.001, max_peaks: int = 3) -> list[Region]:
    """Spectral peaks of the residual above a smooth background (Welch, chi-square test, Bonferroni over bins)."""
    from scipy.ndimage import median_filter  # deferred: scipy.ndimage is slow to import (ilic --help stays fast)

    nper = int(min(len(e), max(64, 2 ** int(np.log2(fs_hz * 2)))))
    f, P = welch_psd(e - np.mean(e), fs_hz, nper)
    if len(P) < 8:
        return []
    segments = max(1, 2 * len(e) // nper - 1)
    background = median_filter(P, size=max(5, len(P) // 16), mode="nearest")
    ratio = np.where(background > 0, P / background, 0.0)
    dof = 2 * segments
    pv = chi2_sf(ratio * dof, dof) * len(P)
    out = []
    peak_idx = local_maxima(ratio)
    for i in peak_idx[np.argsort(pv[peak_idx])][:max_peaks]:
        p = min(1.0, float(pv[i]))
        df = f[1] - f[0]
        out.append(
            Region(
                "frequency",
                f"spectral peak at {f[i]:.3g} Hz",
                (float(f[i] - df / 2), float(f[i] + df / 2)),
                int(len(e)),
                float("nan"),
                float("nan"),
                float(ratio[i]),
                p,
                p < alpha,
            )
        )
    return out


def force_lag(y: np.ndarray, y_hat: np.ndarray, fs_hz: float, max_lag_s: float = 0.025) -> Region:
    """Lag (s) maximising the correlation of the force and the model's prediction (parabolic refinement).

    Positive: the logged force lags the model (the plant's ``delay``).
    """
    a = y - y.mean()
    b = y_hat - y_hat.mean()
    L = int(round(max_lag_s * fs_hz))
    lags = np.arange(-L, L + 1)
    n = len(a)
    c = np.array([float(a[max(k, 0) : n + min(k, 0)] @ b[max(-k, 0) : n - max(k, 0)]) for k in lags.tolist()])
    c /= float(np.linalg.norm(a) * np.linalg.norm(b)) or 1.0
    i = int(np.argmax(c))
    shift = 0.0
    if 0 < i < len(c) - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        shift = 0.5 * (c[i - 1] - c[i + 1]) / den if den != 0 else 0.0
    lag = (lags[i] + shift) / fs_hz
    # is the peak away from zero? compare the correlation at the peak and at zero lag (Fisher z, effective n)
    neff = effective_size(n, lag1_autocorrelation(a - b))
    z = (np.arctanh(min(c[i], 0.999999)) - np.arctanh(min(c[L], 0.999999))) * np.sqrt(max(neff - 3, 1))
    p = float(normal_sf(z)) * len(lags)
    p = min(1.0, p)
    return Region(
        "lag",
        f"force {'lags' if lag > 0 else 'leads'} the model by {abs(lag) * 1e3:.3g} ms",
        (lag, lag),
        n,
        float("nan"),
        float("nan"),
        float(c[i]),
        p,
        bool(p < 0.001 and lags[i] != 0),
    )


def locate(
    e: np.ndarray, *, t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, W: np.ndarray, fs_hz: float, alpha: float = 0.001, q_unit: str = "m"
) -> list[Region]:
    """All families of regions for one residual sampled at ``fs_hz`` (rows of the decimated IDIM system); ``q_unit`` the position's (m or rad)."""
    rho = lag1_autocorrelation(e)
    regions: list[Region] = []
    regions += velocity_bins(e, qd, alpha=alpha, rho=rho, unit=f"{q_unit}/s")
    regions += position_bins(e, q, alpha=alpha, rho=rho, unit=q_unit)
    regions += acceleration_phases(e, qd, qdd, alpha=alpha, rho=rho)
    regions += reversal_windows(e, t, qd, alpha=alpha, rho=rho)
    regions += time_segments(e, t, W, alpha=alpha)
    regions += spectrum_peaks(e, fs_hz, alpha=alpha)
    return regions
