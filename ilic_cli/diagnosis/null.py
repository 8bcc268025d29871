"""A Monte-Carlo null for the replay's decision: simulate the kept model with the log's own noise, and see how often it does as well.

The replay (:func:`ilic_cli.diagnosis.decide.replay_decide`) keeps a proposed
effect when its held-out simulated force error falls significantly. By default
significance is a one-sided Diebold-Mariano test, whose level is asymptotic and
assumes what closed-loop errors are not (measured on the 104 forced spurious
candidates that reach the replay on 128 clean plant logs: p <= 0.01 on none,
<= 0.05 on 3, with the replays carrying the recording's sensor noise; on 9 at
0.01 with noise-free replays). Here (``ilic diagnose
--null montecarlo``) the statistic is also compared with its own distribution
under the null hypothesis that the model kept so far is the truth:

1. The log's residual noise model (:func:`estimate_noise`): white position
   noise and the encoder's quantisation step, estimated from the recording's
   position, and a band-limited force disturbance on the axis sized so that
   the kept model's replay leaves the recording's force residual (in the band
   the replay compares: the error decimated as the IDIM system is).
2. For ``b = 1..B``: the kept model's closed loop, driven by the log's
   reference and controller, with that noise (seed :func:`replicate_seed`)
   gives a synthetic log with the recording's metadata (:func:`synthetic_log`);
   it is prepared as the recording is, the same candidate effect is proposed
   on it again (its nonlinear parameter searched as
   :mod:`ilic_cli.diagnosis.select` does) and the same held-out replay
   statistic is computed (the Diebold-Mariano ``z`` of
   :func:`~ilic_cli.diagnosis.decide.replay_decide`: larger is a larger fall).
3. ``p = (1 + #{T_b >= T_obs}) / (B + 1)`` (:func:`mc_p_value`): exact at any
   ``B`` under exchangeability; a decision at level ``alpha`` needs
   ``B >= 1/alpha - 1`` (:func:`min_replicates`), else it could never reject.

The replay runs the null only for a candidate the Diebold-Mariano test finds
significant, and keeps it only when this p is at most ``alpha`` too. Measured
(``benchmarks/null_calibration.py``, 104 spurious candidates that pass the gates
before the replay, on 128 clean plant logs, ``B = 19``, every replay with the
sensor noise of :mod:`ilic_cli.diagnosis.sensor`): the Monte-Carlo p alone is
<= 0.05 on 6, both on 1 (noise-free replays: 23 and 5).

The noise uses the plant's own effects (``noise``, ``quantization``,
``disturbance``: :mod:`plant.sensors`), as the corpus builds its noisy logs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.diagnosis.compare import band_force_error
from ilic_cli.diagnosis.heldout_replay import replay_decide
from ilic_cli.diagnosis.select import Searcher, Step, fit_system, moving_rows, system
from ilic_cli.diagnosis.sensor import loop_corrected, position_noise, sensor_effects
from ilic_cli.diagnosis.stats import normal_isf
from ilic_cli.diagnosis.verdicts import PlantOf
from ilic_cli.errors import IlicError, ParameterError
from ilic_cli.filtering import kept_indices
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.parallel import ordered_map
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import replay

NULL_KINDS = ("dm", "montecarlo")
"""``dm``: the asymptotic Diebold-Mariano test (default); ``montecarlo``: this module's null."""

REPLAY_ALPHA = 0.05
"""Level of the replay's test, the decision (``--replay-alpha``): the usual 0.05, as the held-out test that proposes
(:attr:`~ilic_cli.diagnosis.select.SelectSettings.alpha_heldout`), reached only past the F-test at 0.001 (Bonferroni).
Forced past the inverse model on 128 clean plant logs (``benchmarks/null_calibration.py``), the p was at most 0.05 on 3
of the 152 trials the replay alone must reject (2.0 %). At 0.01 (before issue 29) true effects lowering the held-out error
by 3-15 % at p = 0.012-0.023 were rejected (robot corpus: 500 Hz lags, Stribeck friction beside a flexibility); at 0.05
they are kept, and none of its 480 clean logs (eight seed sets) has a finding, as at 0.01."""

BANDWIDTH_RANGE = (0.5, 0.4)
"""The disturbance's corner frequency is kept within [0.5 Hz, 0.4 times the decimated rate]."""


