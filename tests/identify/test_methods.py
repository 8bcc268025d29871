"""The one estimator interface and the one registry of methods (issue 32 item 1).

Every method is reached through its registry entry (:mod:`ilic_cli.methods`) and returns a
:class:`~ilic_cli.estimators.base.Fit` whose figures are its own result's; the closed-loop methods simulate
through the loop they are handed, never through an import of the plant.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest

from ilic_cli.closed_loop_id import closed_loop_identify
from ilic_cli.commands.identify import command as identify_command
from ilic_cli.errors import ParameterError
from ilic_cli.estimators import Fit, ModelSpec
from ilic_cli.estimators.closed_loop import ClosedLoopFitSettings
from ilic_cli.identify import IdentifyReport, identify
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io import read_log
from ilic_cli.methods import CHOICES, COMPOSITES, METHODS, OUTPUT_ERROR, choices, methods_of, model_method
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import get_model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.loop import PLANT_LOOP
from ilic_cli.usable import with_rest


@pytest.fixture(scope="module")
def emps(emps_mat: Path) -> RunLog:
    return read_log(emps_mat)


@pytest.fixture(scope="module")
def report(emps: RunLog) -> IdentifyReport:
    return identify(emps, method="both")


def test_the_registry_names_every_choice_once() -> None:
    assert set(CHOICES) == set(METHODS) | set(COMPOSITES) and len(CHOICES) == len(set(CHOICES))
    assert not set(METHODS) & set(COMPOSITES)
    option = next(p for p in identify_command.params if p.name == "method")
    assert isinstance(option.type, click.Choice) and tuple(option.type.choices) == CHOICES  # the CLI reads the registry
    assert choices(output_error=False) == ("ls", "ilic", "both", "didim", "iv", "all")
    assert OUTPUT_ERROR == tuple(m for m, entry in METHODS.items() if entry.output_error)  # the names the help lists agree with the estimators
    for composite in COMPOSITES.values():
        assert set(composite.methods) <= set(METHODS) and composite.model_from in composite.methods


def test_methods_run_in_order_the_start_first() -> None:
    assert methods_of("didim") == ("ls", "didim")  # DIDIM starts from IDIM-LS, reported beside it
    assert methods_of("all") == ("ls", "didim", "iv", "ilic")  # IDIM-ILIC last: its warnings follow the others'
    assert methods_of("ilic") == ("ilic",)
    assert model_method("all") == "didim" and model_method("both") == "ls" and model_method("oe") == "oe"


def test_a_fit_is_its_methods_own_result(report: IdentifyReport) -> None:
    ls = report.fit("ls")
    assert ls is not None and ls.detail is report.ls and ls.method == "IDIM-LS"
    r = report.ls.result  # type: ignore[union-attr]
    assert ls.names == r.names and np.array_equal(ls.theta, r.theta) and np.array_equal(ls.std, r.std)
    np.testing.assert_allclose(np.sqrt(np.diag(ls.cov)), r.std, rtol=1e-9)  # the covariance's diagonal is eq. 9's variances
    assert np.allclose(ls.cov, ls.cov.T) and np.all(np.linalg.eigvalsh(ls.cov) > 0)
    assert ls.residual_rms == pytest.approx(r.error_norm / np.sqrt(r.rows)) and ls.rows == r.rows == 2480
    ilic = report.fit("ilic")
    assert ilic is not None and ilic.diagnostics["k"] == report.ilic.windows[-1].k  # type: ignore[union-attr]
    assert [f.name for f in report.fits] == ["ls", "ilic"]  # the registry's order


def test_fit_serialises_and_tabulates(report: IdentifyReport) -> None:
    ls = report.fit("ls")
    assert ls is not None
    doc = json.loads(json.dumps(ls.to_dict(), allow_nan=False))
    assert doc["method"] == "IDIM-LS" and set(doc["parameters"]) == set(ls.names) and len(doc["covariance"]) == len(ls.names)
    frame = ls.to_frame()
    assert list(frame["parameter"]) == list(ls.names) and frame["value"].to_numpy() == pytest.approx(ls.theta)


def test_the_estimator_fits_a_prepared_log(emps: RunLog, report: IdentifyReport) -> None:
    prepared = with_rest(prepare_log(emps), LSSettings())
    fit = METHODS["ls"].bind().fit(prepared, ModelSpec("rigid-offset"), LSSettings())
    assert isinstance(fit, Fit) and np.array_equal(fit.theta, report.ls.result.theta)  # type: ignore[union-attr]
    asym = METHODS["ls"].bind().fit(prepared, ModelSpec("asymmetric"), LSSettings())
    assert asym.names != fit.names and "Fc_pos" in asym.names


class CountingLoop:
    """The plant's loop, counting the replays it is asked for."""

    def __init__(self) -> None:
        self.replays = 0

    def replay(self, log: RunLog, params: dict[str, float], effects: dict[str, Any] | None) -> RunLog:
        self.replays += 1
        return PLANT_LOOP.replay(log, params, effects)

    def __getattr__(self, name: str) -> Any:
        return getattr(PLANT_LOOP, name)


def test_closed_loop_methods_simulate_through_the_loop_they_are_handed(emps: RunLog, report: IdentifyReport) -> None:
    loop = CountingLoop()
    prepared = with_rest(prepare_log(emps), LSSettings())
    start = tuple(float(x) for x in report.ls.result.theta)  # type: ignore[union-attr]
    settings = ClosedLoopFitSettings(METHODS["didim"].settings().iteration, LSSettings(), start)
    fit = METHODS["didim"].bind(loop).fit(prepared, ModelSpec("rigid-offset"), settings)
    assert fit.method == "DIDIM" and loop.replays == fit.diagnostics["iterations"] + 1  # the start's replay, then one per iteration
    assert fit.plant is not None and fit.plant[0]["M"] == pytest.approx(fit.theta[0])


def test_a_closed_loop_fit_needs_a_loop(emps: RunLog) -> None:
    with pytest.raises(ParameterError, match="loop"):
        closed_loop_identify("didim", emps, get_model("rigid"), np.array([95.0, 200.0, 20.0]))
