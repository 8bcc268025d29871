"""The drive's lag behind its logged command, estimated on IDIM-LS's rows (:func:`drive_lag`, :data:`LAG_RULE`).

A drive's current (torque) loop applies the command it is given after its time constant: a 700 Hz loop 0.23 ms later.
The log holds the command, so IDIM-LS's residual keeps ``M lag dddq`` beside the hold's, and once the rows at rest are
left out every move starts and ends with a jerk of the same sign, which leans Fv one way and Fc the other (the robot
corpus's clean dwell-and-move logs under a 700 Hz loop: 12 of 64 beyond 2 %, Fv down to -5.3 %, Fc up to +3.4 %).
The lag is the one timing the rows determine well: the regressor evaluated later by the lag that minimises the residual.

Pure numerics: :func:`drive_lag` is handed IDIM-LS's system as a function of the lag (``identify`` binds the log to it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli.idim_ls import LSSettings
from ilic_cli.lm import minimise
from ilic_cli.lsq import finite_or_none, lstsq, robust_std

LAG_MAX_S = 2e-3
"""The longest drive lag searched (s). A drive's current loop lags its command by its time constant, a fraction of a
millisecond (a 700 Hz loop: 0.23 ms; a 300 Hz one: 0.53 ms). In seconds, not periods: the loop's bandwidth is the
drive's, whatever rate the log is written at. A longer timing error is no current loop's: ``diagnose`` seeks a delay."""

LAG_MIN_T = 6.0
"""A lag is applied when it exceeds this many of its robust standard deviations (one-sided: a drive lags, never leads).
Calibrated on the logs without one (104 clean dwell-and-move logs of the robot corpus, 250 Hz-8 kHz, four axes, with
sensor noise alone or a force disturbance): the loop's response to the position noise, which the regressor carries too,
acts as a timing of its own, up to 3.8 σ from 400 Hz up on the rows of :data:`LAG_BAND_HZ` and 5.1 σ at 250 Hz, whose rows
keep 16.7 Hz (up to 0.18 ms). Measured on those and 64 under a 700 Hz current loop: M, Fv, Fc
within 2 % on 128 of the 168 without the lag, 139 with it applied above 6 σ (137 above 3 σ, where 6 lag-free logs took
one); under the loop 52 -> 63 of 64, the lag-free logs as they were (76 of 104). That timing is a bias of the rows, not
their noise: its σ-count grows with the log's length, which at 250 Hz may carry it past 6 σ on a long log."""

LAG_BAND_HZ = 20.0
"""The band (Hz) of the rows the lag is estimated on: half the 40 Hz the fits' rows keep from 1 kHz up, and no more than
theirs below (250 Hz: fs/15). The moves' jerk, which carries the lag, lies below it (the corpus's speed ramps last 80-150
ms); above it the position noise, differentiated, and the loop's response to it make a timing of their own. Measured, 40
against 20 Hz: on 40 s logs of the 0.5 kg·m² elbow with sensor noise alone 0.08-0.11 ms (up to 8.5 σ) against 0.00-0.03 ms
(up to 2.9 σ); under the 700 Hz loop at 1 kHz 0.370 against 0.237 ms for its 0.227 ms."""

SUGGEST_T = 3.0
"""A lag of this many robust standard deviations, short of :data:`LAG_MIN_T`, is reported as suggested and not applied: the
usual significance, where the loop's response to the position noise and a weak drive lag cannot be told apart (the robot
corpus's --reseed 1 s3115: the 700 Hz loop at 250 Hz, 0.47 ± 0.12 ms, 3.9 σ; lag-free logs up to 5.1 σ)."""

EDGE_SHARE = 0.02
"""An estimate within this share of :data:`LAG_MAX_S` of its end is on the edge of the range searched: never applied."""

STEP_PERIODS = 0.02
"""The step (in sample periods) of the difference that gives the residual's slope in the lag, for its standard deviation."""

