"""IDIM-ILIC: per-window least squares on the reference trajectory (paper section V).

The estimation step (eq. 24) is :func:`estimate_windows`: the observation
matrix ``W_r(q_r, qd_r, qdd_r)`` is built from the noise-free reference, the
actual force and every column of ``W_r`` are low-pass filtered and decimated
in parallel, and each window is solved by least squares with standard
deviations (eqs. 8-10). Parameters with ``%sigma <= %sigma_max`` are
*essential* and only those are updated (section V-E, :func:`update_parameters`).
The closed-loop plant calls :func:`estimate_window` online; ``ilic identify``
calls :func:`identify_ilic` on a log. Both go through :func:`estimate_windows`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.derivatives import central_difference
from ilic_cli.filtering import CHUNK_ELEMENTS, decimation_factor, lowpass_decimate
from ilic_cli.idim_ls import _columns
from ilic_cli.lsq import LSResult, finite_or_none, solve_batch
from ilic_cli.regressor import COLUMNS, Kinematics, Model
from ilic_cli.row_spans import usable_mask, valid_rows


@dataclass(frozen=True)
class ILICSettings:
    """Settings of the IDIM-ILIC estimation.

    Attributes
    ----------
    window_s : float
        Observation window T_obs (paper: T_cycle = 6.2 s).
    cutoff_hz : float
        Low-pass cut-off for the force and the regressor (paper: 5 Hz).
    decimation : int or None
        Down-sampling factor; ``None``: ``round(0.8*fs/2/cutoff)`` (80 at 1 kHz).
    sigma_max_pct : float
        Parameters with a larger relative standard deviation are not
        essential and not updated (paper: 15; "between 10 and 30").
    filter_order : int
        Butterworth order of the low-pass.
    ref_lag : int or None
        Offline only (:func:`identify_ilic`): delay (samples) applied to the
        reference so that it lines up with the measured motion; ``None``
        estimates it from the positions (:func:`reference_lag`). A loop that
        tracks well (the paper's CTC) gives 0; the EMPS benchmark's PD loop
        trails its reference by about 6 ms.
    max_ref_lag_s : float
        Largest lag searched when ``ref_lag`` is ``None``.
    """

    window_s: float = 6.2
    cutoff_hz: float = 5.0
    decimation: int | None = None
    sigma_max_pct: float = 15.0
    filter_order: int = 4
    ref_lag: int | None = None
    max_ref_lag_s: float = 0.05

    def factor(self, fs_hz: float) -> int:
        return self.decimation or decimation_factor(fs_hz, self.cutoff_hz)


@dataclass(frozen=True)
class WindowEstimate:
    """The estimate of one window (iteration k of the paper)."""

    k: int
    t_start: float
    t_end: float
    result: LSResult
    essential: np.ndarray
    tracking_error_ratio: float | None = None
    note: str = ""
    masked_fraction: float = 0.0
    """Share of the window's decimated rows left out (saturated drive, rest); 0 when all are used."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "k": self.k,
            "t_start": self.t_start,
            "t_end": self.t_end,
            "parameters": self.result.parameters(),
            "essential": {n: bool(e) for n, e in zip(self.result.names, self.essential, strict=True)},
            "relative_error_pct": finite_or_none(self.result.relative_error_pct),
            "condition_number": finite_or_none(self.result.condition_number),
            "tracking_error_ratio": None if self.tracking_error_ratio is None else finite_or_none(self.tracking_error_ratio),
            "note": self.note,
        }


