"""The rows every fit of a log uses, the one definition (:func:`with_rest`, :data:`REST_RULE`).

A decimated row is left out when the drive saturates or the axis stands still anywhere in its span. A stuck
axis carries any force within the static friction, so the sign of the Coulomb column is undefined there. A log
without standstill (the EMPS recordings: their reversals pass through zero speed in 9 ms) keeps every row, and
the published procedure is unchanged. :func:`identification_hold_s`: when the regressor is evaluated half a
period later (the drive's held command).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.errors import IdentificationError, IlicError
from ilic_cli.filtering import butter_lowpass_zero_phase
from ilic_cli.idim_ls import LSSettings, min_samples, part_valid
from ilic_cli.prepare import PreparedLog, RestSamples, tau_sensor
from ilic_cli.row_spans import valid_rows
from ilic_cli.runlog import RunLog

STANDSTILL_FRACTION = 0.01
"""A sample may be at rest when its filtered speed is below this fraction of the top speed (the 99.5th percentile)."""


REST_MIN_S = 0.03
"""Samples below that speed are at rest when they last at least this long (s): longer than a reversal takes to pass
through the band (DATA_EMPS.mat's 31 reversals: 9 ms; the corpus's trapezoid ramps: 3 ms), shorter than any dwell a
trajectory plans (the corpus's: 100 ms). In seconds, not samples: a reversal takes as long at any rate."""


REST_RULE = (
    f"a sample is at rest where the filtered speed stays below {100 * STANDSTILL_FRACTION:g} % of the top speed for at least "
    f"{1e3 * REST_MIN_S:g} ms (a dwell; a reversal passes through faster), and so is every sample within the position filter's reach "
    "(1/cutoff) of one; a decimated row whose span touches such a sample is left out of every fit: a stuck axis carries any force "
    "within the static friction, so the sign of the Coulomb column is undefined there"
)
"""The rule for samples at rest, in words (the reports state it)."""


SIGN_RULE = (
    "once rows at rest are left out, the Coulomb column is the expected sign of the filtered velocity given its noise, "
    "erf(qd / (sqrt(2) s)), s the velocity's RMS over the dwells: the sign of a noisy velocity near rest is a coin toss "
    "whose leak through the decimation filter biases Fv and Fc (measured at 250 Hz: Fv +1.6 % with the sign, +0.6 % with the expected sign); a log "
    "without standstill keeps the sign (the published procedure)"
)
"""The rule for the Coulomb column's sign, in words (the reports state it; :func:`identification_speed_noise`)."""


def rest_samples(q: np.ndarray, fs_hz: float, settings: LSSettings = LSSettings(), segments: tuple[tuple[int, int], ...] | None = None) -> RestSamples:
    """The samples of ``q`` at rest, by :data:`REST_RULE`; each contiguous part of ``segments`` on its own.

    The speed is that of the fit (``settings``' position filter and
    derivative); the top speed is the log's, the largest of its parts' beyond the trimmed edge (a part after a gap that holds
    no move had found most of its dwell above 1 % of its own noise, and fitted it: Fv up to +29 % on a 0.5 kg·m² S-curve with a
    gap at 80 % of its length). A part shorter than :func:`min_samples` is left as it is (IDIM-LS leaves it out).
    """
    q = np.asarray(q, dtype=np.float64)
    settings = settings.at_rate(fs_hz)
    mask = np.zeros(len(q), dtype=bool)
    dwells, threshold, square, still = 0, 0.0, 0.0, 0
    shortest = max(int(np.ceil(REST_MIN_S * fs_hz - 1e-9)), 1)
    reach = int(round(fs_hz / settings.cutoff_hz))  # the position filter's reach (samples)
    speeds = []
    for a, b in segments or ((0, len(q)),):
        if b - a < min_samples(settings):
            continue
        speed = derivative(butter_lowpass_zero_phase(q[a:b], settings.cutoff_hz, fs_hz, settings.order, matlab=settings.matlab), 1.0 / fs_hz, settings.stencil)
        np.abs(speed, out=speed)  # in place: the filtered position is let go; each part's speed is kept until the log's top speed is known
        speeds.append((a, b, speed))
    # the top speed is the log's, over its parts: a part between gaps that holds no move has only its noise for a top speed
    below = threshold = STANDSTILL_FRACTION * max((float(np.percentile(v[settings.trim :], 99.5)) for _, _, v in speeds), default=0.0)
    for a, b, speed in speeds:
        edges = np.flatnonzero(np.diff(np.r_[0, (speed < below).astype(np.int8), 0]))
        part = mask[a:b]
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start >= shortest:  # a dwell, widened by the filter's reach
                dwells += 1
                part[max(start - reach, 0) : stop + reach] = True
                core = speed[max(start + reach, settings.trim) : stop - reach]  # the velocity's noise: beyond the filter's reach of the moves
                square, still = square + float(np.dot(core, core)), still + len(core)
    noise = float(np.sqrt(square / still)) if still else 0.0
    return RestSamples(mask=mask, dwells=dwells, speed_threshold=threshold, rule=REST_RULE, speed_noise=noise)


def with_rest(prepared: PreparedLog, settings: LSSettings = LSSettings()) -> PreparedLog:
    """``prepared`` with its samples at rest masked (:func:`rest_samples` of the measured position), the one
    definition of the samples every fit of the log uses (identify's methods and the diagnosis alike); a log whose position or
    force never changes is refused (:func:`nothing_to_fit`)."""
    if prepared.rest is not None:
        return prepared
    log = prepared.log
    if (why := nothing_to_fit(log["q"], log["tau"]) or glitches(log)) is not None:
        raise IdentificationError(prepared.source, why)
    return prepared.with_rest(rest_samples(log["q"], prepared.fs_hz, settings, prepared.segments))


def nothing_to_fit(q: np.ndarray, tau: np.ndarray) -> str | None:
    """Why a log whose position or force is the same at every sample has nothing to fit, else ``None``. Fitted, a frozen position
    gave ``identify`` M = Fv = Fc = 0 (a rank-deficient matrix) and a force of zeros M = Fv = Fc = 0, both with exit 0, and the
    diagnosis 'Undecided' with exit 0 and NumPy's warnings on stderr."""
    q, tau = np.asarray(q), np.asarray(tau)
    if len(q) and np.ptp(q) == 0.0:
        return f"the position is {float(q[0]) + 0.0:.6g} at every sample: the axis never moves (a frozen sensor?), nothing to fit"
    if len(tau) and np.ptp(tau) == 0.0:
        return f"the force is {float(tau[0]) + 0.0:.6g} at every sample: it carries no dynamics (a channel not logged?), nothing to fit"
    return None


GLITCH_SPANS = 10.0
"""A sample beyond the band of a channel's 0.1 to 99.9 % percentiles by more than this many times the band's width is a glitch
(:func:`glitch`). Measured, the farthest any sample lies beyond it: 0.27 widths (``DATA_EMPS_PULSES.mat``'s force, its pulses),
0.005 on ``DATA_EMPS.mat``, 0.2 over the robot corpus's 189 logs, 0.01 on the paper's and the benchmark's simulations."""


def glitch(name: str, x: np.ndarray, t: np.ndarray) -> str | None:
    """Why channel ``x`` (``name``; ``t`` its time stamps) holds a glitch, a sample far outside all the others (:data:`GLITCH_SPANS`),
    else ``None``. Fitted, one sample of the force at 1e6 N·m in a 0.5 kg·m² joint's log gave ``identify`` M = -84 kg·m² (refused as
    a force that opposes the motion, which it was not)."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 2:
        return None
    lo, hi = (float(v) for v in np.percentile(x, [0.1, 99.9]))
    width = hi - lo
    beyond = np.maximum(lo - x, x - hi)
    far = beyond > GLITCH_SPANS * width
    if width <= 0.0 or not far.any():
        return None
    i = int(np.argmax(beyond))
    return (
        f"{name} has {int(far.sum())} sample(s) far outside all the others ({x[i]:.4g} at t = {float(t[i]):.6g} s, 99.8 % of the "
        f"samples within [{lo:.4g}, {hi:.4g}]): a logger's glitch? no model is fitted to it or compared with it; remove it"
    )


def glitches(log: RunLog) -> str | None:
    """Why a log's position or force holds a glitch (:func:`glitch`), else ``None``: the check of every command that reads the
    recording against a model, the fits (:func:`with_rest`) and ``replay`` (:func:`refuse_glitches`)."""
    return glitch("the position", log["q"], log.t) or (glitch("the force", log["tau"], log.t) if "tau" in log else None)


def refuse_glitches(prepared: PreparedLog) -> None:
    """Refuse a prepared log whose position or force holds a glitch (:func:`glitches`): a replay compared with it reported a
    force error of 100 % for one sample at 1e6 N·m in a 0.5 kg·m² joint's log, whatever the model."""
    if (why := glitches(prepared.log)) is not None:
        raise IlicError(prepared.source, why)


def rows_left_out(mask: np.ndarray, settings: LSSettings, segments: tuple[tuple[int, int], ...] | None = None, *, gap_edges: bool = False) -> tuple[int, int]:
    """``(decimated rows, rows whose span touches a True sample of mask)`` over the parts IDIM-LS fits
    (:func:`ilic_cli.idim_ls.decimated_systems`; ``settings`` at the log's rate); ``gap_edges``: and those a gap's edges leave out
    (:func:`ilic_cli.idim_ls.part_valid`)."""
    spans = segments or ((0, len(mask)),)
    total = touched = 0
    for i, (a, b) in enumerate(spans):
        if b - a < min_samples(settings) and len(spans) > 1:
            continue
        usable = part_valid(~np.asarray(mask[a:b], dtype=bool), b - a, gap_edges and i > 0, gap_edges and i < len(spans) - 1, settings)
        assert usable is not None
        rows = valid_rows(usable[settings.trim :], settings.decimation)
        total += len(rows)
        touched += int(np.count_nonzero(~rows))
    return total, touched


MIN_ROWS_PER_COLUMN = 4
"""A diagnosis fits a model only on more than this many rows per column (:func:`too_few_rows`): its F-tests, held-out blocks
and prewhitening need residual degrees of freedom beyond the parameters'."""


@dataclass(frozen=True)
class UsableRows:
    """The decimated rows of a log every fit uses, and why the others are left out (the one rule: :data:`REST_RULE`).

    Attributes
    ----------
    decimated : int
        Decimated rows of the log's contiguous parts.
    at_rest : int
        Rows whose span touches a sample at rest (:func:`rest_samples`).
    saturated : int
        Rows whose span touches a sample of a saturated drive.
    usable : int
        Rows left: those IDIM-LS fits (the diagnosis leaves out its timing rows beyond them).
    rest : RestSamples or None
        The samples at rest and the rule.
    hold_s : float
        How much later than each sample the regressor is evaluated (:func:`held`): half a period when the force
        is the drive's held command and rows at rest are left out (:func:`identification_hold_s`), else 0.
    speed_noise : float
        The velocity's noise whose expected sign the Coulomb column is (:func:`identification_speed_noise`; 0: the sign).
    gap_edges : int
        Rows left out, beyond those at rest or saturated, at a gap's edges (:func:`ilic_cli.idim_ls.part_valid`).
    """

    decimated: int
    at_rest: int
    saturated: int
    usable: int
    rest: RestSamples | None
    hold_s: float = 0.0
    speed_noise: float = 0.0
    gap_edges: int = 0

    def gap_words(self) -> str:
        """``"; N at a gap's edges"`` when the gaps' edges leave rows out, else ``""``."""
        return f"; {self.gap_edges} at a gap's edges (the filters' transients there, mid-motion)" if self.gap_edges else ""

    def sign_words(self, position_unit: str) -> str:
        """The Coulomb column's sign in a phrase (the JSON and docs/methods.md state :data:`SIGN_RULE` whole), with the velocity's
        noise in ``position_unit`` per second; ``""``: the plain sign."""
        if not self.speed_noise:
            return ""
        return (
            f"the Coulomb column erf(v / (√2 σv)), the expected sign of a velocity whose noise σv is {self.speed_noise:.3g} {position_unit}/s over the dwells"
        )

    def too_few(self, fitted: int, columns: int) -> str | None:
        """Why ``fitted`` rows are too few for a fit of ``columns`` columns (not more than :data:`MIN_ROWS_PER_COLUMN` each), and what
        left the others out; ``None``: enough."""
        if fitted > MIN_ROWS_PER_COLUMN * columns:
            return None
        why = [f"{n} touch a saturated drive" if k == "s" else f"{n} a sample at rest" for k, n in (("s", self.saturated), ("r", self.at_rest)) if n]
        if self.usable > fitted:
            why.append(f"{self.usable - fitted} more a velocity reversal or the filter's edges")
        left_out = f"; of the others, {', '.join(why)}" if why else ""
        return f"only {fitted} of {self.decimated} decimated rows to fit{left_out}: too few for {columns} parameters"

    def to_dict(self) -> dict[str, Any]:
        return {
            "rule": REST_RULE,
            "decimated_rows": self.decimated,
            "rows_at_rest": self.at_rest,
            "rows_saturated": self.saturated,
            "usable_rows": self.usable,
            "rows_at_gap_edges": self.gap_edges,
            "dwells": None if self.rest is None else self.rest.dwells,
            "samples_at_rest": None if self.rest is None else self.rest.count,
            "rest_speed_threshold": None if self.rest is None else self.rest.speed_threshold,
            "regressor_delay_s": self.hold_s,
            "sign_speed_noise": self.speed_noise,
            "coulomb_sign": SIGN_RULE,
            "force_timing": FORCE_TIMING_RULE,
        }


FORCE_TIMING_RULE = (
    "a force that is the drive's command held over each period is the model's mean over it: the regressor is evaluated "
    "half a period later when rows at rest are left out; the published procedure (a log without standstill) evaluates it "
    "at the sample instants"
)
"""When identification evaluates the regressor half a period later (:func:`identification_hold_s`), in words."""


UNKNOWN_FORCE_TIMING = (
    "the log does not say how its force samples the drive (no controller, no drive command): the regressor is evaluated at the "
    "sample instants; if the force is a drive's command held over each period, Fv and Fc lean by a few per cent once rows at "
    "rest are left out (up to 6 % measured): declare the loop that ran to have it evaluated half a period later"
)
"""The warning of :func:`force_timing_unknown`."""


def rest_left_out(prepared: PreparedLog) -> RestSamples | None:
    """The samples at rest of ``prepared`` when its fits leave rows at rest out (some sample is at rest), else ``None``: the
    condition of the rules a log without standstill does not take (the hold, the expected sign; the published procedure)."""
    rest = prepared.rest
    return rest if rest is not None and rest.count else None


def force_timing_unknown(prepared: PreparedLog) -> bool:
    """Whether ``prepared`` leaves rows at rest out while its force's timing is unknown (:func:`ilic_cli.prepare.tau_sensor`:
    ``None``): its fit evaluates the regressor at the sample instants, which biases Fv and Fc if the force is a held command."""
    return rest_left_out(prepared) is not None and tau_sensor(prepared.log) is None


def identification_hold_s(prepared: PreparedLog) -> float:
    """How much later than each sample IDIM-LS evaluates the regressor of ``prepared`` (:data:`FORCE_TIMING_RULE`).

    Half a period when the force is the drive's held command (:attr:`ilic_cli.prepare.PreparedLog.hold_s`) and
    rows at rest are left out, else 0. Neglecting the hold leaves ``M T/2 dddq`` in the residual: over whole moves
    it averages out (DATA_EMPS.mat: 0.1 % of M, the published tables), but every move that starts and ends at
    rest starts and ends with a jerk of the same sign, so once its rows at rest are left out the term biases Fv and
    Fc (measured on PD dwell-and-move logs at 250 Hz-8 kHz: up to 6 % at 1 kHz without it, within 1 % with it).
    """
    return prepared.hold_s if rest_left_out(prepared) is not None else 0.0


def identification_speed_noise(prepared: PreparedLog) -> float:
    """The velocity's noise whose expected sign the Coulomb column of every fit of ``prepared`` is (:data:`SIGN_RULE`):
    the RMS of the filtered velocity over its dwells when rows at rest are left out, else 0 (the sign)."""
    return rest.speed_noise if (rest := rest_left_out(prepared)) is not None else 0.0


def usable_rows(prepared: PreparedLog, settings: LSSettings = LSSettings()) -> UsableRows:
    """The :class:`UsableRows` of ``prepared`` (after :func:`with_rest`) under ``settings``."""
    n = len(prepared.log)
    settings = settings.at_rate(prepared.fs_hz)
    segs = prepared.segments or ((0, n),)
    none = np.zeros(n, dtype=bool)
    total, at_rest = rows_left_out(none if prepared.rest is None else prepared.rest.mask, settings, segs)
    _, saturated = rows_left_out(none if prepared.saturated is None else prepared.saturated, settings, segs)
    mask = none if prepared.valid is None else ~prepared.valid
    _, unusable = rows_left_out(mask, settings, segs, gap_edges=True)
    _, masked = rows_left_out(mask, settings, segs) if len(segs) > 1 else (total, unusable)
    return UsableRows(
        total, at_rest, saturated, total - unusable, prepared.rest, identification_hold_s(prepared), identification_speed_noise(prepared), unusable - masked
    )


def too_few_rows(prepared: PreparedLog, settings: LSSettings, fitted: int, columns: int) -> str | None:
    """Why ``fitted`` rows of ``prepared`` are too few for ``columns`` columns (:data:`MIN_ROWS_PER_COLUMN`), with what left the
    others out (:meth:`UsableRows.too_few`); ``None``: enough. The rows' summary is built only to refuse."""
    if fitted > MIN_ROWS_PER_COLUMN * columns:
        return None
    return usable_rows(prepared, settings).too_few(fitted, columns)