LAG_RULE = (
    f"when rows at rest are left out and the force is the drive's held command, the drive's lag is estimated: the regressor "
    f"evaluated later again by the lag in 0-{LAG_MAX_S * 1e3:g} ms that minimises IDIM-LS's residual on rows keeping at most "
    f"{LAG_BAND_HZ:g} Hz, applied when it exceeds "
    f"{LAG_MIN_T:g} of its robust standard deviations (Newey-West, on the residual's slope in the lag) and is off the range's "
    "end; a current loop's lag left out leans Fv and Fc by a few per cent once the dwells are left out. A lag stated with the "
    "model (--effect delay:delay=-SECONDS, 0 for none) is taken instead"
)
"""The rule, in words (the reports state it)."""


@dataclass(frozen=True)
class DriveLag:
    """The drive's lag estimated on a log: its value and robust standard deviation (s), whether it is applied and why not."""

    value_s: float
    std_s: float
    applied: bool
    reason: str = ""
    """Why it is not applied (``""`` when it is)."""
    at_edge: bool = False
    """At the end of the range searched (never applied nor suggested)."""

    @property
    def suggested(self) -> bool:
        """Not applied, but :data:`SUGGEST_T` standard deviations or more from 0 (off the range's end): the report says so."""
        return not self.applied and not self.at_edge and bool(np.isfinite(self.std_s)) and self.value_s > SUGGEST_T * self.std_s

    def to_dict(self) -> dict[str, Any]:
        return {
            "value_s": self.value_s,
            "std_s": finite_or_none(self.std_s),
            "applied": self.applied,
            "suggested": self.suggested,
            "not_applied_because": self.reason or None,
            "rule": LAG_RULE,
        }

    def words(self) -> str:
        """The estimate in a phrase (``0.229 ± 0.010 ms``)."""
        return f"{self.value_s * 1e3:.3g} ± {self.std_s * 1e3:.2g} ms"


def drive_lag(system: Callable[[float], tuple[np.ndarray, np.ndarray]], period_s: float, *, max_s: float = LAG_MAX_S, min_t: float = LAG_MIN_T) -> DriveLag:
    """The lag in ``[0, max_s]`` that minimises IDIM-LS's residual, its robust standard deviation, and whether it is applied
    (:data:`LAG_RULE`). ``system(lag)``: IDIM-LS's decimated system ``(W, y)`` with its regressor evaluated ``lag`` later
    again, beyond the hold (:func:`ilic_cli.idim_ls.decimated_systems`); ``period_s``: the log's sample period.

    The standard deviation is the Gauss-Newton one: the slope of the fitted force in the lag, one column beside the
    model's, its Newey-West standard deviation (:func:`ilic_cli.lsq.robust_std`) at the minimum.
    """
    built: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def at(d: float) -> tuple[np.ndarray, np.ndarray]:  # each lag's rows built once: the minimum is one of the lags searched
        if d not in built:
            built[d] = system(d)
        return built[d]

    lag = minimise(lambda d: lstsq(*at(d))[1], 0.0, max_s, use_log=False, rel_tol=1e-3)
    W, y = at(lag)
    theta, _ = lstsq(W, y)
    lo, hi = max(lag - STEP_PERIODS * period_s, 0.0), lag + STEP_PERIODS * period_s
    slope = (system(hi)[0] - system(lo)[0]) @ theta / (hi - lo)
    std = float(robust_std(np.c_[W, slope], y - W @ theta).std[-1])
    if lag >= (1.0 - EDGE_SHARE) * max_s:
        return DriveLag(lag, std, False, f"at the end of the range searched (0-{max_s * 1e3:g} ms): no current loop's", at_edge=True)
    if not (np.isfinite(std) and lag > min_t * std):
        return DriveLag(lag, std, False, f"within {min_t:g} of its robust standard deviations, what a log without a lag gives")
    return DriveLag(lag, std, True)


def lag_rows(ls: LSSettings, fs_hz: float) -> LSSettings:
    """The settings of the rows the lag is estimated on: the fits' (``ls``), keeping :data:`LAG_BAND_HZ` at most (a decimation
    given as it is: ``ls`` itself)."""
    if ls.band_hz is None:
        return ls
    return replace(ls, band_hz=min(ls.band_hz, LAG_BAND_HZ), at_hz=None).at_rate(fs_hz)
