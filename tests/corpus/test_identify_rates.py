"""``identify --method ls`` below 1 kHz on fresh draws of the robot corpus's clean dwell-and-move logs (issue 29: within
2 % at every rate). The corpus itself has 8 such logs at 250 Hz; here 16 a rate, on seeds the corpus does not use, with
sensor noise alone: the derivatives and the rows' band below 1 kHz (:func:`ilic_cli.filtering.rows_stencil`). Central
differences keeping 0.04·fs left 24-28 of 40 such logs within 2 % at 250 Hz, M +0.30 % on average; the plain sign of the
noisy velocity as the Coulomb column leaned Fv by +0.45 % on average at 250 Hz (:data:`ilic_cli.usable.SIGN_RULE`)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from ilic_cli.identify import identify
from ilic_cli.identify_report import to_markdown
from ilic_cli.runlog import RunLog
from tests.corpus.robot import ALL_AXES, AXES, DWELL_TRAJECTORIES, Case, simulate

SEED0 = 7000
"""Seeds beyond the corpus's (1-999, and 3000 more with ``--reseed 1``)."""


@pytest.mark.parametrize("fs", [250.0, 500.0])
def test_identify_is_within_2_percent_below_1_khz(fs: float) -> None:
    """All 16 logs (4 axes x 2 trajectories x 2 seeds) within 2 % of M, Fv and Fc, M within 0.25 % and Fv within 0.3 % on
    average (measured: 16 and 16 of 16, M +0.18 % and +0.08 %, Fv -0.11 % and -0.15 %, the largest Fv error 1.47 % at 250 Hz.
    With the Coulomb column's plain sign (before the expected sign of a noisy velocity, :data:`ilic_cli.usable.SIGN_RULE`):
    15 of 16 at 250 Hz, Fv +0.45 % on average, up to 2.71 %; central differences keeping 0.04·fs: 12)."""
    errors = []
    for k, (a, tr) in enumerate(itertools.product(AXES, DWELL_TRAJECTORIES)):
        for s in range(2):
            case = Case(a, tr, fs, "sensor", SEED0 + 97 * s + k)
            fit = identify(simulate(case, {}), method="ls").ls
            assert fit is not None
            theta = dict(zip(fit.result.names, fit.result.theta, strict=True))
            errors.append([theta[p] / AXES[a].truth[p] - 1.0 for p in ("M", "Fv", "Fc")])
    e = np.array(errors)
    within = int(np.count_nonzero(np.abs(e).max(axis=1) <= 0.02))
    assert within == len(e), (within, np.round(100 * e, 2).tolist())
    assert abs(float(e[:, 0].mean())) < 2.5e-3, np.round(100 * e[:, 0], 2).tolist()
    assert abs(float(e[:, 1].mean())) < 3e-3, np.round(100 * e[:, 1], 2).tolist()  # the noise's sign no longer leans Fv


@pytest.mark.parametrize(
    ("axis", "trajectory", "fs", "seed", "at"),
    [
        ("lin12", "s-curve", 8000.0, 4758, 0.8),
        ("lin200", "trapezoid", 8000.0, 4522, 0.8),
        ("rev0.5", "s-curve", 2000.0, 5037, 0.8),
        ("rev0.01", "trapezoid", 250.0, 4596, 0.8),
    ],
)
def test_a_log_with_a_gap_is_identified_from_its_parts(axis: str, trajectory: str, fs: float, seed: int, at: float) -> None:
    """A 0.3 s gap at 80 % of a clean dwell-and-move log: each part leaves out its edges at the gap (``idim_ls.part_valid``: four
    decimation spans, 40 ms at 8 kHz), the rest threshold is the log's top speed (``usable.rest_samples``), and too few rows is
    judged on the parts together. Within 2 % of M, Fv and Fc; before, Fv +7.2 % and Fc -14 %, refused ('only 0 decimated rows'),
    Fv +29 % and +24 %. (``benchmarks/identify_gaps.py``, 120 such logs, four axes, 250 Hz to 8 kHz, the gap at 30, 55 and 80 %:
    120 within 2 %; 84, and 4 refused, before.)"""
    log = simulate(Case(axis, trajectory, fs, "sensor", seed), {})
    t = log.t
    keep = (t < at * t[-1]) | (t > at * t[-1] + 0.3)
    gapped = RunLog({k: np.asarray(log[k])[keep] for k in ("t", "q", "tau", "q_ref")}, log.units, log.meta)
    report = identify(gapped, method="ls")
    fit = report.ls
    assert fit is not None and report.usable is not None
    theta = dict(zip(fit.result.names, fit.result.theta, strict=True))
    e = {p: theta[p] / ALL_AXES[axis].truth[p] - 1.0 for p in ("M", "Fv", "Fc")}
    assert max(abs(v) for v in e.values()) <= 0.02, e
    # the report counts the rows the fit uses, and says what the gap's edges left out
    u, md = report.usable, to_markdown(report)
    assert u.usable == fit.result.rows and f"{u.usable} of {u.decimated} decimated rows fitted" in md
    assert (f"; {u.gap_edges} at a gap's edges" in md) is (u.gap_edges > 0)  # none where the edges fall at rest (lin12 at 8 kHz)
