"""Materiality: a proposed effect whose force is below the inverse model's own residual is not a finding, nor a delay shorter than the rows resolve.

Before any replay (:mod:`ilic_cli.diagnosis.decide`): an effect whose force is below :data:`MATERIAL_FORCE` of
the force (the inverse model's own discretisation residual) wherever the replay may put it, is not a finding. A
drive lag shorter than a sample is judged like any other: on the corpus the replay keeps one of the current
loop's size (0.23 ms) on every log with that loop and the EMPS, paper or trapezoid reference, and on none without it.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.diagnosis.search import SEARCH_STEPS, search_range
from ilic_cli.diagnosis.system import Step, fit_system, system
from ilic_cli.effects import unit_on
from ilic_cli.idim_ls import IDIMData
from ilic_cli.regressor import Model

MATERIAL_FORCE = 0.003
"""An effect whose force (RMS over the rows used) is below this share of the RMS force is not a finding.

Origin: on noise-free closed-loop logs of the plant without any effect (PD on
the EMPS reference and on seeded exciting cycles, Fc = 0 and Fc = 20 N), the
rigid fit with the hold in the baseline leaves 0.18-0.25 % of the force
(the IDIM filters, differentiation and the plant's integration): an effect
whose force is below that whole residual cannot be told from it. The
spurious effects it leaves measured 0.06-0.24 %; a concealed effect that
raises the rigid error by 0.2 points from 1 % has about 0.66 %."""


def immaterial(force_rms: float, total_rms: float, share: float = MATERIAL_FORCE, unit: str = "N") -> str | None:
    """Why an effect adding ``force_rms`` to a force of ``total_rms`` (RMS over the rows used, in ``unit``) is below ``share`` of
    it (:data:`MATERIAL_FORCE`), else ``None``."""
    if total_rms > 0 and force_rms < share * total_rms:
        return f"not material: its force ({force_rms:.3g} {unit} RMS) is below {100 * share:g} % of the force ({total_rms:.3g} {unit} RMS)"
    return None


MIN_DELAY_PERIODS = 0.1
"""A drive lag shorter than this share of the log's sample period is not a finding. The baseline already holds the
force half a period (:mod:`ilic_cli.diagnosis.baseline`) and the delay's grid steps by half a period
(:func:`ilic_cli.effects`' ``delay`` scan): below a tenth of a period the rows cannot tell a lag from the sample
timing (a clean 2 kHz log got -1.0 us, 0.2 % of a period). The lags that are physics are well above it: the
corpus's 700 Hz current loop lags 0.23 ms, 23 % of its 1 kHz period."""


def below_period(step: Step, fs_hz: float, min_periods: float = MIN_DELAY_PERIODS) -> str | None:
    """Why ``step`` is a delay shorter than ``min_periods`` of the sample period, too short to be a finding (:data:`MIN_DELAY_PERIODS`), else ``None``."""
    if step.effect.id != "delay" or step.value is None or isinstance(step.value, tuple):
        return None
    lag, period = abs(float(step.value)), 1.0 / fs_hz
    if lag < min_periods * period:
        return (
            f"not a finding: a delay of {1e6 * lag:.3g} us is below {min_periods:g} of the log's sample period ({1e6 * period:.4g} us), "
            "what the rows cannot tell from the sample timing"
        )
    return None


def materiality(data: IDIMData, base: Model, kept: list[Step], step: Step, rows: np.ndarray, share: float = MATERIAL_FORCE) -> str | None:
    """Why ``step`` is not material on top of ``base + kept`` (:func:`immaterial`), else ``None``.

    An effect whose value the closed loop searches (:data:`ilic_cli.diagnosis.select.SEARCH_STEPS`:
    the inverse model biases it) is immaterial only when its force is below the
    threshold at every value of that search: on the Stribeck + flexibility log
    of the corpus the inverse model's ``vs`` (21 mm/s, truth 8) gives 0.21 % of
    the force, the search's largest 0.33 %, and the replay names the effect.
    """
    force, total = effect_force_rms(data, base, kept, step, rows)
    scan = step.effect.scan
    if step.effect.id in SEARCH_STEPS and scan is not None and not isinstance(step.value, tuple):
        for v in search_range(step.effect, scan.grid(data.kin, data.fs_hz), float(step.value)):
            force = max(force, effect_force_rms(data, base, kept, Step(step.effect, float(v)), rows)[0])
    return immaterial(force, total, share, unit_on("N", data.joint))


def effect_force_rms(data: IDIMData, base: Model, kept: list[Step], step: Step, rows: np.ndarray) -> tuple[float, float]:
    """RMS of the force ``step`` adds to the model ``base + kept`` (fitted on ``rows``), and of the force there (N)."""
    fit = fit_system(data, base, [*kept, step], rows)
    W, y, theta = fit.W, fit.y, fit.theta
    if step.effect.shift:
        W0, y0, _ = system(data, base, kept, rows)
        added = y - y0
    else:
        m = len(step.effect.column_names)
        added = W[:, -m:] @ theta[-m:]
    return float(np.sqrt(np.mean(added**2))), float(np.sqrt(np.mean(y**2)))
