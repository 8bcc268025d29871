"""A value the closed-loop refit searched is stated with at least the folds' spread (:func:`ilic_cli.diagnosis.refit.with_folds_spread`).

The folds' values are those of the independent simulator's 0.01 kg·m² joint at 8 kHz (a 1.5 ms drive lag on a chirp,
seed 41), refitted to -1.753 ms with the curvature's ± 0.051 ms.
"""

from __future__ import annotations

import math

import pytest

from ilic_cli.diagnosis.decide import Decision
from ilic_cli.diagnosis.fits import Refit, ValueSearch
from ilic_cli.diagnosis.refit import with_folds_spread
from ilic_cli.diagnosis.verdicts import PROPOSED_BY_DRIFT, ReplayVerdict, Verdict

FOLDS = (-0.000505, -0.000485, -0.000393, -0.000210, -0.001449)
CURVATURE = 5.13e-5


def _refit() -> Refit:
    search = ValueSearch("delay", "delay", "s", -0.001594, -0.001753, -0.001753, CURVATURE, (-0.003625, 0.000375), 0.649, 0.634, 10, True, "searched")
    return Refit(True, "refitted", [], ("M", "Fv", "Fc", "delay"), value_std={"delay": CURVATURE}, searches=[search])


def _decision(folds: tuple[float, ...], accepted: bool = True, proposed_by: str | None = None) -> Decision:
    by = {} if proposed_by is None else {"proposed_by": proposed_by}
    verdict = ReplayVerdict("delay", 1.06, 0.755, 0.022, 0.018, 2e-10, None, None, accepted, "the replay agrees", searched=folds, verdict=Verdict.AGREES, **by)
    return Decision([], [verdict], None)


def _jackknife(values: tuple[float, ...]) -> float:
    k = len(values)
    mean = sum(values) / k
    return math.sqrt((k - 1) / k * sum((v - mean) ** 2 for v in values))


def test_the_folds_jackknife_states_a_value_the_curvature_understates() -> None:
    out = with_folds_spread(_refit(), _decision(FOLDS))
    spread = _jackknife(FOLDS)
    assert spread == pytest.approx(8.66e-4, rel=1e-3)  # the truth, -1.5 ms, 0.29 of it from -1.753 ms; 4.9 curvature σ
    assert out.value_std["delay"] == pytest.approx(spread, rel=1e-12)
    assert out.searches[0].std == pytest.approx(spread, rel=1e-12)
    assert out.searches[0].value == -0.001753  # the value is the refit's: only its spread is the folds'
    assert "folds' jackknife" in out.searches[0].reason


def test_folds_tighter_than_the_curvature_leave_it() -> None:
    tight = tuple(-0.001753 + 1e-6 * i for i in range(5))
    refit = _refit()
    assert with_folds_spread(refit, _decision(tight)).value_std["delay"] == CURVATURE


@pytest.mark.parametrize(("accepted", "proposed_by"), [(False, None), (True, PROPOSED_BY_DRIFT)])
def test_only_the_folds_of_a_value_the_replay_kept_and_searched_count(accepted: bool, proposed_by: str | None) -> None:
    out = with_folds_spread(_refit(), _decision(FOLDS, accepted, proposed_by))
    assert out.value_std["delay"] == CURVATURE
