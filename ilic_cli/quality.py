"""Data-quality checks on a logged run: sampling, saturation, frozen sensor, length.

Everything here is a pure function of NumPy arrays; :func:`assess` gathers the
checks into a :class:`QualityReport` that ``ilic info`` prints and ``ilic
convert`` uses for its warnings. Non-finite samples and non-increasing
timestamps are refused earlier, at read time, by
:func:`ilic_cli.runlog.validate_samples`.

Rules (each documented at its function)
---------------------------------------
* **sampling** -- the nominal rate, gaps and jitter of :mod:`ilic_cli.timebase`;
  sampling is *irregular* when the jitter exceeds 1 % or when there are gaps;
* **saturation** -- the drive command sits on a plateau at its largest absolute
  value for at least 0.5 % of the samples *and* that value is a round limit
  such as 10 V (:func:`saturation`);
* **frozen sensor** -- the measured position stays bit-identical for at least
  0.1 s (and 10 samples) while the reference moves by more than 1 % of its
  range (:func:`frozen_runs`);
* **too short** -- fewer than 1000 samples or less than 1 s of data.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ilic_cli.timebase import GAP_FACTOR, IRREGULAR_JITTER, sampling_kind, sampling_stats

SATURATION_MIN_SHARE = 0.005
"""Least share of samples on the plateau for the drive command to count as saturated."""

SATURATION_ATOL = 1e-9
"""Samples within this distance (V) of the largest absolute value are on the plateau."""

FROZEN_MIN_S = 0.1
"""Shortest run (s) of identical positions that can be reported as a frozen sensor."""

FROZEN_MIN_SAMPLES = 10
"""Shortest run (samples) of identical positions that can be reported as a frozen sensor."""

FROZEN_REF_SHARE = 0.01
"""Reference motion during a frozen run, as a share of the reference's total range."""

SHORT_SAMPLES = 1000
"""Logs with fewer samples are reported as too short for identification."""

SHORT_DURATION_S = 1.0
"""Logs shorter than this (s) are reported as too short for identification."""


@dataclass(frozen=True)
class QualityFinding:
    """One observation about a log.

    Attributes
    ----------
    code : str
        Stable identifier: ``gaps``, ``irregular``, ``saturation``, ``frozen``,
        ``short``.
    severity : str
        ``"warning"`` (may spoil identification) or ``"info"``.
    message : str
        One human-readable sentence.
    """

    code: str
    severity: str
    message: str


