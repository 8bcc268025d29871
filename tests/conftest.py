"""Shared fixtures: the real EMPS recordings beside the repository and a small synthetic log."""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from ilic_cli.runlog import RunLog
from tests.shared_cache import use_folder

SHARED_EMPS = Path(__file__).parents[1].parent / "shared" / "emps"
"""``../shared/emps`` relative to the repository root (read-only data, never copied)."""

EMPS_FILES = ("DATA_EMPS.mat", "DATA_EMPS_PULSES.mat")


def skip_outside_ci(why: str) -> None:
    """Skip the calling test (or module) with ``why``; under ``CI`` fail instead.

    The one rule for skipping in this suite: nothing skips in CI (``CI`` set
    to a non-empty value), where a missing recording or a failed import is a
    failure. Every skip goes through this helper.

    Parameters
    ----------
    why : str
        What is missing.
    """
    if os.environ.get("CI"):
        pytest.fail(f"{why} (CI: nothing may skip)", pytrace=False)
    pytest.skip(why, allow_module_level=True)


def import_or_skip(name: str) -> ModuleType:
    """Import module ``name``; when that fails, skip outside CI and fail under CI (:func:`skip_outside_ci`).

    Parameters
    ----------
    name : str
        Dotted module name.

    Returns
    -------
    ModuleType
        The imported module.
    """
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        skip_outside_ci(f"cannot import {name}: {exc}")
        raise  # unreachable: skip_outside_ci always raises


def require_shared() -> Path:
    """Return the EMPS folder; skip when it is absent outside CI, fail when it is absent in CI.

    Returns
    -------
    Path
        ``../shared/emps`` with both recordings.
    """
    missing = [name for name in EMPS_FILES if not (SHARED_EMPS / name).is_file()]
    if not missing:
        return SHARED_EMPS
    skip_outside_ci(f"EMPS recordings missing from {SHARED_EMPS}: {', '.join(missing)}; CI must provide ../shared beside the clone")
    raise AssertionError("unreachable")


@pytest.fixture(scope="session", autouse=True)
def _shared_artefacts(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Under pytest-xdist, the artefacts of :mod:`tests.shared_cache` go beside the workers' tmp dirs (one folder for the run)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        use_folder(tmp_path_factory.getbasetemp().parent / "shared-artefacts")


@pytest.fixture(scope="session")
def emps_dir() -> Path:
    """The folder with the real EMPS recordings (see :func:`require_shared`)."""
    return require_shared()


@pytest.fixture(scope="session")
def emps_mat(emps_dir: Path) -> Path:
    """``DATA_EMPS.mat`` (estimation run)."""
    return emps_dir / "DATA_EMPS.mat"


@pytest.fixture(scope="session")
def emps_pulses_mat(emps_dir: Path) -> Path:
    """``DATA_EMPS_PULSES.mat`` (validation run with force pulses)."""
    return emps_dir / "DATA_EMPS_PULSES.mat"


def make_synthetic_log(samples: int = 400, rate_hz: float = 1000.0, seed: int = 3) -> RunLog:
    """Return a small synthetic EMPS-like log with every standard channel.

    Parameters
    ----------
    samples : int
        Number of samples.
    rate_hz : float
        Sample rate (Hz).
    seed : int
        Seed of the measurement noise.

    Returns
    -------
    RunLog
        Channels ``t, q, qd, q_ref, qd_ref, qdd_ref, tau, vir, pulses`` and
        metadata with drive gain, PD controller, scenario and true parameters.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(samples) / rate_hz
    w = 2 * np.pi * 0.7
    q_ref = 0.1 * np.sin(w * t)
    qd_ref = 0.1 * w * np.cos(w * t)
    qdd_ref = -0.1 * w * w * np.sin(w * t)
    q = q_ref + rng.normal(0.0, 1e-6, samples)
    qd = qd_ref + rng.normal(0.0, 1e-4, samples)
    gain = 35.15065188248547
    vir = (95.0 * qdd_ref + 200.0 * qd_ref + 20.0 * np.tanh(100 * qd_ref)) / gain + rng.normal(0.0, 1e-3, samples)
    pulses = np.where((np.arange(samples) // 50) % 4 == 1, 5.0, 0.0)
    return RunLog(
        {"t": t, "q": q, "qd": qd, "q_ref": q_ref, "qd_ref": qd_ref, "qdd_ref": qdd_ref, "tau": gain * vir, "vir": vir, "pulses": pulses},
        meta={
            "sample_rate_hz": rate_hz,
            "drive_gain": gain,
            "controller": {"kind": "pd", "kp": 160.18, "kv": 243.45},
            "scenario": {"name": "unit-test", "seed": seed},
            "true_parameters": {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0},
        },
    )


@pytest.fixture()
def synthetic_log() -> RunLog:
    """A fresh small synthetic log (see :func:`make_synthetic_log`)."""
    return make_synthetic_log()
