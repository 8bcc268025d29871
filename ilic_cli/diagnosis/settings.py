"""The settings of a diagnosis (:class:`DiagnosisSettings`), passed down the stages: propose, decide, refit, report.

One frozen object: what the command line chooses (the structure, the selection's statistics, the replay's test,
...) and the tuning of the stages, whose defaults are the values measured on the corpus; each field says what it
is and why that value (the measurement is given where the value is defined, in the module that uses it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ilic_cli.diagnosis.drift import ALPHA as DRIFT_ALPHA
from ilic_cli.diagnosis.drift import MIN_CHANGE as DRIFT_MIN_CHANGE
from ilic_cli.diagnosis.drift import WINDOWS as DRIFT_WINDOWS
from ilic_cli.diagnosis.drift import DriftResult, detect_drift
from ilic_cli.diagnosis.dwell import DWELL_MIN_COUNT, DWELL_MIN_S
from ilic_cli.diagnosis.materiality import MATERIAL_FORCE, MIN_DELAY_PERIODS
from ilic_cli.diagnosis.null import NullSettings
from ilic_cli.diagnosis.refit_search import MAX_ROUNDS, ROUND_GAIN
from ilic_cli.diagnosis.search import FOLD_XATOL_STEPS
from ilic_cli.diagnosis.segments import LEVEL_Z, SEGMENT_S
from ilic_cli.diagnosis.select import SelectSettings
from ilic_cli.idim_ls import LSSettings


@dataclass(frozen=True)
class DiagnosisSettings:
    """Settings of a diagnosis: ``diagnose(log, settings=DiagnosisSettings())``.

    Attributes
    ----------
    model : str
        Rigid model structure identified first (``rigid-offset``).
    ls : LSSettings
        IDIM-LS filtering and decimation (benchmark defaults).
    select : SelectSettings
        Statistics of the forward selection.
    simulate : bool
        Replay the recorded reference through the plant (before/after).
    null : NullSettings
        The test that decides the replay (default: Diebold-Mariano; or a Monte-Carlo null).
    pd_timing : {"recorded", "documented"}
        When a PD log's command acts in every replay (:data:`ilic_cli.parameters.PD_TIMINGS`).
    replay_noise : bool
        The replays that decide carry the recording's position noise (:mod:`ilic_cli.diagnosis.sensor`); ``False``: noise-free.

    The tuning of the stages follows, each field with its reason.
    """

    model: str = "rigid-offset"
    ls: LSSettings = LSSettings()
    select: SelectSettings = field(default_factory=SelectSettings)
    simulate: bool = True
    null: NullSettings = NullSettings()
    pd_timing: str = "recorded"
    replay_noise: bool = True
    material_force: float = MATERIAL_FORCE
    """Decide: an effect whose force (RMS over the rows used) is below this share of the RMS force is not material. Why 0.3 %: the
    rigid fit of noise-free plant logs without any effect leaves 0.18-0.25 % of the force (:data:`ilic_cli.diagnosis.materiality.MATERIAL_FORCE`)."""
    min_delay_periods: float = MIN_DELAY_PERIODS
    """Decide: a drive lag shorter than this share of the sample period is not a finding. Why a tenth: below it the rows cannot tell a
    lag from the sample timing, and the physical lags are well above it (:data:`ilic_cli.diagnosis.materiality.MIN_DELAY_PERIODS`)."""
    fold_xatol_steps: float = FOLD_XATOL_STEPS
    """Decide: tolerance of the per-fold closed-loop search of a value the inverse model biases, in steps of its grid (a drive lag:
    0.05 ms on its 0.5 ms grid, :data:`ilic_cli.diagnosis.search.FOLD_XATOL_STEPS`)."""
    dwell_min_s: float = DWELL_MIN_S
    """Propose, refit: a rest of the reference at least this long (s) is a dwell (:data:`ilic_cli.diagnosis.dwell.DWELL_MIN_S`)."""
    dwell_min_count: int = DWELL_MIN_COUNT
    """Propose, refit: a reference with at least this many dwells is searched for Stribeck friction at them, and its finding refitted
    on open-loop segments (:data:`ilic_cli.diagnosis.dwell.DWELL_MIN_COUNT`)."""
    segment_s: float = SEGMENT_S
    """Refit: length of each open-loop segment driven by the recorded force (s; :data:`ilic_cli.diagnosis.segments.SEGMENT_S`)."""
    segment_level_z: float = LEVEL_Z
    """Refit: the Stribeck level the open-loop segments give must be this many standard deviations above zero, else the recording
    refutes the friction (:data:`ilic_cli.diagnosis.segments.LEVEL_Z`)."""
    refit_round_gain: float = ROUND_GAIN
    """Refit: the share of the closed-loop output error an output-error fit must gain to be kept, and a round of the value searches
    to be repeated. Why 1 %: below it a fit gains what the replay's discretisation moves (:data:`ilic_cli.diagnosis.refit_search.ROUND_GAIN`)."""
    refit_max_rounds: int = MAX_ROUNDS
    """Refit: most rounds of the coordinate search of the kept effects' values. Why 5: on the corpus's Stribeck + flexibility log four
    rounds bring the lag, the resonance and the level to 0.4-4 % (one round left them 9-16 % off; :data:`ilic_cli.diagnosis.refit_search.MAX_ROUNDS`)."""
    drift_windows: int = DRIFT_WINDOWS
    """Report: windows of equal duration the per-window estimates beside a friction drift are shown on (a 30 s log: 3 s each;
    :data:`ilic_cli.diagnosis.drift_windows.WINDOWS`); the drift is tested on all the rows."""
    drift_alpha: float = DRIFT_ALPHA
    """Report: level of the test of a friction trend on the rows, after Bonferroni (:data:`ilic_cli.diagnosis.drift.ALPHA`)."""
    drift_min_change: float = DRIFT_MIN_CHANGE
    """Report: smallest change of a friction coefficient over the log, relative to its start, that is a finding
    (:data:`ilic_cli.diagnosis.drift.MIN_CHANGE`)."""


DiagnoseSettings = DiagnosisSettings
"""The name callers knew (``ilic_cli.diagnosis.DiagnoseSettings``): the same class."""


def replay_alpha(settings: DiagnosisSettings) -> float:
    """Level of the replay's test (:attr:`ilic_cli.diagnosis.null.NullSettings.level`)."""
    return settings.null.level


def drift_test(
    settings: DiagnosisSettings, t: np.ndarray, W: np.ndarray, y: np.ndarray, names: tuple[str, ...], origin: float, nuisance: np.ndarray | None
) -> DriftResult:
    """:func:`~ilic_cli.diagnosis.drift.detect_drift` at the ``settings``' windows, level and least change: the drift test of the
    rigid model's proposal (:func:`ilic_cli.diagnosis.propose.drift_given`) and of the final model (:func:`ilic_cli.diagnosis.refit.drift_on`)."""
    return detect_drift(
        t, W, y, names, origin=origin, n_windows=settings.drift_windows, alpha=settings.drift_alpha, min_change=settings.drift_min_change, nuisance=nuisance
    )
