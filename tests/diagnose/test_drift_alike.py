"""A warm-up of Fv on moves at one cruise speed is as well one of Fc: the finding says so (issue 29 item 5;
:mod:`ilic_cli.diagnosis.drift_alike`). The independent simulator's 3 kg·m² joint (Coulomb friction three times the viscous
at cruise), S-curves at 250 Hz, Fv warming up by a quarter with a time constant of 2.5 s (``benchmarks/corpus_independent.py``'s
``friction_drift``), seed 61 of the probe that found it."""

from __future__ import annotations

import pytest

from ilic_cli.diagnosis import DiagnoseSettings, Diagnosis, diagnose
from ilic_cli.diagnosis.report import to_markdown
from tests.corpus.independent import run_loop
from tests.corpus.robot import ALL_AXES, reference


@pytest.fixture(scope="module", params=["previous", "same"])
def diagnosed(request: pytest.FixtureRequest) -> tuple[str, Diagnosis]:
    axis = ALL_AXES["rev3"]
    _, q_ref = reference(axis, "s-curve", 250.0, 61, 10.0)
    warm_up = {"drift": {"dFv": -0.25 * axis.truth["Fv"], "tau": 2.5}}
    return request.param, diagnose(run_loop(axis, 250.0, q_ref, request.param, warm_up, 61, "rev3", 40), settings=DiagnoseSettings())


def test_a_drift_the_rows_cannot_place_is_stated_with_both_coefficients(diagnosed: tuple[str, Diagnosis]) -> None:
    """Under the loop a period late the trend of Fc was kept (p = 1.2e-96), Fc -0.485 +- 0.015 N·m for the truth's Fv -0.5 N·m·s/rad
    at 1 rad/s, and nothing said of Fv; each trend given the other: p = 0.92 and 1. Under the loop at its sample the trend of Fv
    given Fc's is significant (p = 0.0005): Fv alone, as the truth (planted: either test alone, fails)."""
    loop, diag = diagnosed
    (finding,) = [f for f in diag.findings if f.effect.id == "friction_drift"]
    assert diag.drift is not None
    alike = diag.drift.alike
    if loop == "previous":
        assert alike is not None and alike.parameter == "Fv" and "Fc_change" in finding.parameters
        assert "the rows cannot tell which of Fc and Fv drifts" in finding.evidence.reason and finding.note.startswith("a trend of Fv explains")
        assert diag.drift.to_dict()["alike"]["parameter"] == "Fv" and finding.to_dict()["note"] == finding.note
        report = to_markdown(diag)
        assert "(exponential, time constant 3.36 s)). " in report and "The rows cannot tell which of Fc and Fv drifts." in report
    else:
        assert alike is None and "Fv_change" in finding.parameters and "cannot tell" not in finding.evidence.reason + to_markdown(diag)
        assert diag.drift.to_dict()["alike"] is None