def min_replicates(alpha: float) -> int:
    """Fewest replicates with which a Monte-Carlo test can reject at level ``alpha``: ``ceil(1/alpha - 1)``.

    Parameters
    ----------
    alpha : float
        Level of the test, in (0, 1).
    """
    return max(int(math.ceil(1.0 / alpha - 1.0 - 1e-9)), 1)


def mc_p_value(t_obs: float, t_null: np.ndarray) -> float:
    """Monte-Carlo p-value ``(1 + #{T_b >= T_obs}) / (B + 1)``; a replicate without a statistic (NaN) counts as ``>=``.

    Parameters
    ----------
    t_obs : float
        The statistic on the recording (larger: more evidence against the null).
    t_null : ndarray
        The ``B`` statistics of the replicates.
    """
    t = np.asarray(t_null, dtype=np.float64)
    at_least = int(np.sum(~(t < t_obs)))  # NaN: not less, so counted
    return (1.0 + at_least) / (len(t) + 1.0)


def replicate_seed(seed: int, b: int) -> int:
    """Noise seed of replicate ``b`` (``b = 0``: the sizing of the disturbance), from the run's ``seed`` (NumPy ``SeedSequence``).

    Parameters
    ----------
    seed : int
        ``ilic diagnose --seed``.
    b : int
        Replicate number.
    """
    return int(np.random.SeedSequence([int(seed), int(b)]).generate_state(1)[0])


@dataclass(frozen=True)
class NullSettings:
    """Which test decides the replay, and how.

    Attributes
    ----------
    kind : str
        One of :data:`NULL_KINDS`.
    replicates : int
        ``B`` of the Monte-Carlo null.
    seed : int
        Seed of the replicates (:func:`replicate_seed`).
    alpha : float or None
        Level of the replay's test; ``None``: :data:`REPLAY_ALPHA`.
    """

    kind: str = "dm"
    replicates: int = 99
    seed: int = 0
    alpha: float | None = None

    def check(self, alpha: float) -> None:
        """Refuse an unknown kind, or a ``B`` too small for level ``alpha`` (:class:`ParameterError`).

        Parameters
        ----------
        alpha : float
            The level the replay's test decides at.
        """
        if self.kind not in NULL_KINDS:
            raise ParameterError("null", self.kind, f"one of {', '.join(NULL_KINDS)}")
        if self.kind == "montecarlo" and self.replicates < min_replicates(alpha):
            raise ParameterError(
                "replicates",
                self.replicates,
                f"at least {min_replicates(alpha)} for a Monte-Carlo test at level {alpha:g} (p cannot go below 1/(B+1))",
            )

    @property
    def level(self) -> float:
        """The level the replay's test runs at: :attr:`alpha`, else :data:`REPLAY_ALPHA`."""
        return self.alpha if self.alpha is not None else REPLAY_ALPHA

    def to_dict(self) -> dict[str, Any]:
        return {"null": self.kind, "replicates": self.replicates if self.kind == "montecarlo" else None, "seed": self.seed, "alpha": self.level}


# ---------------------------------------------------------------------------
# the log's own noise model
# ---------------------------------------------------------------------------
def disturbance_bandwidth(r: np.ndarray, fs_dec_hz: float) -> float:
    """Corner frequency (Hz) of a second-order Butterworth noise with the lag-one autocorrelation of ``r``.

    The autocorrelation of white noise through a second-order Butterworth
    low-pass of corner ``fc`` is ``exp(-a t) (cos a t + sin a t)``,
    ``a = sqrt(2) pi fc``; solved at one decimated period for the lag-one
    autocorrelation of ``r``, within :data:`BANDWIDTH_RANGE`.

    Parameters
    ----------
    r : ndarray
        Decimated force residual (contiguous rows).
    fs_dec_hz : float
        Its rate.
    """
    from scipy.optimize import brentq  # deferred: scipy.optimize is slow to import

    r = np.asarray(r, dtype=np.float64) - float(np.mean(r))
    lo, hi = BANDWIDTH_RANGE[0], BANDWIDTH_RANGE[1] * fs_dec_hz
    den = float(r @ r)
    rho = float(r[1:] @ r[:-1]) / den if den > 0 else 0.0
    T = 1.0 / fs_dec_hz

    def acf(fc: float) -> float:
        a = math.sqrt(2.0) * math.pi * fc * T
        return math.exp(-a) * (math.cos(a) + math.sin(a))

    if rho >= acf(lo):
        return lo
    if rho <= acf(hi):
        return hi
    return float(brentq(lambda fc: acf(fc) - rho, lo, hi, xtol=1e-6))


