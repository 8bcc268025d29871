"""The replay's integration step by the log's rate (:func:`ilic_cli.simulation.replay.replay_substeps`)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from ilic_cli.simulation.replay import LAW_INSIDE_STEP_S, REPLAY_STEP_S, replay, replay_substeps
from plant.controllers import PDSettings
from tests.conftest import make_synthetic_log

STEPS = [(250.0, 10, 10), (500.0, 10, 10), (1000.0, 5, 10), (1024.0, 5, 10), (2000.0, 3, 5), (4000.0, 2, 3), (8000.0, 2, 2), (20000.0, 2, 2)]
"""``(rate, substeps, substeps of a law inside the dynamics)``."""


@pytest.mark.parametrize(("fs_hz", "substeps", "inside"), STEPS)
def test_a_tenth_of_the_period_but_no_finer_than_the_step(fs_hz: float, substeps: int, inside: int) -> None:
    """Ten substeps up to 500 Hz; above, steps of at most 0.2 ms (0.1 ms for a law inside the dynamics), and at least two."""
    assert replay_substeps(fs_hz) == substeps and replay_substeps(fs_hz, continuous=True) == inside
    assert 1.0 / (fs_hz * substeps) <= max(REPLAY_STEP_S, 0.1 / fs_hz) * (1 + 1e-9)
    assert 1.0 / (fs_hz * inside) <= max(LAW_INSIDE_STEP_S, 0.1 / fs_hz) * (1 + 1e-9)


@pytest.mark.parametrize(("fs_hz", "substeps", "inside"), [(1000.0, 5, 10), (8000.0, 2, 2)])
def test_the_diagnosis_s_replay_integrates_at_that_step(fs_hz: float, substeps: int, inside: int) -> None:
    """The step by the law the replay runs: the log's, or the controller given."""
    log = make_synthetic_log(samples=200, rate_hz=fs_hz)
    plant = {"M": 95.0, "Fv": 200.0, "Fc": 20.0}
    law = PDSettings(velocity="exact", delay_samples=0.0, continuous=True)
    for sim, n in ((replay(log, plant, None), substeps), (replay(log, plant, None, controller=law), inside)):
        assert sim.meta["simulation"]["substeps"] == n and sim.meta["simulation"]["dt"] == pytest.approx(1.0 / (fs_hz * n))
    inside_log = replace(log, meta={**log.meta, "controller": law.to_dict()})
    assert replay(inside_log, plant, None).meta["simulation"]["substeps"] == inside  # the log's own law
