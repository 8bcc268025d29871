"""Trends of a batch table: per machine, joint and parameter, a step or a slope, tested and corrected.

The test, stated once (:data:`TEST`): each series (one machine, one joint,
one parameter, one method's estimates in time order) is fitted three ways by
least squares: a constant, a line in time, and two constant levels split
between two logs (the split that fits best, at least :data:`MIN_SIDE` logs a
side). The change is the one of the line or of the step, whichever leaves the
smaller residual. Its p-value: the line's slope t-test (``n - 2`` degrees of
freedom; the scatter is the residual's, not the per-log σ, so logs that scatter
more than their σ are not over-trusted), or the step's F-test against the
constant, multiplied by the number of splits tried (Bonferroni for the search).
The p-values of all series are then corrected together, across machines x
joints x parameters (Holm by default, or Benjamini-Hochberg). A series is
flagged when its corrected p is below ``alpha`` (0.01) and its change is at
least ``min_change_pct`` (10 %) of its first level; a parameter whose first
level is not :data:`LEVEL_Z` times its standard error, nor :data:`LEVEL_Z` times
one log's median σ, away from zero (an offset near 0 N) has no relative change
and is not tested. A flagged rise of Fv or Fc is wear; a
flagged step of M is a payload swap, named by the day of the first log after it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.errors import ParameterError
from ilic_cli.fleet.table import format_time

MIN_POINTS = 6
MIN_SIDE = 2
LEVEL_Z = 5.0
CORRECTIONS = ("holm", "bh")
TEST = (
    "per machine x joint x parameter: the better of a line in time (slope t-test) and a two-level step (F-test, Bonferroni over the splits); "
    "p-values corrected across all series ({correction}); flagged when corrected p < {alpha:g} and the change >= {min_change:g} % of the first level"
)


@dataclass(frozen=True)
class TrendSettings:
    """The stated test's thresholds (:data:`TEST`)."""

    alpha: float = 0.01
    min_change_pct: float = 10.0
    correction: str = "holm"
    method: str = "IDIM-LS"

    def check(self) -> None:
        """Refuse a level outside (0, 1), a negative change or an unknown correction."""
        if not 0 < self.alpha < 1:
            raise ParameterError("alpha", self.alpha, "between 0 and 1")
        if not (math.isfinite(self.min_change_pct) and self.min_change_pct >= 0):
            raise ParameterError("min_change_pct", self.min_change_pct, "a change of at least 0 %")
        if self.correction not in CORRECTIONS:
            raise ParameterError("correction", self.correction, f"one of {', '.join(CORRECTIONS)}")

    def statement(self) -> str:
        """The test in words, with these thresholds."""
        name = {"holm": "Holm", "bh": "Benjamini-Hochberg"}[self.correction]
        return TEST.format(correction=name, alpha=self.alpha, min_change=self.min_change_pct)


# ---------------------------------------------------------------------------
# the statistics: pure functions on arrays
# ---------------------------------------------------------------------------
def slope_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float, float, float]:
    """Line ``y = a + b (x - x[0])``: ``(a, b, se_a, se_b, rss)`` (standard errors from the residual's scatter)."""
    u = x - x[0]
    n = len(y)
    X = np.c_[np.ones(n), u]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    rss = float(r @ r)
    s2 = rss / (n - 2)
    cov = s2 * np.linalg.inv(X.T @ X)
    return float(coef[0]), float(coef[1]), math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1]), rss


def step_fit(y: np.ndarray, min_side: int = MIN_SIDE) -> tuple[int, float, float, float, int]:
    """Best two-level split: ``(k, mean before, mean from k on, rss, splits tried)`` (``k``: the first index after the step)."""
    n = len(y)
    c1 = np.cumsum(y)
    c2 = np.cumsum(y * y)
    best = (0, float("nan"), float("nan"), float("inf"))
    for k in range(min_side, n - min_side + 1):
        s1, q1, s2, q2 = c1[k - 1], c2[k - 1], c1[-1] - c1[k - 1], c2[-1] - c2[k - 1]
        rss = (q1 - s1 * s1 / k) + (q2 - s2 * s2 / (n - k))
        if rss < best[3]:
            best = (k, s1 / k, s2 / (n - k), float(rss))
    return best[0], float(best[1]), float(best[2]), max(best[3], 0.0), n - 2 * min_side + 1


def p_slope(b: float, se_b: float, dof: int) -> float:
    """Two-sided p-value of a slope's t-test."""
    from scipy import stats  # deferred: scipy.stats takes a while to import

    if se_b == 0:
        return 0.0 if b != 0 else 1.0
    return float(2 * stats.t.sf(abs(b / se_b), dof))