@dataclass(frozen=True)
class NoiseModel:
    """The log's residual noise, as the plant's effects (:meth:`effects`).

    Attributes
    ----------
    q_std : float
        White position noise (m).
    resolution : float or None
        Encoder quantisation step (m), ``None`` off a grid.
    disturbance_std, bandwidth_hz : float
        Band-limited force disturbance on the axis (N, Hz).
    residual_rms : float
        RMS of the recording's force residual it is sized to (N, decimated, the rows the replay compares).
    """

    q_std: float
    resolution: float | None
    disturbance_std: float
    bandwidth_hz: float
    residual_rms: float

    def effects(self) -> dict[str, dict[str, float]]:
        """The plant effects ``noise``, ``quantization`` and ``disturbance`` of this noise (those that are not zero)."""
        out = sensor_effects(self.q_std, self.resolution)
        if self.disturbance_std > 0:
            out["disturbance"] = {"std": self.disturbance_std, "bandwidth_hz": self.bandwidth_hz}
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "position_noise_std_m": self.q_std,
            "quantization_step_m": self.resolution,
            "disturbance_std_n": self.disturbance_std,
            "disturbance_bandwidth_hz": self.bandwidth_hz,
            "residual_rms_n": self.residual_rms,
        }


def compared_rows(log: RunLog, data: IDIMData, rows: np.ndarray) -> np.ndarray:
    """Decimated samples of ``log`` the replay compares (those of its held-out blocks: from the first row used to the last)."""
    t = np.asarray(log.t)
    t_rows = data.t_dec[rows]
    a, b = int(np.searchsorted(t, t_rows[0])), int(np.searchsorted(t, t_rows[-1], side="right"))
    at = kept_indices(len(log), max(data.settings.decimation, 1))
    return np.flatnonzero((at >= a) & (at < b))


def disturbance_std(r_obs: np.ndarray, r_noise: np.ndarray, d_unit: np.ndarray) -> float:
    """Std of the disturbance that brings the replay residual's mean square from ``r_noise``'s to ``r_obs``'s.

    ``d_unit`` is the residual a disturbance of unit std adds (same noise
    seed); the two parts are taken as uncorrelated:
    ``S^2 = (ms(r_obs) - ms(r_noise)) / ms(d_unit)``, 0 when the position
    noise alone leaves as much.

    Parameters
    ----------
    r_obs, r_noise, d_unit : ndarray
        Decimated force residuals (N) on the same rows.
    """
    ms = lambda x: float(np.mean(np.square(x)))  # noqa: E731
    excess = ms(r_obs) - ms(r_noise)
    return math.sqrt(excess / ms(d_unit)) if excess > 0 and ms(d_unit) > 0 else 0.0


def estimate_noise(
    log: RunLog, data: IDIMData, rows: np.ndarray, rigid: dict[str, float], effects: dict[str, Any], ls: LSSettings, seed: int = 0
) -> NoiseModel:
    """The residual noise model of ``log`` under the model ``(rigid, effects)``.

    Position noise and quantisation from the recording (:func:`position_noise`),
    corrected for the loop on a replay of the model (:func:`loop_corrected`). The
    disturbance's bandwidth from the recorded replay residual
    (:func:`disturbance_bandwidth`) and its std from replays of the model
    (:func:`disturbance_std`): noise-free, with the position noise, and with it
    and a disturbance of unit std (seed :func:`replicate_seed` ``(seed, 0)``).
    The residual is the replayed force minus the logged one, decimated as the
    IDIM system is, on the rows the replay compares (:func:`compared_rows`).

    Parameters
    ----------
    log : RunLog
        The recording.
    data : IDIMData
        Its IDIM system.
    rows : ndarray of bool
        Decimated rows used.
    rigid, effects : dict
        The model (plant parameters and effects), noise-free.
    ls : LSSettings
        The IDIM position filter and decimation.
    seed : int
        The run's seed.
    """
    q_std, res = position_noise(np.asarray(log["q"]), log.fs_hz, ls)
    idx = compared_rows(log, data, rows)
    r = max(data.settings.decimation, 1)
    clean = replay(log, rigid, effects)
    r_obs = band_force_error(log, clean, r)[idx]
    rms = float(np.sqrt(np.mean(r_obs**2)))
    fs_dec = log.fs_hz / r
    bw = disturbance_bandwidth(r_obs, fs_dec)
    s0 = replicate_seed(seed, 0)
    q_std = loop_corrected(q_std, res, log.fs_hz, ls, lambda sensor: replay(log, rigid, {**effects, **sensor}, seed=s0))
    noisy = replay(log, rigid, {**effects, **NoiseModel(q_std, res, 0.0, bw, rms).effects()}, seed=s0)
    unit = replay(log, rigid, {**effects, **NoiseModel(q_std, res, 1.0, bw, rms).effects()}, seed=s0)
    std = disturbance_std(r_obs, band_force_error(noisy, clean, r)[idx], band_force_error(noisy, unit, r)[idx])
    return NoiseModel(q_std, res, std, bw, rms)


