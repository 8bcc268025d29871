"""The replay against the recording in words (``report.simulation_sentence``) and its force error in the inverse model's band."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.diagnosis.compare import SimulationComparison, band_force_error_pct
from ilic_cli.diagnosis.report import NOISE_BAND_RATIO, simulation_sentence
from ilic_cli.idim_ls import LSSettings
from ilic_cli.runlog import RunLog


def _log(tau: np.ndarray, fs: float) -> RunLog:
    t = np.arange(len(tau)) / fs
    return RunLog({"t": t, "q": np.zeros_like(t), "tau": tau}, {"t": "s", "q": "m", "tau": "N"}, {})


def test_the_band_leaves_out_the_force_above_it() -> None:
    """A recording whose force is a replay's plus white noise: most of the full-band error, little of the band's; a slow
    error is the same in both (the band keeps 40 Hz of the 4 kHz log)."""
    fs = 4000.0
    t = np.arange(40_000) / fs
    smooth = 10.0 * np.sin(2 * np.pi * 0.5 * t)
    noise = np.random.default_rng(0).normal(0.0, 5.0, len(t))
    ls = LSSettings()
    rec = _log(smooth + noise, fs)
    full = 100 * np.linalg.norm(noise) / np.linalg.norm(smooth + noise)
    band = band_force_error_pct(rec, _log(smooth, fs), ls)
    assert full > 40 and band < 0.25 * full  # white noise: about sqrt(40 / 2000) of it in the band
    slow = _log(smooth, fs)
    assert band_force_error_pct(slow, _log(1.02 * smooth, fs), ls) == pytest.approx(2.0, rel=0.01)
    assert band_force_error_pct(slow, _log(1.02 * smooth[:30_000], fs), ls) == pytest.approx(2.0, rel=0.01)  # another length: the common part


def test_the_sentence_says_whose_the_full_band_error_is() -> None:
    noisy = SimulationComparison({"force": 59.72, "force_in_band": 4.31, "position": 0.00846, "velocity": 0.14}, None, "replay through the plant")
    text = simulation_sentence(noisy)
    assert text.startswith("Simulation against recording (replay through the plant): force error 59.72 % (in the inverse model's band 4.31 %), ")
    assert "mostly the loop's answer to the sensor noise" in text
    quiet = SimulationComparison(
        {"force": 4.55, "force_in_band": 4.50, "position": 0.00108, "velocity": 0.12}, {"force": 3.42, "force_in_band": 3.38}, "replay through the plant"
    )
    text = simulation_sentence(quiet)
    assert "force error 4.55 % -> 3.42 % (in the inverse model's band 4.50 % -> 3.38 %), position 0.00108 %" in text and "sensor noise" not in text
    at = NOISE_BAND_RATIO * 4.31
    assert "sensor noise" not in simulation_sentence(SimulationComparison({**noisy.before, "force": at}, None, "x"))
    assert "sensor noise" in simulation_sentence(SimulationComparison({**noisy.before, "force": at * 1.001}, None, "x"))