def p_step(rss0: float, rss1: float, dof: int, splits: int) -> float:
    """F-test of a step against a constant (``rss0``: the constant's residual), times the splits tried, at most 1."""
    from scipy import stats  # deferred: scipy.stats takes a while to import

    if rss1 <= 0:
        return 0.0 if rss0 > 0 else 1.0
    f = (rss0 - rss1) / (rss1 / dof)
    return float(min(1.0, splits * stats.f.sf(f, 1, dof)))


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error)."""
    p = np.asarray(p, dtype=float)
    m = len(p)
    order = np.argsort(p, kind="stable")
    adj = np.maximum.accumulate((m - np.arange(m)) * p[order])
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out


def benjamini_hochberg(p: np.ndarray) -> np.ndarray:
    """Benjamini-Hochberg adjusted p-values (false discovery rate)."""
    p = np.asarray(p, dtype=float)
    m = len(p)
    order = np.argsort(p, kind="stable")
    scaled = p[order] * m / np.arange(1, m + 1)
    adj = np.minimum.accumulate(scaled[::-1])[::-1]
    out = np.empty(m)
    out[order] = np.minimum(adj, 1.0)
    return out


# ---------------------------------------------------------------------------
# series and the report
# ---------------------------------------------------------------------------
@dataclass
class Series:
    """One machine's joint's parameter over time: the estimates, the fits and the verdict."""

    machine: str
    joint: str
    parameter: str
    unit: str
    times_ns: list[int]
    values: list[float]
    stds: list[float]
    kind: str = "untested"
    """``slope``, ``step`` or ``untested`` (too few logs, or a level not distinguishable from zero)."""
    level: float = float("nan")
    change_pct: float = float("nan")
    p: float = float("nan")
    p_adjusted: float = float("nan")
    flagged: bool = False
    step_index: int | None = None
    before: float = float("nan")
    after: float = float("nan")
    label: str = ""

    @property
    def step_day(self) -> str | None:
        """The day (YYYY-MM-DD, UTC) of the first log after the step."""
        return None if self.step_index is None or self.kind != "step" else format_time(self.times_ns[self.step_index])[:10]

    def fit(self) -> None:
        """Fit the line and the step; keep the better as the change, with its p-value (:data:`TEST`)."""
        n = len(self.values)
        if n < MIN_POINTS:
            return
        x = (np.asarray(self.times_ns, dtype=np.int64) - self.times_ns[0]).astype(float) / 86400e9
        y = np.asarray(self.values, dtype=float)
        a, b, se_a, se_b, rss_line = slope_fit(x, y)
        if not abs(a) > LEVEL_Z * max(se_a, float(np.median(self.stds))):
            return
        k, m1, m2, rss_step, splits = step_fit(y)
        rss0 = float(((y - y.mean()) ** 2).sum())
        if rss_step < rss_line:
            self.kind, self.level, self.step_index, self.before, self.after = "step", m1, k, m1, m2
            self.change_pct = 100.0 * (m2 - m1) / m1
            self.p = p_step(rss0, rss_step, n - 2, splits)
        else:
            self.kind, self.level = "slope", a
            self.before, self.after = a, a + b * x[-1]
            self.change_pct = 100.0 * b * x[-1] / a
            self.p = p_slope(b, se_b, n - 2)

    def to_dict(self) -> dict[str, Any]:
        d = {k: v for k, v in asdict(self).items() if k not in ("times_ns", "values", "stds")}
        for k, v in d.items():
            if isinstance(v, float) and not math.isfinite(v):
                d[k] = None
        d["logs"] = len(self.values)
        d["step_day"] = self.step_day
        return d


def _or(x: float | None, default: float) -> float:
    return default if x is None else x


def is_friction(name: str) -> bool:
    """Fv, Fc and their asymmetric sides."""
    return name.startswith(("Fv", "Fc"))


@dataclass
class TrendReport:
    """Every series with its verdict, and the machines ranked by their largest flagged friction rise."""

    settings: TrendSettings
    series: list[Series]
    skipped: int = 0
    """Rows without a start time or an estimate (not placed in time)."""
    warnings: list[str] = field(default_factory=list)

    def flagged(self) -> list[Series]:
        """The flagged series, in table order."""
        return [s for s in self.series if s.flagged]

    def machines(self) -> list[dict[str, Any]]:
        """Per machine and joint: largest friction rise (flagged or not), wear and payload-swap flags; ranked."""
        groups: dict[tuple[str, str], list[Series]] = {}
        for s in self.series:
            groups.setdefault((s.machine, s.joint), []).append(s)
        out: list[dict[str, Any]] = []
        for (machine, joint), ss in groups.items():
            friction = [s for s in ss if is_friction(s.parameter) and s.kind != "untested"]
            worst = max(friction, key=lambda s: s.change_pct, default=None)
            wear = [s for s in friction if s.flagged and s.change_pct > 0]
            swaps = [s for s in ss if s.parameter == "M" and s.flagged and s.kind == "step"]
            out.append(
                {
                    "machine": machine,
                    "joint": joint,
                    "wear": bool(wear),
                    "largest_friction_change_pct": None if worst is None else worst.change_pct,
                    "largest_friction_parameter": None if worst is None else worst.parameter,
                    "payload_swaps": [{"day": s.step_day, "M_before": s.before, "M_after": s.after} for s in swaps],
                    "flags": [s.label for s in ss if s.flagged],
                }
            )
        # worn first by their largest friction rise, then a swapped payload, then the rest by their largest friction change
        out.sort(
            key=lambda m: (
                not m["wear"],
                -_or(m["largest_friction_change_pct"], -math.inf) if m["wear"] else 0.0,
                not m["payload_swaps"],
                -_or(m["largest_friction_change_pct"], -math.inf),
                m["machine"],
                m["joint"],
            )
        )
        for i, m in enumerate(out):
            m["rank"] = i + 1
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "test": self.settings.statement(),
            "settings": asdict(self.settings),
            "machines": self.machines(),
            "series": [s.to_dict() for s in self.series],
            "skipped_rows": self.skipped,
            "warnings": list(self.warnings),
        }


def trend(frame: Any, settings: TrendSettings = TrendSettings()) -> TrendReport:
    """Fit and test every series of a batch table (a DataFrame, :func:`ilic_cli.fleet.table.read_table`)."""
    settings.check()
    ok = frame[(frame["status"] == "ok") & (frame["method"] == settings.method)]
    names = [c[: -len("_rel_std_pct")] for c in frame.columns if c.endswith("_rel_std_pct")]
    timed = ok[ok["start_time"].notna()]
    report = TrendReport(settings, [], skipped=len(ok) - len(timed))
    if report.skipped:
        report.warnings.append(f"{report.skipped} row(s) without a start time are not placed in time")
    if not len(timed):
        report.warnings.append(f"no {settings.method} estimate with a start time in the table")
        return report
    ns = timed["start_time"].astype("int64").to_numpy()
    machine = timed["machine"].fillna("").astype(str).to_numpy()
    joint = timed["joint"].fillna("").astype(str).to_numpy()
    jtype = timed["joint_type"].fillna("prismatic").astype(str).to_numpy()
    for key in sorted(set(zip(machine, joint))):
        sel = np.flatnonzero((machine == key[0]) & (joint == key[1]))
        sel = sel[np.argsort(ns[sel], kind="stable")]
        for name in names:
            v = timed[name].to_numpy(dtype=float)[sel]
            s = timed[f"{name}_std"].to_numpy(dtype=float)[sel]
            good = np.isfinite(v)
            series = Series(key[0], key[1], name, parameters.unit(name, jtype[sel[0]]), [int(t) for t in ns[sel][good]], list(v[good]), list(s[good]))
            series.fit()
            report.series.append(series)
    tested = [s for s in report.series if s.kind != "untested"]
    if tested:
        p = np.array([s.p for s in tested])
        adj = holm(p) if settings.correction == "holm" else benjamini_hochberg(p)
        for s, pa in zip(tested, adj):
            s.p_adjusted = float(pa)
            s.flagged = bool(pa < settings.alpha and abs(s.change_pct) >= settings.min_change_pct)
            s.label = _label(s)
    return report


def _label(s: Series) -> str:
    sign = f"{s.change_pct:+.1f} %"
    if s.parameter == "M" and s.kind == "step":
        return f"payload swap on {s.step_day}: M {s.before:.4g} -> {s.after:.4g} {s.unit} ({sign})"
    what = "wear" if is_friction(s.parameter) and s.change_pct > 0 else "change"
    when = f" from {s.step_day}" if s.kind == "step" else " over the period"
    return f"{s.parameter} {what} {sign} ({s.kind}{when}, p = {s.p_adjusted:.2g} corrected)"


def to_markdown(report: TrendReport) -> str:
    """The summary: the test, machines ranked, then every flagged series."""
    out = ["# Fleet trends", "", f"Test: {report.settings.statement()}.", "", f"Estimates: {report.settings.method}.", ""]
    out += [
        "## Machines, ranked",
        "",
        "| rank | machine | joint | largest friction change | wear | payload swap | flags |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for m in report.machines():
        change = "—" if m["largest_friction_change_pct"] is None else f"{m['largest_friction_parameter']} {m['largest_friction_change_pct']:+.1f} %"
        swaps = ", ".join(f"{s['day']} (M {s['M_before']:.4g} -> {s['M_after']:.4g})" for s in m["payload_swaps"]) or "—"
        out.append(f"| {m['rank']} | {m['machine'] or '—'} | {m['joint'] or '—'} | {change} | {'yes' if m['wear'] else 'no'} | {swaps} | {len(m['flags'])} |")
    out += ["", "## Flagged changes", ""]
    flagged = report.flagged()
    out += [f"- {s.machine or '—'}{'/' + s.joint if s.joint else ''}: {s.label}" for s in flagged] or ["None."]
    if report.warnings:
        out += ["", "## Warnings", ""] + [f"- {w}" for w in report.warnings]
    return "\n".join(out) + "\n"
