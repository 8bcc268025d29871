"""The drive's lag estimated by ``identify`` where the model states none (:func:`ilic_cli.drive_lag.drive_lag`, issue 29).

Measured on 168 clean dwell-and-move logs of the robot corpus (its four seed sets and the beyond set, 250 Hz-8 kHz): under
the 700 Hz current loop the lag is found on 63 of 64, 0.21-0.31 ms at 500 Hz-8 kHz for the loop's 0.227 ms (0.25-0.47 ms
at 250 Hz: the loop's response to the position noise adds to it), and M, Fv, Fc come within 2 % on 63 (52 without it); on
none of the 104 without a lag is one applied."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.drive_lag import LAG_BAND_HZ, LAG_MAX_S, DriveLag, drive_lag, lag_rows
from ilic_cli.errors import IdentificationError
from ilic_cli.estimators.base import ModelSpec
from ilic_cli.identify import identify
from ilic_cli.identify_report import to_markdown
from ilic_cli.idim_ls import LSSettings, decimated_systems
from ilic_cli.io import read_log
from ilic_cli.prepare import prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.usable import identification_hold_s, identification_speed_noise, with_rest
from tests.corpus.robot import ALL_AXES, Case, build, simulate

LOOP_LAG_S = 1.0 / (2.0 * np.pi * 700.0)
"""The corpus's current loop: a first-order lag of 0.227 ms."""
LOOP = Case("rev0.5", "trapezoid", 250.0, "current_loop", 9115)
"""The 0.5 kg·m² elbow under the loop at 250 Hz: without the lag Fv -4.4 % and Fc +2.5 % on average over 6 seeds."""
SENSOR = Case("lin12", "s-curve", 500.0, "sensor", 1)
"""The 12 kg axis, sensor noise alone: the rows give no lag (0.001 ± 0.012 ms)."""


@cache
def _log(case: Case) -> RunLog:
    return build(case).log


def _errors(log: RunLog, effects: dict[str, float] | None = None) -> dict[str, float]:
    r = identify(log, method="ls", effects=effects).ls
    assert r is not None
    truth = ALL_AXES[LOOP.axis if log is _log(LOOP) else SENSOR.axis].truth
    return {n: float(r.result.theta[r.result.names.index(n)] / truth[n] - 1.0) for n in ("M", "Fv", "Fc")}


def test_the_loops_lag_is_found_and_takes_its_bias_off() -> None:
    log = _log(LOOP)
    report = identify(log, method="ls")
    lag = report.drive_lag
    assert lag is not None and lag.applied and lag.reason == "", lag
    assert 0.25e-3 < lag.value_s < 0.6e-3 and lag.value_s > 3 * lag.std_s, lag  # 0.370 ± 0.034 ms measured
    assert report.ls is not None and report.ls.hold_s == pytest.approx(2e-3 + lag.value_s)  # the hold, then the lag
    found, none = _errors(log), _errors(log, {"delay": 0.0})
    assert all(abs(e) < 0.02 for e in found.values()), found
    assert none["Fv"] < -0.02, none  # stated none: the bias the lag leaves (Fv -3.4 % on this seed, +0.15 % with it)
    assert report.model_effects() == {"delay": {"delay": pytest.approx(-lag.value_s)}}  # the model file keeps it, as a stated one
    assert report.to_dict()["effects"] == {}  # stated: none
    d = report.to_dict()["drive_lag"]
    assert d["applied"] is True and d["value_s"] == lag.value_s and "drive's held command" in d["rule"]
    assert f"the drive's lag, {lag.words()}, estimated on the log" in to_markdown(report)


def test_no_lag_is_applied_where_the_rows_show_none() -> None:
    log = _log(SENSOR)
    report = identify(log, method="ls")
    lag = report.drive_lag
    assert lag is not None and not lag.applied and lag.reason.startswith("within 6 of its robust"), lag
    stated_none = identify(log, method="ls", effects={"delay": 0.0})
    assert stated_none.drive_lag is None  # a stated lag (0: none) is taken instead
    assert report.ls is not None and stated_none.ls is not None
    assert np.array_equal(report.ls.result.theta, stated_none.ls.result.theta)  # not applied: the same fit bit for bit