# ---------------------------------------------------------------------------
# replicates
# ---------------------------------------------------------------------------
SIMULATED_CHANNELS = ("q", "tau", "vir", "qd_plant", "qdd_plant")
"""Channels of the recording a replicate replaces by the simulated ones (when the simulation has them); the rest is kept."""


def synthetic_log(log: RunLog, rigid: dict[str, float], effects: dict[str, Any], noise: NoiseModel, seed: int) -> RunLog:
    """One replicate: the model's closed loop on ``log``'s reference and controller, with ``noise``, as a log like ``log``.

    The recording's channels and metadata, its measured ones
    (:data:`SIMULATED_CHANNELS`) replaced by the simulation's; same seed,
    bit-identical log.

    Parameters
    ----------
    log : RunLog
        The recording.
    rigid, effects : dict
        The model simulated (noise-free).
    noise : NoiseModel
        The noise added (:meth:`NoiseModel.effects`).
    seed : int
        Noise seed of the replicate (:func:`replicate_seed`).
    """
    sim = replay(log, rigid, {**effects, **noise.effects()}, seed=seed)
    chans = {k: (sim[k] if k in SIMULATED_CHANNELS and k in sim else v) for k, v in log.channels.items()}
    chans = {k: v for k, v in chans.items() if k not in SIMULATED_CHANNELS or k in sim}
    meta = {**log.meta, "montecarlo_replicate": {"seed": int(seed), "noise": noise.to_dict()}}
    return RunLog(chans, dict(log.units), meta)


def reproposed(data: IDIMData, base: Model, kept: list[Step], step: Step, rows: np.ndarray) -> Step:
    """``step``'s effect proposed again on ``data``: its nonlinear parameter searched as the selection does (grid, then refined).

    Parameters
    ----------
    data : IDIMData
        A replicate's IDIM system.
    base : Model
        Rigid structure.
    kept : list of Step
        The model so far (fixed).
    step : Step
        The candidate on the recording.
    rows : ndarray of bool
        Decimated rows used on ``data``.
    """
    eff = step.effect
    if not eff.nonlinear:
        return Step(eff, step.value)
    W, y, _ = system(data, base, kept, rows)
    searcher = Searcher(data, data.fs_hz, rows)
    at = searcher.log_rate(base, kept, factor=searcher.rate_factor(eff)) if searcher.at_log_rate(eff) else None
    value = searcher.scan(eff, W, y, at=at)
    value, _ = searcher.refine(eff, W, y, value, at=at)
    return Step(eff, value)


def dm_z(p: float | None) -> float:
    """The Diebold-Mariano statistic ``z`` of its one-sided p-value (larger: a larger fall); NaN without one.

    Parameters
    ----------
    p : float or None
        One-sided p-value (:func:`ilic_cli.diagnosis.stats.heldout_fall_p`).
    """
    return math.nan if p is None else float(normal_isf(p))


