"""The PD loop's computation delay (``PDSettings.delay_samples``): where the command acts, and what is logged."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.errors import ParameterError
from ilic_cli.simulation.timing import pd_law_residuals
from plant.controllers import PDSettings
from plant.replay import simulate_replay
from tests.conftest import make_synthetic_log

PARAMS = {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}


def _acting_share(delay_samples: float) -> tuple[np.ndarray, object]:
    """Least squares of the force balance over each period on the logged commands ``u[k-1], u[k]``: their shares of the period."""
    log = make_synthetic_log(samples=2000)
    sim = simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=delay_samples))
    T = sim.dt_s
    q, qd, u = sim["q"], sim["qd_plant"], sim["tau"]
    k = np.arange(1, len(q) - 1)
    v_mean = (q[k + 1] - q[k]) / T
    sliding = (np.abs(qd[k]) > 0.01) & (np.abs(qd[k + 1]) > 0.01) & (np.sign(qd[k]) == np.sign(qd[k + 1]))
    # M dv/T = mean applied force - Fv*mean velocity - Fc*sign - offset (friction is linear between reversals)
    y = PARAMS["M"] * (qd[k + 1] - qd[k]) / T + PARAMS["Fv"] * v_mean + PARAMS["Fc"] * np.sign(qd[k]) + PARAMS["offset"]
    A = np.c_[u[k - 1], u[k]][sliding]
    return np.linalg.lstsq(A, y[sliding], rcond=None)[0], sim


@pytest.mark.parametrize("delay", [0.0, 0.4, 0.75])
def test_a_same_sample_command_acts_after_its_lag(delay: float) -> None:
    """Inverse of forward: the command logged at k (the law on q(k)) acts over the last 1 - delay of the period, the one before over the first part."""
    share, sim = _acting_share(delay)
    np.testing.assert_allclose(share, [delay, 1.0 - delay], atol=2e-3)
    c = PDSettings()
    law = pd_law_residuals(sim["q"], sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, sim.dt_s)
    assert law.follows == "same" and law.same_pct < 1e-9  # logged as the EMPS recordings log it
    assert sim.meta["controller"]["delay_samples"] == delay


def test_the_documented_loop_is_unchanged() -> None:
    """delay_samples = 1 (the default): the command from the previous sample, acting over the whole period it is logged at."""
    share, sim = _acting_share(1.0)
    np.testing.assert_allclose(share, [0.0, 1.0], atol=2e-3)
    c = PDSettings()
    assert pd_law_residuals(sim["q"], sim["q_ref"], sim["vir"], sim["pulses"], c.kp, c.kv, c.vmax, sim.dt_s).follows == "previous"
    assert sim.meta["controller"]["delay_samples"] == 1 and isinstance(sim.meta["controller"]["delay_samples"], int)


def test_delay_samples_is_checked() -> None:
    log = make_synthetic_log(samples=200)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ParameterError, match="delay_samples"):
            simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=bad))
    with pytest.raises(ParameterError, match="ramped pulses"):
        simulate_replay(log, PARAMS, controller=PDSettings(delay_samples=0.5, pulse_input="ramp"))