def test_a_lag_beyond_the_range_is_never_applied() -> None:
    """A 3 ms delay is no current loop's: the minimum sits at the range's end and nothing moves."""
    case = Case("lin12", "s-curve", 1000.0, "sensor", 2)
    log = simulate(case, {"delay": {"delay": -3e-3}})
    prepared = with_rest(prepare_log(log), LSSettings().at_rate(1000.0))
    p = prepared.log
    model = ModelSpec().regressor(1000.0)
    hold, noise = identification_hold_s(prepared), identification_speed_noise(prepared)
    assert hold == pytest.approx(0.5e-3)
    lag = drive_lag(
        lambda d: decimated_systems(p.t, p["q"], p["tau"], 1000.0, model, LSSettings(), prepared.valid, prepared.segments, hold + d, noise)[:2], 1e-3
    )
    assert lag.value_s > 0.98 * LAG_MAX_S and not lag.applied and "end of the range" in lag.reason, lag
    assert identify(log, method="ls").to_dict()["ls"]["regressor_delay_s"] == pytest.approx(hold)


def test_a_log_without_standstill_keeps_the_published_procedure(emps_mat: Path) -> None:
    report = identify(read_log(emps_mat), method="ls")
    assert report.drive_lag is None and report.to_dict()["drive_lag"] is None
    assert report.ls is not None and report.ls.hold_s == 0.0


def test_a_log_idim_ls_cannot_fit_is_refused_as_its_fit_refuses_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """The lag's search builds IDIM-LS's system first: where it cannot (no part of the log long enough), the same error."""
    import ilic_cli.identify as ident

    def short(*_: object) -> tuple[np.ndarray, np.ndarray]:
        raise ValueError("no contiguous part of the log has the 212 samples IDIM-LS needs")

    monkeypatch.setattr(ident, "decimated_systems", short)
    with pytest.raises(IdentificationError, match="no contiguous part of the log has the 212 samples"):
        identify(_log(LOOP), method="ls")


def test_the_lag_is_sought_on_rows_keeping_20_hz_at_most() -> None:
    """Above 20 Hz the position noise, differentiated, and the loop's response to it make a timing of their own (module doc)."""
    assert LAG_BAND_HZ == 20.0
    assert lag_rows(LSSettings().at_rate(1000.0), 1000.0).decimation == 20  # the fits' rows: 10 (40 Hz)
    assert lag_rows(LSSettings().at_rate(2000.0), 2000.0).decimation == 40
    low, fits = lag_rows(LSSettings().at_rate(250.0), 250.0), LSSettings().at_rate(250.0)
    assert (low.decimation, low.stencil) == (fits.decimation, fits.stencil) == (6, 5)  # fs/15 = 16.7 Hz: the fits' own rows
    given = LSSettings(decimation=7, band_hz=None)
    assert lag_rows(given, 1000.0) is given  # a decimation given is kept as given


def test_a_lag_short_of_the_gate_is_suggested_and_how_to_state_it_said() -> None:
    """The corpus's --reseed 1 s3115 (the 700 Hz loop at 250 Hz): 0.47 ± 0.12 ms, 3.9 σ, not applied (Fv -3.7 %): the report
    says the rows suggest it and how to state it; a lag-free log's 0.001 ± 0.012 ms is not mentioned."""
    report = identify(build(Case("rev0.5", "trapezoid", 250.0, "current_loop", 3115)).log, method="ls")
    lag = report.drive_lag
    assert lag is not None and not lag.applied and lag.suggested and 3 < lag.value_s / lag.std_s < 6, lag
    text = to_markdown(report)
    assert f"The rows suggest a drive lag of {lag.words()}" in text and f"`--effect delay:delay={-lag.value_s:.3g}`" in text
    assert report.to_dict()["drive_lag"]["suggested"] is True
    quiet = identify(_log(SENSOR), method="ls")
    assert quiet.drive_lag is not None and not quiet.drive_lag.suggested and "The rows suggest" not in to_markdown(quiet)
    edge = DriveLag(2e-3, 1e-5, False, "at the end", at_edge=True)
    assert not edge.suggested  # 200 σ, but at the range's end: never