@dataclass
class NullDistribution:
    """The Monte-Carlo null of one candidate: the statistic on the recording and on each replicate.

    Attributes
    ----------
    effect : str
        The candidate.
    t_obs : float
        Diebold-Mariano ``z`` of the held-out replay errors on the recording.
    t_null : ndarray
        The same on each replicate (NaN: the replicate's model was no valid plant).
    p_value : float
        :func:`mc_p_value`.
    noise : NoiseModel
        The noise of the replicates.
    dm_p_value : float
        The asymptotic Diebold-Mariano p of the recording (the replay keeps a candidate only when both are significant).
    values : list
        The candidate's nonlinear value found on each replicate that gave a statistic.
    """

    effect: str
    t_obs: float
    t_null: np.ndarray
    p_value: float
    noise: NoiseModel
    dm_p_value: float
    values: list[Any] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        t = self.t_null[np.isfinite(self.t_null)]
        qs = (0.05, 0.25, 0.5, 0.75, 0.95)
        return {
            "replicates": len(self.t_null),
            "replicates_without_statistic": int(len(self.t_null) - len(t)),
            "statistic": "Diebold-Mariano z of the held-out replayed force errors (larger: a larger fall)",
            "t_obs": self.t_obs,
            "t_null_quantiles": {f"q{int(100 * q):02d}": float(np.quantile(t, q)) for q in qs} if len(t) else None,
            "t_null_max": float(t.max()) if len(t) else None,
            "p_value": self.p_value,
            "dm_p_value": self.dm_p_value,
            "noise_model": self.noise.to_dict(),
        }


@dataclass(frozen=True)
class MonteCarloNull:
    """The hook :func:`~ilic_cli.diagnosis.decide.replay_decide` calls to judge a candidate (``--null montecarlo``).

    Attributes
    ----------
    replicates : int
        ``B``.
    seed : int
        The run's seed.
    ls : LSSettings
        IDIM filtering of the diagnosis.
    prepare : callable
        ``RunLog -> IDIMData``: the recording's preparation, applied to each replicate.
    sensor_noise : bool
        Each replicate's replays carry its own estimated sensor noise, as the recording's do (``replay_decide``'s ``sensor_noise``).
    """

    replicates: int
    seed: int
    ls: LSSettings
    prepare: Callable[[RunLog], IDIMData]
    sensor_noise: bool = True

    def distribution(
        self, log: RunLog, data: IDIMData, base: Model, kept: list[Step], step: Step, rows: np.ndarray, plant_of: PlantOf, folds: int, p_obs: float
    ) -> NullDistribution:
        """The null distribution of the replay statistic for ``step`` added to ``kept`` on ``log``, and its p-value.

        Parameters
        ----------
        log : RunLog
            The recording.
        data : IDIMData
            Its IDIM system.
        base : Model
            Rigid structure.
        kept : list of Step
            The model so far: the truth under the null.
        step : Step
            The candidate.
        rows : ndarray of bool
            Decimated rows used on the recording.
        plant_of : callable
            Plant parameters of a fit (as given to :func:`~ilic_cli.diagnosis.decide.replay_decide`).
        folds : int
            Held-out blocks.
        p_obs : float
            The recording's Diebold-Mariano p (its statistic is :func:`dm_z` of it).
        """
        fit = fit_system(data, base, kept, rows)
        rigid, effects = plant_of(kept, fit.names, fit.theta)
        noise = estimate_noise(log, data, rows, rigid, effects, self.ls, self.seed)

        def replicate(b: int) -> tuple[Any, float] | None:
            """Replicate ``b``'s re-proposed value and statistic; ``None`` when it diverged or left too little to fit."""
            try:
                synth = synthetic_log(log, rigid, effects, noise, replicate_seed(self.seed, b))
                data_b = self.prepare(synth)
                rows_b = moving_rows(data_b)
                cand = reproposed(data_b, base, kept, step, rows_b)
                _, verdicts = replay_decide(synth, data_b, base, kept, [cand], rows_b, plant_of, folds=folds, alpha=0.0, sensor_noise=self.sensor_noise)
            except IlicError:
                return None
            return cand.value, dm_z(verdicts[0].p_value)

        done = ordered_map(replicate, range(1, self.replicates + 1))  # each replicate its own seed: side by side
        t_null = np.array([np.nan if r is None else r[1] for r in done])  # no statistic: counted as at least as extreme
        values = [r[0] for r in done if r is not None]
        t_obs = dm_z(p_obs)
        return NullDistribution(step.effect.id, t_obs, t_null, mc_p_value(t_obs, t_null), noise, p_obs, values)