@dataclass(frozen=True)
class ILICResult:
    """IDIM-ILIC estimates of every window of a log, in time order."""

    model: str
    names: tuple[str, ...]
    settings: ILICSettings
    windows: list[WindowEstimate] = field(default_factory=list)
    dropped_s: float = 0.0
    ref_lag: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": "IDIM-ILIC",
            "model": self.model,
            "window_s": self.settings.window_s,
            "cutoff_hz": self.settings.cutoff_hz,
            "sigma_max_pct": self.settings.sigma_max_pct,
            "ref_lag_samples": self.ref_lag,
            "windows": [w.to_dict() for w in self.windows],
            "dropped_tail_s": self.dropped_s,
        }

    def to_frame(self) -> Any:
        import pandas as pd  # deferred: pandas costs ~0.3 s of import, paid only by a caller of to_frame()

        rows = []
        for w in self.windows:
            row: dict[str, Any] = {"k": w.k, "t_start": w.t_start, "t_end": w.t_end}
            for n, v, s, r, e in zip(w.result.names, w.result.theta, w.result.std, w.result.rel_std_pct, w.essential, strict=True):
                row[n] = v
                row[f"{n}_std"] = s
                row[f"{n}_rel_std_pct"] = r
                row[f"{n}_essential"] = bool(e)
            row["relative_error_pct"] = w.result.relative_error_pct
            row["tracking_error_ratio"] = w.tracking_error_ratio
            rows.append(row)
        return pd.DataFrame(rows)


def essential_mask(result: LSResult, sigma_max_pct: float) -> np.ndarray:
    """Parameters whose relative standard deviation is at most ``sigma_max_pct`` (section V-E)."""
    rel = np.asarray(result.rel_std_pct)
    return np.isfinite(rel) & (rel <= sigma_max_pct)


def update_parameters(chi: np.ndarray, estimate: WindowEstimate) -> np.ndarray:
    """Return ``chi`` with only the essential parameters replaced by the new estimate."""
    return np.where(estimate.essential, estimate.result.theta, chi)


