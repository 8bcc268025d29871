"""The replay's integration step by the log's rate (:func:`ilic_cli.simulation.replay.replay_substeps`)."""

from __future__ import annotations

import pytest

from ilic_cli.simulation.replay import REPLAY_STEP_S, replay, replay_substeps
from tests.conftest import make_synthetic_log


@pytest.mark.parametrize(("fs_hz", "substeps"), [(250.0, 10), (500.0, 10), (1000.0, 10), (1024.0, 10), (2000.0, 5), (4000.0, 3), (8000.0, 2), (20000.0, 2)])
def test_a_tenth_of_the_period_but_no_finer_than_the_step(fs_hz: float, substeps: int) -> None:
    """Ten substeps up to 1 kHz (the EMPS's step there, unchanged); above, steps of at most 0.1 ms, and at least two."""
    assert replay_substeps(fs_hz) == substeps
    assert 1.0 / (fs_hz * substeps) <= max(REPLAY_STEP_S, 0.1 / fs_hz) * (1 + 1e-9)


@pytest.mark.parametrize(("fs_hz", "substeps"), [(1000.0, 10), (8000.0, 2)])
def test_the_diagnosis_s_replay_integrates_at_that_step(fs_hz: float, substeps: int) -> None:
    sim = replay(make_synthetic_log(samples=200, rate_hz=fs_hz), {"M": 95.0, "Fv": 200.0, "Fc": 20.0}, None)
    assert sim.meta["simulation"]["substeps"] == substeps and sim.meta["simulation"]["dt"] == pytest.approx(1.0 / (fs_hz * substeps))
