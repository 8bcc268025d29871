"""The edge rule of the search, the extended regressor and the columns kept per data set (exact cases)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli.diagnosis.select import EDGE_STEPS, SECONDARY_EDGE, Step, at_edge, effect_columns, extended, search_range, shifted_force
from ilic_cli.effects import EFFECTS
from ilic_cli.effects.grids import delay_grid
from ilic_cli.idim_ls import lsq_rows
from ilic_cli.regressor import get_model
from tests.unit.synth import FS, motion, rigid_force


def test_edge_constants() -> None:
    assert (EDGE_STEPS, SECONDARY_EDGE) == (0.5, 0.02)


def test_log_grid_edges_at_half_a_step() -> None:
    grid = np.geomspace(0.001, 0.1, 21)  # a step of 10**0.1 in log
    stribeck = EFFECTS["stribeck"]
    half = 10 ** (0.1 * 0.5)
    assert at_edge(stribeck, grid, 0.001) == "vs = 0.001 m/s at the lower end of the range searched (0.001 to 0.1)"
    assert at_edge(stribeck, grid, 0.001 * half * 0.999) is not None and at_edge(stribeck, grid, 0.001 * half * 1.001) is None
    assert at_edge(stribeck, grid, 0.1) == "vs = 0.1 m/s at the upper end of the range searched (0.001 to 0.1)"
    assert at_edge(stribeck, grid, 0.1 / half * 1.001) is not None and at_edge(stribeck, grid, 0.1 / half * 0.999) is None
    assert at_edge(stribeck, np.array([0.01]), 0.01) is None  # a one-point grid brackets nothing: no edge claimed
    # in the units of the joint (corpus s3931 said "L = 1.442 m" of a revolute joint's ripple)
    assert at_edge(stribeck, grid, 0.1, "revolute") == "vs = 0.1 rad/s at the upper end of the range searched (0.001 to 0.1)"
    assert at_edge(EFFECTS["position_ripple"], grid, 0.1, "revolute") == "L = 0.1 rad at the upper end of the range searched (0.001 to 0.1)"
    assert at_edge(EFFECTS["delay"], grid, 0.1, "revolute") == "delay = 0.1 s at the upper end of the range searched (0.001 to 0.1)"


def test_a_lags_closed_loop_search_spans_2_ms_at_every_rate_from_1_khz() -> None:
    """The inverse model's bias of a drive lag is a time (0.3-0.7 ms), so its search reaches 2 ms either side at every rate;
    in steps of its half-sample grid alone it was 0.5 ms at 4 kHz (a 3 kg·m² joint's 1.41 ms lag, 1.71 ms by the inverse
    model, kept at 1.71 ms in every fold and rejected). Four steps at 1 kHz and below, where they reach 2 ms already."""
    delay = EFFECTS["delay"]
    for fs, steps in ((250.0, 4), (500.0, 4), (1000.0, 4), (2000.0, 8), (4000.0, 16), (8000.0, 32)):
        grid = delay_grid(None, fs)  # type: ignore[arg-type]  # the lag's grid needs no kinematics
        sub = search_range(delay, grid, -1.7e-3)
        assert len(sub) == 2 * steps + 1, (fs, len(sub))
        assert (sub[-1] - sub[0]) / 2 == pytest.approx(max(2e-3, 4 * 0.5 / fs)) and sub[0] < -1.7e-3 < sub[-1]
    assert len(search_range(EFFECTS["stribeck"], np.geomspace(0.001, 0.1, 41), 0.01)) == 21  # a vs's bias is a factor: 10 steps


def test_linear_grid_edges_and_unitless_names() -> None:
    lin = np.arange(-0.025, 0.02501, 0.0005)
    delay = EFFECTS["delay"]
    assert at_edge(delay, lin, -0.025 + 0.24 * 0.0005) == "delay = -0.02488 s at the lower end of the range searched (-0.025 to 0.025)"
    assert at_edge(delay, lin, -0.025 + 0.26 * 0.0005) is not None and at_edge(delay, lin, -0.025 + 0.51 * 0.0005) is None
    assert at_edge(delay, lin, 0.025 - 0.49 * 0.0005) is not None and at_edge(delay, lin, 0.025 - 0.51 * 0.0005) is None
    uneven = np.array([0.0, 1.0, 10.0])  # the steps at the two ends differ
    payload = EFFECTS["payload_change"]
    assert at_edge(payload, uneven, 0.49) is not None and at_edge(payload, uneven, 0.51) is None
    assert at_edge(payload, uneven, 5.51) is not None and at_edge(payload, uneven, 5.49) is None


def test_secondary_bounds() -> None:
    flex = EFFECTS["flexibility"]
    grid = np.geomspace(2.0, 40.0, 40)
    span = math.log(0.5) - math.log(0.005)
    just_in, just_out = math.exp(math.log(0.5) - 0.019 * span), math.exp(math.log(0.5) - 0.021 * span)
    assert at_edge(flex, grid, (16.8, just_in)) == f"damping_ratio = {just_in:.4g} at a bound of the range searched (0.005 to 0.5)"
    assert at_edge(flex, grid, (16.8, just_out)) is None
    assert at_edge(flex, grid, (16.8, math.exp(math.log(0.005) + 0.019 * span))) is not None
    assert at_edge(flex, grid, (16.8, math.exp(math.log(0.005) + 0.021 * span))) is None
    assert "f_res = 2 Hz at the lower end" in (at_edge(flex, grid, (2.0, 0.05)) or "")  # the first parameter of a pair


def _data():  # type: ignore[no-untyped-def]
    t, q, qd, qdd = motion(6000)
    return lsq_rows(t, q, rigid_force(qd, qdd), FS, get_model("rigid"))


def test_extended_regressor_and_the_columns_kept() -> None:
    base = get_model("rigid")
    steps = [Step(EFFECTS["spring"]), Step(EFFECTS["delay"], 0.001), Step(EFFECTS["position_ripple"], 0.02)]
    model = extended(base, steps, FS)
    assert model.names == ("M", "Fv", "Fc", "k_spring", "ripple_sin", "ripple_cos")
    assert model.name == "rigid+spring+delay+position_ripple"
    assert extended(base, [Step(EFFECTS["delay"], 0.001)], FS) is base  # a shift adds no column
    data = _data()
    kept = effect_columns(data, EFFECTS["spring"])
    assert effect_columns(data, EFFECTS["spring"]) is kept  # decimated once per data set
    assert effect_columns(data, EFFECTS["spring"], remember=False) is not kept
    np.testing.assert_array_equal(effect_columns(data, EFFECTS["spring"], remember=False), kept)
    assert ("spring", None) in data.memo and ("position_ripple", 0.03) not in data.memo
    effect_columns(data, EFFECTS["position_ripple"], 0.03, remember=False)
    assert ("position_ripple", 0.03) not in data.memo  # values tried while refining are not kept
    shifted = shifted_force(data, 0.002)
    assert shifted_force(data, 0.002) is shifted and ("shift", 0.002) in data.memo
    shifted_force(data, 0.003, remember=False)
    assert ("shift", 0.003) not in data.memo
