"""IDIM-LS: offline inverse dynamic identification by least squares (paper section III).

The benchmark procedure (``emps-benchmark.md``): zero-phase Butterworth
low-pass of the measured position, central-difference velocity and
acceleration, edge trimming, observation matrix from the model's columns,
parallel decimation of the force and of every column, least squares with
standard deviations (eq. 9) and relative standard deviations (eq. 10).
With the defaults it reproduces the published EMPS tables to every digit.

The rows every fit uses, the one definition (:func:`ilic_cli.usable.with_rest`, :data:`ilic_cli.usable.REST_RULE`): a
decimated row is left out when the drive saturates or the axis stands still
anywhere in its span. A stuck axis carries any force within the static
friction, so the sign of the Coulomb column is undefined there. A log without
standstill (the EMPS recordings: their reversals pass through zero speed in
9 ms) keeps every row, and the published procedure is unchanged.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.estimators.columns import Derived
from ilic_cli.filtering import (
    ROWS_BAND_HZ,
    butter_lowpass_zero_phase,
    decimate_matlab,
    decimated_band_hz,
    kept_indices,
    lowpass_decimate,
    rows_decimation,
    rows_stencil,
)
from ilic_cli.lsq import LSResult, RobustStd, SigmaConvention, evaluate, most_correlated, robust_std, solve
from ilic_cli.regressor import Kinematics, Model
from ilic_cli.row_spans import usable_mask, valid_rows


@dataclass(frozen=True)
class LSSettings:
    """Filtering and decimation of IDIM-LS (defaults: the published benchmark).

    Attributes
    ----------
    cutoff_hz : float
        Position low-pass cut-off (benchmark: 100 Hz, 5x the loop bandwidth).
    order : int
        Butterworth order of the position filter.
    decimation : int
        Parallel decimation factor (benchmark: round(0.8*500/40) = 10); set from the log's rate by ``band_hz``
        unless that is ``None`` (:meth:`at_rate`).
    trim : int
        Samples dropped at the start (edge effects of the filters).
    matlab : bool
        MATLAB-compatible filtering (transfer-function filtfilt padding and
        Chebyshev decimation, end-aligned); otherwise SciPy second-order
        sections and a Butterworth anti-alias filter.
    sigma : {"sample_std", "eq8"}
        Error standard deviation: the benchmark's sample std (default) or
        the paper's eq. (8).
    band_hz : float or None
        The widest band the decimated rows keep (:data:`ilic_cli.filtering.ROWS_BAND_HZ`): the decimation is
        :func:`ilic_cli.filtering.rows_decimation` at the log's rate (:meth:`at_rate`, which every fit calls);
        ``None``: ``decimation`` as given (``identify --decimation N``).
    at_hz : float or None
        The rate :meth:`at_rate` set ``decimation`` for (``None``: not yet set).
    stencil : int
        Points of the derivatives' central stencil (:func:`ilic_cli.derivatives.derivative`): 3, the benchmark's central
        differences, or 5 where the rows' band is more than 0.04 of the rate (:func:`ilic_cli.filtering.rows_stencil`,
        set with ``decimation`` by :meth:`at_rate`).
    """

    cutoff_hz: float = 100.0
    order: int = 4
    decimation: int = 10
    trim: int = 49
    matlab: bool = True
    sigma: SigmaConvention = "sample_std"
    band_hz: float | None = ROWS_BAND_HZ
    at_hz: float | None = None
    stencil: int = 3

    def at_rate(self, fs_hz: float) -> LSSettings:
        """These settings for a log sampled at ``fs_hz``: the decimation and the derivatives' stencil by
        :func:`ilic_cli.filtering.rows_decimation` and :func:`~ilic_cli.filtering.rows_stencil` (every command's fits use them)."""
        if self.band_hz is None or self.at_hz == fs_hz:
            return self
        return replace(self, decimation=rows_decimation(fs_hz, self.band_hz), stencil=rows_stencil(fs_hz, self.band_hz), at_hz=fs_hz)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        del d["at_hz"]
        if d["band_hz"] is None:
            del d["band_hz"]
        return d


@dataclass(frozen=True)
class IDIMData:
    """Filtered, trimmed signals at the full rate and the decimated system.

    Diagnosis adds columns with :meth:`decimate` and solves again.
    """

    kin: Kinematics
    tau: np.ndarray
    W: np.ndarray
    y: np.ndarray
    fs_hz: float
    settings: LSSettings
    rows: np.ndarray | None = None
    memo: dict[Any, np.ndarray] = field(default_factory=dict, repr=False, compare=False)
    """Decimated columns already computed on this data, by key (:meth:`decimate_once`)."""
    shift_s: float = 0.0  # how much later than the samples the kinematics are evaluated (held)
    position_noise_std: float = 0.0
    """The measured position's noise (m or rad; 0: not known), realised in the columns by :mod:`ilic_cli.diagnosis.column_noise`."""
    joint: str = "prismatic"
    """The joint's type (:func:`ilic_cli.runlog.joint_type`): the units the diagnosis's reasons write its values in."""
    unaccelerated: tuple[tuple[float, float], ...] = ()
    """The spans of the log (s, their first and last samples) where the reference does not accelerate, its cruises and dwells:
    a payload's change there shows in no row but through the noise (:func:`ilic_cli.diagnosis.search.unaccelerated_spans`;
    none without a reference)."""

    @property
    def t_dec(self) -> np.ndarray:
        """Time of the decimated rows (s) that were kept (see ``rows``)."""
        assert self.kin.t is not None
        t = self.kin.t[kept_indices(len(self.kin.t), self.settings.decimation)]
        return t if self.rows is None else t[self.rows]

    def decimate(self, x: np.ndarray) -> np.ndarray:
        """Decimate full-rate trimmed column(s) exactly as the force was (masked rows left out)."""
        d = _decimate(np.asarray(x, dtype=np.float64), self.settings, self.fs_hz)
        return d if self.rows is None else d[self.rows]

    def decimate_once(self, key: Any, full: Callable[[], np.ndarray]) -> np.ndarray:
        """``decimate(full())``, computed once per ``key`` on this data (diagnosis asks for the same columns many times)."""
        if key not in self.memo:
            self.memo[key] = self.decimate(full())
        return self.memo[key]


@dataclass(frozen=True)
class IDIMLSResult:
    """IDIM-LS estimate of one log."""

    model: str
    result: LSResult
    settings: LSSettings
    t: np.ndarray | None = None
    y: np.ndarray | None = None
    y_hat: np.ndarray | None = None
    kept: np.ndarray | None = None
    """The decimated rows fitted, among all of them (the contiguous parts' stacked); ``None``: every one."""
    hold_s: float = 0.0
    """How much later than its sample the regressor was evaluated (:func:`held`; 0: at the sample instants)."""
    robust: RobustStd | None = None
    """The standard deviations widened for the residual's autocorrelation, beside eq. 9's (:func:`robust_std`)."""
    speed_noise: float = 0.0
    """The velocity's noise whose expected sign the Coulomb column is (:func:`lsq_rows`; 0: the sign)."""

    def to_dict(self) -> dict[str, Any]:
        d = {"method": "IDIM-LS", "model": self.model, **self.result.to_dict(), "settings": self.settings.to_dict()}
        d |= {"regressor_delay_s": self.hold_s, "sign_speed_noise": self.speed_noise}
        if self.robust is not None:
            d["robust_std"] = self.robust.to_dict(self.result.names, self.result.std)
        if (pair := self.most_correlated()) is not None:
            d["most_correlated"] = {"parameters": [pair[0], pair[1]], "correlation": pair[2]}
        return d

    def most_correlated(self) -> tuple[str, str, float] | None:
        """The two estimates whose errors lean together most (:func:`ilic_cli.lsq.most_correlated`), with their correlation."""
        return None if self.result.cov is None else most_correlated(self.result.names, self.result.cov)

    def to_frame(self) -> Any:
        import pandas as pd  # deferred: pandas costs ~0.3 s of import, paid only by a caller of to_frame()

        r = self.result
        return pd.DataFrame({"parameter": r.names, "value": r.theta, "std": r.std, "rel_std_pct": r.rel_std_pct})


def _decimate(x: np.ndarray, settings: LSSettings, fs_hz: float) -> np.ndarray:
    if settings.matlab:
        return decimate_matlab(x, settings.decimation, axis=0)
    return lowpass_decimate(x, settings.decimation, decimated_band_hz(fs_hz, settings.decimation), fs_hz, 8, axis=0)


def held(data: IDIMData, model: Model, shift_s: float) -> IDIMData:
    """``data`` with ``model``'s regressor (and every effect column built later) evaluated ``shift_s`` later.

    Parameters
    ----------
    data : IDIMData
        Prepared with ``model`` (:func:`lsq_rows`).
    model : Model
        The regressor of ``data.W``.
    shift_s : float
        Half a period when the logged force is the held command (:attr:`ilic_cli.prepare.PreparedLog.hold_s`);
        0 returns ``data`` itself.

    Returns
    -------
    IDIMData
        Same force, time stamps and rows; kinematics linearly interpolated at
        ``t + shift_s`` (the last value held at the end, inside the trimmed
        edge rows) and the decimated regressor rebuilt from them.
    """
    if shift_s == 0.0:
        return data
    return replace(rebuilt(data, model, data.kin.later(shift_s)), shift_s=data.shift_s + shift_s)


def rebuilt(data: IDIMData, model: Model, kin: Kinematics) -> IDIMData:
    """``data`` with kinematics ``kin`` and ``model``'s decimated regressor rebuilt from them (same force and rows)."""
    return replace(data, kin=kin, W=np.ascontiguousarray(data.decimate(model.matrix(kin))), memo={})


def lsq_rows(
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: LSSettings = LSSettings(),
    *,
    extra: dict[str, np.ndarray] | None = None,
    valid: np.ndarray | None = None,
    speed_noise: float = 0.0,
) -> IDIMData:
    """Filter, differentiate, trim, build and decimate the IDIM system (eqs. 5-6).

    Parameters
    ----------
    t, q, tau : ndarray
        Time (s), measured position and force, sampled at ``fs_hz``.
    fs_hz : float
        Sampling frequency.
    model : Model
        Regressor columns.
    settings : LSSettings
        Filtering and decimation.
    extra : dict, optional
        Further full-rate channels made available to columns (trimmed alike).
    valid : ndarray of bool, optional
        Full-rate samples that may be used; the decimated rows whose span
        touches an invalid sample are dropped (:func:`valid_rows`). ``None``
        (or all True) keeps every row.
    speed_noise : float
        The velocity's noise (RMS): the Coulomb column is its expected sign (:func:`ilic_cli.regressor.expected_sign`); 0: ``sign``.
    """
    settings = settings.at_rate(fs_hz)
    qf, W, y, rows = _system(t, q, tau, fs_hz, model, settings, valid, extra=extra, speed_noise=speed_noise)
    s = slice(settings.trim, None)
    kin = Kinematics(*differentiated(qf, fs_hz, settings), t=np.asarray(t, dtype=np.float64)[s], extra=_trimmed(extra, s), speed_noise=speed_noise)
    return IDIMData(kin=kin, tau=np.asarray(tau, dtype=np.float64)[s], W=W, y=y, fs_hz=fs_hz, settings=settings, rows=rows)


def filtered_position(q: np.ndarray, fs_hz: float, settings: LSSettings) -> np.ndarray:
    """The IDIM position filter (zero-phase Butterworth, ``settings``' cut-off and order) applied to ``q``."""
    return butter_lowpass_zero_phase(np.asarray(q, dtype=np.float64), settings.cutoff_hz, fs_hz, settings.order, matlab=settings.matlab)


def differentiated(qf: np.ndarray, fs_hz: float, settings: LSSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(qd, qdd, q)`` of a filtered position by ``settings``' stencil, the first ``settings.trim`` samples left out."""
    qd = derivative(qf, 1.0 / fs_hz, settings.stencil)
    qdd = derivative(qd, 1.0 / fs_hz, settings.stencil)
    s = slice(settings.trim, None)
    return qd[s], qdd[s], qf[s]


def _trimmed(extra: dict[str, np.ndarray] | None, s: slice) -> dict[str, np.ndarray]:
    return {k: np.asarray(v, dtype=np.float64)[s] for k, v in (extra or {}).items()}


def _too_few_rows(left: int, model: Model) -> None:
    """Refuse ``left`` decimated rows for ``model``: not more than one beyond its columns."""
    if left <= len(model.columns) + 1:
        why = "the samples left out (a saturated drive, the axis at rest, a gap's edges)"
        raise ValueError(f"only {left} decimated rows are left once {why} are masked; too few for {len(model.columns)} parameters")


def _system(
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: LSSettings,
    valid: np.ndarray | None,
    shift_s: float = 0.0,
    extra: dict[str, np.ndarray] | None = None,
    speed_noise: float = 0.0,
    *,
    one_part: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(qf, W, y, rows)`` of :func:`lsq_rows` (``settings`` at the log's rate; ``qf`` the filtered position, untrimmed).
    ``one_part``: the log is this part alone, refused with too few rows; a part of several is judged with the others
    (:func:`decimated_systems`).

    Each column is built, decimated and let go in turn from kinematics differentiated for it alone
    (:class:`ilic_cli.estimators.columns.Derived`): beside the log, the filtered position and at most two more full-rate arrays live at once.
    ``shift_s``: the columns evaluated that much later (:func:`held`'s, bit for bit); ``speed_noise``: :func:`lsq_rows`'.
    """
    if len(q) < min_samples(settings):
        raise ValueError(f"too few samples ({len(q)}) for IDIM-LS with trim {settings.trim} and decimation {settings.decimation}")
    s = slice(settings.trim, None)
    rows = None
    valid = usable_mask(valid, np.shape(q))
    if valid is not None:
        rows = valid_rows(valid[s], settings.decimation)
        if one_part:
            _too_few_rows(int(np.count_nonzero(rows)), model)
    y = _decimate(np.asarray(tau, dtype=np.float64)[s], settings, fs_hz)
    qf = filtered_position(q, fs_hz, settings)
    tt = np.asarray(t, dtype=np.float64)[s]
    extra_s = _trimmed(extra, s)
    columns = []
    for c in model.columns:  # the parallel decimation, one column at a time: the full-rate matrix is never held
        col = np.broadcast_to(c.build(Derived(qf, 1.0 / fs_hz, settings.trim, tt, shift_s, extra_s, settings.stencil, speed_noise)), tt.shape)
        columns.append(_decimate(np.asarray(col, dtype=np.float64), settings, fs_hz))
        del col
    Wy = np.column_stack([*columns, y])
    if rows is not None:
        Wy = Wy[rows]
    return qf, np.ascontiguousarray(Wy[:, :-1]), np.ascontiguousarray(Wy[:, -1]), rows


def _columns(model: Model, kin: Kinematics, *more: np.ndarray) -> Iterator[np.ndarray]:
    """The columns of ``model.matrix(kin)`` built one at a time, then ``more``."""
    shape = np.shape(kin.qd)
    for c in model.columns:
        yield np.broadcast_to(c.build(kin), shape)
    yield from more


def min_samples(settings: LSSettings) -> int:
    """Fewest samples :func:`lsq_rows` takes (edge trim plus the decimation filter's padding; ``settings`` at the log's rate: :meth:`LSSettings.at_rate`)."""
    return settings.trim + 3 * settings.decimation * 9 + 1


GAP_EDGE_SPANS = 4
"""How many decimation spans either side of a gap a part leaves out (:func:`part_valid`): the anti-alias filter's reach, where a
part's edge mixes the filters' transients into its rows. On 120 logs with a 0.3 s gap (``benchmarks/identify_gaps.py``: four axes,
250 Hz to 8 kHz, S-curves and trapezoids, the gap at 30, 55 and 80 % of the log), 120 within 2 % of M, Fv and Fc with 4 or 8 spans,
112 with the start's ``trim`` alone (49 samples: 6 ms at 8 kHz)."""


def gap_edge(settings: LSSettings) -> int:
    """Samples a part leaves out at an edge that is a gap (``settings`` at the log's rate): :data:`GAP_EDGE_SPANS` decimation
    spans, and never fewer than the ``trim`` every part's start leaves out."""
    return max(settings.trim, GAP_EDGE_SPANS * settings.decimation)


def part_valid(valid: np.ndarray | None, n: int, after_gap: bool, before_gap: bool, settings: LSSettings) -> np.ndarray | None:
    """The samples of a contiguous part of ``n`` samples that IDIM-LS may use: ``valid`` (``None``: every one), and not the
    :func:`gap_edge` samples at an edge that is a gap: the position filter, the derivatives and the anti-alias filter have an
    edge there, mid-motion where a log's own start and end are at rest. A 0.3 s gap cut in a move of the 0.5 kg·m² joint's 500 Hz
    trapezoid left Fv +3.75 % and Fc -2.8 % off, -0.38 and +0.24 % without its edges (the whole log: -0.40 and +0.25 %). A log's
    own start and end keep the published procedure's (``trim`` at the start)."""
    if not (after_gap or before_gap):
        return valid
    out = np.ones(n, dtype=bool) if valid is None else np.array(valid, dtype=bool)
    edge = gap_edge(settings)
    if after_gap:
        out[:edge] = False
    if before_gap:
        out[max(n - edge, 0) :] = False
    return out


def decimated_systems(
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: LSSettings,
    valid: np.ndarray | None,
    segments: tuple[tuple[int, int], ...] | None,
    hold_s: float = 0.0,
    speed_noise: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(W, y, t_dec, kept)`` of the contiguous ``segments`` (default: the whole log), each filtered and decimated on its own, stacked.

    Segments shorter than :func:`min_samples` are left out; none left is an error; a part leaves out its edges at a gap
    (:func:`part_valid`); too few rows is an error of the parts together, not of one (a 0.3 s gap before the
    200 kg axis's last move at 8 kHz left the part after it almost all at rest, and no row at the drive lag's 20 Hz). ``hold_s``: the regressor is
    evaluated that much later (:func:`held`); ``speed_noise``: :func:`lsq_rows`'. ``kept``: the rows fitted among all
    decimated rows of the parts (``None``: all).
    """
    settings = settings.at_rate(fs_hz)
    spans = segments or ((0, len(q)),)
    parts = []
    for i, (a, b) in enumerate(spans):
        if b - a < min_samples(settings) and len(spans) > 1:
            continue
        v = part_valid(None if valid is None else valid[a:b], b - a, i > 0, i < len(spans) - 1, settings)
        _, W, y, rows = _system(t[a:b], q[a:b], tau[a:b], fs_hz, model, settings, v, hold_s, speed_noise=speed_noise, one_part=len(spans) == 1)
        td = t[a:b][settings.trim :][kept_indices(b - a - settings.trim, settings.decimation)]
        parts.append((W, y, td if rows is None else td[rows], np.ones(len(td), dtype=bool) if rows is None else rows))
    if not parts:
        raise ValueError(f"no contiguous part of the log has the {min_samples(settings)} samples IDIM-LS needs")
    W, y, td, kept = (np.concatenate(x) for x in zip(*parts, strict=True))
    if len(spans) > 1:  # the parts' rows together: a part with few rows of its own (a long dwell after a gap) adds them
        _too_few_rows(len(y), model)
    return W, y, td, None if kept.all() else kept


def idim_ls(
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: LSSettings = LSSettings(),
    *,
    valid: np.ndarray | None = None,
    segments: tuple[tuple[int, int], ...] | None = None,
    hold_s: float = 0.0,
    speed_noise: float = 0.0,
) -> IDIMLSResult:
    """IDIM-LS estimate of ``model`` from measured position and force.

    ``valid`` (boolean, one per sample) masks samples such as a saturated
    drive: the decimated rows they touch are left out (see :func:`lsq_rows`).
    ``segments`` (``(start, stop)`` sample ranges between gaps of the time
    stamps): each is filtered, differentiated and decimated on its own, never
    across a gap, and their rows are solved together; the estimate equals that
    of the segments' rows stacked by hand. ``hold_s``: the regressor is evaluated that much later than each
    sample (:func:`held`; the published procedure: 0). ``speed_noise``: the Coulomb column is the expected sign of the
    velocity given that noise (:func:`lsq_rows`; the published procedure: 0, the sign).
    """
    t, q, tau = (np.asarray(a, dtype=np.float64) for a in (t, q, tau))
    settings = settings.at_rate(fs_hz)
    W, y, t_dec, kept = decimated_systems(t, q, tau, fs_hz, model, settings, valid, segments, hold_s, speed_noise)
    result = solve(W, y, model.names, sigma=settings.sigma)
    y_hat = W @ result.theta
    robust = robust_std(W, y - y_hat)
    robust = replace(robust, std=np.where(np.isfinite(result.std), robust.std, np.inf))  # not identifiable: as eq. 9 says
    return IDIMLSResult(
        model=model.name, result=result, settings=settings, t=t_dec, y=y, y_hat=y_hat, kept=kept, hold_s=hold_s, robust=robust, speed_noise=speed_noise
    )


def cross_validate(
    theta: np.ndarray,
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    model: Model,
    settings: LSSettings = LSSettings(),
    *,
    valid: np.ndarray | None = None,
    segments: tuple[tuple[int, int], ...] | None = None,
    hold_s: float = 0.0,
    speed_noise: float = 0.0,
) -> LSResult:
    """Apply estimates ``theta`` to another log with the same processing (cross-test validation; ``valid``, ``segments``,
    ``hold_s``, ``speed_noise`` as :func:`idim_ls`: the other log's own)."""
    t, q, tau = (np.asarray(a, dtype=np.float64) for a in (t, q, tau))
    W, y, _, _ = decimated_systems(t, q, tau, fs_hz, model, settings, valid, segments, hold_s, speed_noise)
    return evaluate(W, y, np.asarray(theta, dtype=np.float64), model.names)