def tracking_error_ratio(q_ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``||e_q|| / ||q - mean(q)||`` along the last axis (paper Table II, last line)."""
    q = np.asarray(q)
    e = _norm(np.subtract(q_ref, q))
    spread = _norm(q - q.mean(axis=-1, keepdims=True))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(spread > 0, e / spread, np.inf)


def _norm(x: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(x, axis=-1)`` bit for bit, of a temporary ``x`` squared in place (one array of the log's length, not three)."""
    if not np.issubdtype(x.dtype, np.floating):
        return np.asarray(np.linalg.norm(x, axis=-1))
    np.multiply(x, x, out=x)
    return np.sqrt(np.add.reduce(x, axis=-1))


def _decimated_columns(model: Model, kin: Kinematics, r: int, fs_hz: float, settings: ILICSettings) -> list[np.ndarray]:
    """Each column of the windows' observation matrices (rows of ``kin``) low-pass filtered and decimated, one at a time.

    The rigid structure's columns (:data:`ilic_cli.regressor.COLUMNS`, sample by sample in the kinematics) are built a group of
    windows at a time, the groups the filter's own blocks of rows (:data:`ilic_cli.filtering.CHUNK_ELEMENTS`): the same bits,
    one group's column at the full rate instead of every window's (a 1-hour log: 16 MiB, not 27 MiB and two blocks' filters).
    """
    K, n = np.shape(kin.qd)
    rigid = all(any(c is k for k in COLUMNS.values()) for c in model.columns)
    group = max(1, CHUNK_ELEMENTS // max(n, 1)) if rigid else max(K, 1)
    parts = []
    for a in range(0, max(K, 1), group):  # no window: one empty group, as before
        rows = slice(a, a + group)
        part = Kinematics(qd=kin.qd[rows], qdd=kin.qdd[rows], q=None if kin.q is None else kin.q[rows], t=None if kin.t is None else kin.t[rows])
        parts.append(
            [lowpass_decimate(np.asarray(c, dtype=np.float64), r, settings.cutoff_hz, fs_hz, settings.filter_order, axis=1) for c in _columns(model, part)]
        )
    return [np.concatenate(p, axis=0) for p in zip(*parts, strict=True)]


def estimate_windows(
    model: Model,
    qd_ref: np.ndarray,
    qdd_ref: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    settings: ILICSettings,
    *,
    q_ref: np.ndarray | None = None,
    q: np.ndarray | None = None,
    t: np.ndarray | None = None,
    k0: int = 1,
    valid: np.ndarray | None = None,
) -> list[WindowEstimate]:
    """Estimate the parameters of K windows at once (paper eq. 24).

    Parameters
    ----------
    model : Model
        Regressor columns.
    qd_ref, qdd_ref, tau : ndarray, shape (K, n)
        Reference velocity and acceleration (noise-free) and actual force,
        one row per window.
    fs_hz : float
        Sampling frequency.
    settings : ILICSettings
        Filter, decimation and %sigma_max.
    q_ref, q : ndarray, shape (K, n), optional
        Reference and measured position, for the tracking error ratio (and
        for position-dependent columns).
    t : ndarray, shape (K, n), optional
        Time, for the window bounds and time-dependent columns.
    k0 : int
        Index of the first window (``k`` counts from 1).
    valid : ndarray of bool, shape (K, n), optional
        Samples that may be used (False: e.g. a saturated drive); in each
        window the decimated rows whose span touches an invalid sample are
        dropped before the least squares. ``None`` keeps every row.
    """
    qd_ref, qdd_ref, tau = (np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (qd_ref, qdd_ref, tau))
    kin = Kinematics(qd=qd_ref, qdd=qdd_ref, q=None if q_ref is None else np.atleast_2d(q_ref), t=None if t is None else np.atleast_2d(t))
    r = settings.factor(fs_hz)
    columns = _decimated_columns(model, kin, r, fs_hz, settings)
    Wd = np.moveaxis(np.stack(columns, axis=1), 1, -1)  # (K, rows, columns), laid out as before: solve_batch's bits depend on it
    yd = lowpass_decimate(tau, r, settings.cutoff_hz, fs_hz, settings.filter_order, axis=1)
    results = solve_batch(Wd, yd, model.names, sigma="eq8")
    masked: dict[int, float] = {}
    if valid is not None and not np.all(valid):
        rows = valid_rows(np.atleast_2d(valid), r)
        for i in np.flatnonzero(~rows.all(axis=1)).tolist():
            keep = rows[i]
            if keep.sum() > Wd.shape[-1]:
                results[i] = solve_batch(Wd[i : i + 1, keep], yd[i : i + 1, keep], model.names, sigma="eq8")[0]
            else:  # nothing identifiable is left: a null system (rank 0, infinite std)
                b = Wd.shape[-1]
                results[i] = solve_batch(np.zeros((1, b, b)), np.zeros((1, b)), model.names, sigma="eq8")[0]
            masked[i] = float(1 - keep.mean())
    ratios = tracking_error_ratio(np.atleast_2d(q_ref), np.atleast_2d(q)) if q_ref is not None and q is not None else None
    out = []
    for i, res in enumerate(results):
        ess = essential_mask(res, settings.sigma_max_pct)
        note = ""
        if not res.full_rank:
            missing = [n for n, s in zip(res.names, res.std, strict=True) if not np.isfinite(s)]
            note = f"rank-deficient: {', '.join(missing)} not excited in this window"
        elif not ess.all():
            note = "not essential: " + ", ".join(n for n, e in zip(res.names, ess, strict=True) if not e)
        if i in masked:
            share = f"{100 * masked[i]:.3g} % of the rows masked (saturated drive)"
            note = f"{share}; {note}" if note else share
        t0 = float(t[i, 0]) if t is not None else float("nan")
        t1 = float(t[i, -1]) if t is not None else float("nan")
        out.append(
            WindowEstimate(
                k=k0 + i,
                t_start=t0,
                t_end=t1,
                result=res,
                essential=ess,
                tracking_error_ratio=None if ratios is None else float(ratios[i]),
                note=note,
                masked_fraction=masked.get(i, 0.0),
            )
        )
    return out


def estimate_window(
    model: Model,
    qd_ref: np.ndarray,
    qdd_ref: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    settings: ILICSettings,
    *,
    q_ref: np.ndarray | None = None,
    q: np.ndarray | None = None,
    t: np.ndarray | None = None,
    k: int = 1,
) -> WindowEstimate:
    """Estimate one window (the online step of the closed loop); see :func:`estimate_windows`."""

    def stack(a: np.ndarray) -> np.ndarray:
        return np.asarray(a, dtype=np.float64)[None]

    def stack_optional(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else stack(a)

    return estimate_windows(
        model, stack(qd_ref), stack(qdd_ref), stack(tau), fs_hz, settings, q_ref=stack_optional(q_ref), q=stack_optional(q), t=stack_optional(t), k0=k
    )[0]


def reference_lag(q_ref: np.ndarray, q: np.ndarray, max_lag: int, max_samples: int = 200_000) -> int:
    """Delay ``L`` (samples, ``0 <= L <= max_lag``) minimising ``||q_ref(t - L) - q(t)||``.

    Uses positions only (no noisy derivatives): the lag by which the axis
    trails its reference. The regressor stays built from the noise-free
    reference, merely delayed by ``L``. The lag of a loop is a constant, so at
    most the first ``max_samples`` samples are used.
    """
    q_ref = np.asarray(q_ref, dtype=np.float64)[:max_samples]
    q = np.asarray(q, dtype=np.float64)[:max_samples]
    n = len(q)
    max_lag = max(0, min(int(max_lag), n // 4))
    costs = [float(np.mean((q_ref[: n - L] - q[L:]) ** 2)) for L in range(max_lag + 1)]
    return int(np.argmin(costs))


def delay_samples(x: np.ndarray, lag: int) -> np.ndarray:
    """``x(t - lag)`` on the same grid; the first ``lag`` samples repeat ``x[0]``."""
    if lag <= 0:
        return x
    return np.concatenate([np.full(lag, x[0]), x[: len(x) - lag]])


def reference_derivatives(q_ref: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration of a noise-free reference by central differences."""
    qd = central_difference(q_ref, dt_s)
    return qd, central_difference(qd, dt_s)


def identify_ilic(
    t: np.ndarray,
    q_ref: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: ILICSettings,
    *,
    qd_ref: np.ndarray | None = None,
    qdd_ref: np.ndarray | None = None,
    q: np.ndarray | None = None,
    valid: np.ndarray | None = None,
) -> ILICResult:
    """IDIM-ILIC estimates over consecutive windows of ``settings.window_s``.

    Windows hold ``round(window_s*fs)`` samples; a trailing part shorter than
    a window is left out (reported as ``dropped_s``). Missing reference
    derivatives are computed from ``q_ref`` by central differences.
    ``valid`` (boolean, one per sample) masks samples such as a saturated
    drive inside each window (see :func:`estimate_windows`).
    """
    n = int(round(settings.window_s * fs_hz))
    K = len(t) // n if n > 0 else 0
    if K == 0:
        raise ValueError(f"the log ({len(t) / fs_hz:.3g} s) is shorter than one window ({settings.window_s:g} s); choose a shorter window")
    if qd_ref is None or qdd_ref is None:
        qd_ref, qdd_ref = reference_derivatives(q_ref, 1.0 / fs_hz)
    lag = settings.ref_lag
    if lag is None:
        lag = reference_lag(q_ref, q, int(round(settings.max_ref_lag_s * fs_hz))) if q is not None else 0
    m = K * n
    q_ref_actual = q_ref
    q_ref, qd_ref, qdd_ref = (delay_samples(np.asarray(a, dtype=np.float64), lag) for a in (q_ref, qd_ref, qdd_ref))

    def cut(a: np.ndarray) -> np.ndarray:
        return np.asarray(a[:m], dtype=np.float64).reshape(K, n)

    def cut_optional(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else cut(a)

    valid = usable_mask(valid, np.shape(t))
    mask = None if valid is None else valid[:m].reshape(K, n)
    windows = estimate_windows(model, cut(qd_ref), cut(qdd_ref), cut(tau), fs_hz, settings, q_ref=cut(q_ref), q=cut_optional(q), t=cut(t), valid=mask)
    if lag and q is not None:  # the tracking error is the controller's: against the reference as recorded
        ratios = tracking_error_ratio(cut(q_ref_actual), cut(q))
        windows = [replace(w, tracking_error_ratio=float(r)) for w, r in zip(windows, ratios, strict=True)]
    return ILICResult(model=model.name, names=model.names, settings=settings, windows=windows, dropped_s=float((len(t) - m) / fs_hz), ref_lag=lag)
