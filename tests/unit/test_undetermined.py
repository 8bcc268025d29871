"""An estimate the log does not determine is said so (``Estimate.determined``): its 95 % interval holds 0 (issue 29: honest
about uncertainty). Gravity's ``MX`` on a swing of ±0.4 rad is one: ``cos q`` hardly moves there, and the offset takes it."""

from __future__ import annotations

import math

from ilic_cli.diagnosis.core import diagnose
from ilic_cli.diagnosis.report import _undetermined, to_markdown
from ilic_cli.effects import Estimate
from ilic_cli.effects.definition import Z95
from tests.corpus.robot import Case, build


def test_an_interval_holding_0_is_not_determined() -> None:
    assert Estimate(0.0598, 0.0583, "kg·m").determined is False  # 1.03 of its std
    assert Estimate(0.0575, 0.0066, "kg·m").determined is True
    assert Estimate(1.0, 1.001 / Z95).determined is False  # 0 just inside the interval
    assert Estimate(1.0, 0.99 / Z95).determined is True
    assert Estimate(-2.0, 0.5).determined is True  # a negative value is as determined as a positive one
    assert Estimate(1.0, math.inf).determined is False and Estimate(1.0, None).determined is True  # no std: nothing claimed
    assert Estimate(0.0598, 0.0583, "kg·m").to_dict()["determined"] is False


def test_the_finding_says_which_estimates_the_log_does_not_determine() -> None:
    said = _undetermined({"MX": Estimate(0.05984, 0.0583, "kg·m"), "MY": Estimate(0.05748, 0.00663, "kg·m"), "k": Estimate(1.0, math.inf, "N/m")})
    assert said == "; not determined by this log, its 95 % interval holding 0: MX = 0.05984 ± 0.0583 kg·m, k (no finite std)"
    assert _undetermined({"MY": Estimate(0.05748, 0.00663, "kg·m")}) == ""


def test_gravity_on_a_short_swing_names_its_undetermined_moment() -> None:
    """The corpus's s530 (0.5 kg·m² multisine at 500 Hz, ±0.4 rad under the 10 Hz disturbance): gravity is named, MY within
    17 % of the truth, MX 0.060 ± 0.058 for 0.061: the log does not tell it from none, and the report says so."""
    built = build(Case("rev0.5", "multisine", 500.0, "disturbance", 530, ("gravity",), 0.4))
    diag = diagnose(built.log)
    (gravity,) = [f for f in diag.findings if f.effect.id == "gravity"]
    assert not gravity.parameters["MX"].determined and gravity.parameters["MY"].determined, gravity.parameters
    assert "; not determined by this log, its 95 % interval holding 0: MX = " in to_markdown(diag)