@dataclass
class QualityReport:
    """Data-quality figures and findings for one log.

    Attributes
    ----------
    samples : int
        Number of samples.
    duration_s : float
        Time from first to last sample (s).
    nominal_rate_hz : float or None
        Nominal sample rate used for the checks.
    median_step_s : float or None
        Median time step (s).
    max_step_s : float or None
        Longest time step (s).
    jitter : float
        Standard deviation of the steps (gaps excluded) relative to the nominal period.
    gaps : int
        Number of steps longer than 1.5 nominal periods.
    dropped_samples : int
        Estimated number of samples missing in those gaps.
    irregular : bool
        True when there are gaps or the jitter exceeds 1 %.
    saturation_share : float or None
        Share of samples on the drive command's max-abs plateau (None without ``vir``).
    saturation_limit : float or None
        The plateau value when it is judged a saturation, else None.
    frozen_runs : list of dict
        Runs with ``start_s``, ``duration_s``, ``samples`` where the sensor looks frozen.
    findings : list of QualityFinding
        What is worth telling the user.
    """

    samples: int
    duration_s: float
    nominal_rate_hz: float | None
    median_step_s: float | None
    max_step_s: float | None
    jitter: float
    gaps: int
    dropped_samples: int
    irregular: bool
    saturation_share: float | None = None
    saturation_limit: float | None = None
    frozen_runs: list[dict[str, float]] = field(default_factory=list)
    findings: list[QualityFinding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when there is no warning."""
        return not any(f.severity == "warning" for f in self.findings)

    def warnings(self) -> list[str]:
        """Return the messages of the warning findings."""
        return [f.message for f in self.findings if f.severity == "warning"]

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable dictionary of the report."""
        out = asdict(self)
        out["ok"] = self.ok
        return out


def is_round_limit(value: float) -> bool:
    """Return True when ``value`` has at most two significant digits (10, 2.5, 24, 0.5).

    Controllers clip their output at a configured limit, and configured limits
    are round numbers; the largest value of an unclipped signal almost never is.
    """
    if not (value > 0 and math.isfinite(value)):
        return False
    return math.isclose(value, float(f"{value:.2g}"), rel_tol=1e-9, abs_tol=0.0)


def saturation(vir: np.ndarray) -> tuple[float, float | None]:
    """Detect saturation of the drive command.

    The command is called saturated when at least 0.5 % of its samples lie
    within 1e-9 of its largest absolute value ``m`` (a plateau: a clipped
    signal stays on its limit, a free one touches its maximum once) and ``m``
    is a round limit (:func:`is_round_limit`).

    Parameters
    ----------
    vir : ndarray
        Drive command samples (V).

    Returns
    -------
    share : float
        Share of the samples on the max-abs plateau.
    limit : float or None
        ``m`` when the command is judged saturated, else None.
    """
    a = np.abs(np.asarray(vir, dtype=np.float64).reshape(-1))
    if len(a) == 0:
        return 0.0, None
    m = float(a.max())
    if m == 0.0:
        return 0.0, None
    share = float(np.mean(a >= m - SATURATION_ATOL))
    limit = m if (share >= SATURATION_MIN_SHARE and is_round_limit(m)) else None
    return share, limit


def saturation_mask(vir: np.ndarray, limit: float) -> np.ndarray:
    """Samples of the drive command on its saturation plateau ``|vir| >= limit - 1e-9``.

    Parameters
    ----------
    vir : ndarray
        Drive command samples (V).
    limit : float
        The plateau value found by :func:`saturation`.

    Returns
    -------
    ndarray of bool
        True where the command sits at the limit (identification masks these).
    """
    return np.abs(np.asarray(vir, dtype=np.float64).reshape(-1)) >= limit - SATURATION_ATOL


def frozen_runs(t: np.ndarray, q: np.ndarray, q_ref: np.ndarray) -> list[dict[str, float]]:
    """Find runs where the position sensor looks frozen.

    A run is a stretch of bit-identical consecutive ``q`` samples lasting at
    least 0.1 s and 10 samples during which ``q_ref`` moves (max - min) by more
    than 1 % of its range over the whole log. A stuck axis under a moving
    reference builds a growing error that the controller resolves long before
    that; a sensor that stops updating does not.

    Parameters
    ----------
    t, q, q_ref : ndarray
        Time (s), measured and reference position, equally long.

    Returns
    -------
    list of dict
        ``start_s``, ``duration_s``, ``samples`` and ``ref_motion`` of each run.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    q = np.asarray(q, dtype=np.float64).reshape(-1)
    q_ref = np.asarray(q_ref, dtype=np.float64).reshape(-1)
    if len(q) < 2:
        return []
    span = float(q_ref.max() - q_ref.min())
    if span <= 0:
        return []
    same = np.diff(q) == 0
    # run boundaries of "same" stretches: sample i..j where q[i] == ... == q[j]
    edges = np.flatnonzero(np.diff(np.concatenate(([0], same.view(np.int8), [0]))))
    runs: list[dict[str, float]] = []
    for start, stop in zip(edges[0::2], edges[1::2]):
        first, last = int(start), int(stop)  # samples first..last are identical
        n = last - first + 1
        dur = float(t[last] - t[first])
        if n < FROZEN_MIN_SAMPLES or dur < FROZEN_MIN_S:
            continue
        seg = q_ref[first : last + 1]
        motion = float(seg.max() - seg.min())
        if motion > FROZEN_REF_SHARE * span:
            runs.append({"start_s": float(t[first]), "duration_s": dur, "samples": n, "ref_motion": motion})
    return runs


def assess(
    t: np.ndarray,
    *,
    q: np.ndarray | None = None,
    q_ref: np.ndarray | None = None,
    vir: np.ndarray | None = None,
    rate_hz: float | None = None,
) -> QualityReport:
    """Run every check and return the report.

    Parameters
    ----------
    t : ndarray
        Increasing time stamps (s).
    q, q_ref : ndarray, optional
        Measured and reference position; the frozen-sensor check needs both.
    vir : ndarray, optional
        Drive command (V) for the saturation check.
    rate_hz : float, optional
        Nominal sample rate; default :func:`nominal_rate_hz` of ``t``.

    Returns
    -------
    QualityReport
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    stats = sampling_stats(t, rate_hz)
    duration = float(t[-1] - t[0]) if len(t) else 0.0
    report = QualityReport(samples=len(t), duration_s=duration, **stats)
    findings = report.findings
    if report.gaps:
        findings.append(
            QualityFinding(
                "gaps",
                "warning",
                f"{report.gaps} gap(s) longer than {GAP_FACTOR}x the nominal period; about {report.dropped_samples} sample(s) dropped "
                f"(longest step {report.max_step_s:.6g} s)",
            )
        )
    if sampling_kind(t) == "irregular":
        findings.append(
            QualityFinding(
                "irregular",
                "warning",
                f"irregular sampling (step jitter {100 * report.jitter:.3g} % of the mean period, not a fixed-rate loop): identification "
                "interpolates it linearly onto a uniform grid",
            )
        )
    elif report.jitter > IRREGULAR_JITTER:
        findings.append(
            QualityFinding("jitter", "info", f"stamp jitter {100 * report.jitter:.3g} % of the period: a fixed-rate loop, samples kept at the mean rate")
        )
    elif report.median_step_s is not None:
        findings.append(QualityFinding("jitter", "info", f"step jitter {100 * report.jitter:.3g} % of the nominal period"))
    if vir is not None and len(vir):
        share, limit = saturation(vir)
        report.saturation_share = share
        report.saturation_limit = limit
        if limit is not None:
            findings.append(QualityFinding("saturation", "warning", f"drive command saturated at +/-{limit:g} on {100 * share:.3g} % of the samples"))
    if q is not None and q_ref is not None and len(q) == len(t) == len(q_ref):
        report.frozen_runs = frozen_runs(t, q, q_ref)
        if report.frozen_runs:
            longest = max(r["duration_s"] for r in report.frozen_runs)
            findings.append(
                QualityFinding("frozen", "warning", f"position frozen while the reference moves: {len(report.frozen_runs)} run(s), longest {longest:.3g} s")
            )
    if len(t) < SHORT_SAMPLES or duration < SHORT_DURATION_S:
        findings.append(
            QualityFinding(
                "short",
                "warning",
                f"log too short for identification ({len(t)} samples, {duration:.3g} s; want >= {SHORT_SAMPLES} samples and >= {SHORT_DURATION_S:g} s)",
            )
        )
    return report


def assess_log(log: Any, command: np.ndarray | None = None) -> QualityReport:
    """Run :func:`assess` on a :class:`~ilic_cli.runlog.RunLog`.

    Parameters
    ----------
    log : RunLog
        The log; ``q``, ``q_ref`` and ``vir`` are used when present.
    command : ndarray, optional
        The drive command (V) in place of ``vir`` (:func:`ilic_cli.prepare.drive_command`: a PD loop's force over
        its declared drive gain).

    Returns
    -------
    QualityReport
    """
    ch = log.channels
    rate = log.meta.get("sample_rate_hz")
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (math.isfinite(rate) and rate > 0):
        rate = None
    return assess(ch["t"], q=ch.get("q"), q_ref=ch.get("q_ref"), vir=ch.get("vir") if command is None else command, rate_hz=rate)
