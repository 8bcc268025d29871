"""The standard deviations the diagnosis states of the inverse model's estimates: ``identify``'s robust ones (issue 29: honest
about uncertainty; :func:`ilic_cli.lsq.robust_covariance`).

Under the robot corpus's 10 Hz force disturbance the residual is coloured down to the moves' own frequencies. The covariance of
the least squares whitened by the residual's AR model (BIC order) took that colour for noise it could whiten away: on the 12 kg
trapezoid at 1 kHz (``lin12/trapezoid/1000Hz/disturbance/clean/s5``) it stated Fc ± 1.25 % where Fc was 5.6 % off and 20 draws
of the disturbance spread it by 3.1 % (``identify``'s Newey-West σ: 2.75 %). The sandwich states 2.75 % too.
"""

from __future__ import annotations

import pytest

from ilic_cli.diagnosis import diagnose
from ilic_cli.identify import identify
from tests.corpus.robot import ALL_AXES, case_named, simulate


def test_the_base_estimates_are_stated_with_identify_s_robust_std_on_the_same_rows() -> None:
    case = case_named("lin12/trapezoid/1000Hz/disturbance/clean/s5")
    log = simulate(case, {})
    diag = diagnose(log)
    base = diag.to_dict()["base"]["parameters"]
    ls = identify(log, method="ls").to_dict()["ls"]
    truth = ALL_AXES[case.axis].truth
    for n in ("M", "Fv", "Fc"):
        assert base[n]["value"] == ls["parameters"][n]["value"]  # the same rows and model
        assert base[n]["std"] == pytest.approx(ls["robust_std"]["std"][n], rel=1e-12)
    assert abs(base["Fc"]["value"] / truth["Fc"] - 1) < 2.58 * base["Fc"]["std"] / truth["Fc"]  # 5.6 % off, 2.0 stated σ
    assert base["Fc"]["std"] / truth["Fc"] > 0.025  # the whitened covariance's 1.25 % is not
