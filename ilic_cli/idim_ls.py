"""IDIM-LS: offline inverse dynamic identification by least squares (paper section III).

The benchmark procedure (``emps-benchmark.md``): zero-phase Butterworth
low-pass of the measured position, central-difference velocity and
acceleration, edge trimming, observation matrix from the model's columns,
parallel decimation of the force and of every column, least squares with
standard deviations (eq. 9) and relative standard deviations (eq. 10).
With the defaults it reproduces the published EMPS tables to every digit.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ilic_cli.filtering import butter_lowpass_zero_phase, central_difference, decimate_matlab, kept_indices, lowpass_decimate
from ilic_cli.lsq import LSResult, SigmaConvention, evaluate, solve
from ilic_cli.regressor import Kinematics, Model


@dataclass(frozen=True)
class LSSettings:
    """Filtering and decimation of IDIM-LS (defaults: the published benchmark).

    Attributes
    ----------
    cutoff_hz : float
        Position low-pass cut-off (benchmark: 100 Hz, 5x the loop bandwidth).
    order : int
        Butterworth order of the position filter.
    decimation : int
        Parallel decimation factor (benchmark: round(0.8*500/40) = 10).
    trim : int
        Samples dropped at the start (edge effects of the filters).
    matlab : bool
        MATLAB-compatible filtering (transfer-function filtfilt padding and
        Chebyshev decimation, end-aligned); otherwise SciPy second-order
        sections and a Butterworth anti-alias filter.
    sigma : {"sample_std", "eq8"}
        Error standard deviation: the benchmark's sample std (default) or
        the paper's eq. (8).
    """

    cutoff_hz: float = 100.0
    order: int = 4
    decimation: int = 10
    trim: int = 49
    matlab: bool = True
    sigma: SigmaConvention = "sample_std"

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class IDIMData:
    """Filtered, trimmed signals at the full rate and the decimated system.

    Diagnosis adds columns with :meth:`decimate` and solves again.
    """

    kin: Kinematics
    tau: np.ndarray
    W: np.ndarray
    y: np.ndarray
    fs_hz: float
    settings: LSSettings

    @property
    def t_dec(self) -> np.ndarray:
        """Time of the decimated rows (s)."""
        assert self.kin.t is not None
        return self.kin.t[kept_indices(len(self.kin.t), self.settings.decimation)]

    def decimate(self, x: np.ndarray) -> np.ndarray:
        """Decimate full-rate trimmed column(s) exactly as the force was."""
        return _decimate(np.asarray(x, dtype=np.float64), self.settings, self.fs_hz)


@dataclass(frozen=True)
class IDIMLSResult:
    """IDIM-LS estimate of one log."""

    model: str
    result: LSResult
    settings: LSSettings
    t: np.ndarray | None = None
    y: np.ndarray | None = None
    y_hat: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"method": "IDIM-LS", "model": self.model, **self.result.to_dict(), "settings": self.settings.to_dict()}

    def to_frame(self) -> Any:
        import pandas as pd

        r = self.result
        return pd.DataFrame({"parameter": r.names, "value": r.theta, "std": r.std, "rel_std_pct": r.rel_std_pct})


def _decimate(x: np.ndarray, settings: LSSettings, fs_hz: float) -> np.ndarray:
    if settings.matlab:
        return decimate_matlab(x, settings.decimation, axis=0)
    return lowpass_decimate(x, settings.decimation, 0.8 * fs_hz / 2 / settings.decimation, fs_hz, 8, axis=0)


def prepare(t: np.ndarray, q: np.ndarray, tau: np.ndarray, fs_hz: float, model: Model, settings: LSSettings = LSSettings(), *, extra: dict[str, np.ndarray] | None = None) -> IDIMData:
    """Filter, differentiate, trim, build and decimate the IDIM system (eqs. 5-6).

    Parameters
    ----------
    t, q, tau : ndarray
        Time (s), measured position and force, sampled at ``fs_hz``.
    fs_hz : float
        Sampling frequency.
    model : Model
        Regressor columns.
    settings : LSSettings
        Filtering and decimation.
    extra : dict, optional
        Further full-rate channels made available to columns (trimmed alike).
    """
    dt = 1.0 / fs_hz
    if len(q) <= settings.trim + 3 * settings.decimation * 9:
        raise ValueError(f"too few samples ({len(q)}) for IDIM-LS with trim {settings.trim} and decimation {settings.decimation}")
    qf = butter_lowpass_zero_phase(np.asarray(q, dtype=np.float64), settings.cutoff_hz, fs_hz, settings.order, matlab=settings.matlab)
    qd = central_difference(qf, dt)
    qdd = central_difference(qd, dt)
    s = slice(settings.trim, None)
    kin = Kinematics(
        qd=qd[s],
        qdd=qdd[s],
        q=qf[s],
        t=np.asarray(t, dtype=np.float64)[s],
        extra={k: np.asarray(v, dtype=np.float64)[s] for k, v in (extra or {}).items()},
    )
    y_full = np.asarray(tau, dtype=np.float64)[s]
    # parallel decimation of the force and every column, in one call (columns filtered in threads)
    Wy = _decimate(np.column_stack([model.matrix(kin), y_full]), settings, fs_hz)
    W, y = np.ascontiguousarray(Wy[:, :-1]), np.ascontiguousarray(Wy[:, -1])
    return IDIMData(kin=kin, tau=y_full, W=W, y=y, fs_hz=fs_hz, settings=settings)


def idim_ls(t: np.ndarray, q: np.ndarray, tau: np.ndarray, fs_hz: float, model: Model, settings: LSSettings = LSSettings()) -> IDIMLSResult:
    """IDIM-LS estimate of ``model`` from measured position and force."""
    data = prepare(t, q, tau, fs_hz, model, settings)
    result = solve(data.W, data.y, model.names, sigma=settings.sigma)
    return IDIMLSResult(model=model.name, result=result, settings=settings, t=data.t_dec, y=data.y, y_hat=data.W @ result.theta)


def cross_validate(theta: np.ndarray, t: np.ndarray, q: np.ndarray, tau: np.ndarray, fs_hz: float, model: Model, settings: LSSettings = LSSettings()) -> LSResult:
    """Apply estimates ``theta`` to another log with the same processing (cross-test validation)."""
    data = prepare(t, q, tau, fs_hz, model, settings)
    return evaluate(data.W, data.y, np.asarray(theta, dtype=np.float64), model.names)
