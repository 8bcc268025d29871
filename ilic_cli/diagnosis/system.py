"""The IDIM system of the diagnosis: the rigid regressor plus the columns of the effects in the model, and its least-squares fit.

A :class:`Step` is an effect in the model with its nonlinear value fixed; :func:`system` builds the decimated
``(W, y)`` of ``base + steps`` on the rows the diagnosis uses (:func:`moving_rows`), :func:`fit_system` solves it.
Every stage (propose, decide, refit) fits through these.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.diagnosis.baseline import reversal_samples
from ilic_cli.diagnosis.column_noise import noise_kinematics
from ilic_cli.effects import Effect
from ilic_cli.filtering import kept_indices
from ilic_cli.idim_ls import IDIMData, rebuilt
from ilic_cli.lsq import lstsq, noise_corrected_lstsq
from ilic_cli.regressor import Kinematics, Model, evaluated_later
from ilic_cli.row_spans import valid_rows


@dataclass(frozen=True)
class Step:
    """An effect in the model with its nonlinear parameter fixed.

    ``level``: the effect's linear coefficients (its columns' order), held at
    these values instead of fitted: a closed-loop estimate the inverse model
    cannot make (:mod:`ilic_cli.diagnosis.dwell`); its columns' force is then
    taken off the fitted force (:func:`system`). ``level_std``: their standard
    deviations, when known; ``value_std``: the nonlinear value's, when it was
    estimated with the level.
    """

    effect: Effect
    value: Any = None
    level: tuple[float, ...] | None = None
    level_std: tuple[float, ...] | None = None
    value_std: float | None = None


def change_time(steps: list[Step] | tuple[Step, ...]) -> float | None:
    """The log's time the first of ``steps`` whose value is one stands at (a payload's change,
    :attr:`ilic_cli.effects.Scan.of_the_whole_log`), where the held-out folds are laid on each side
    (:func:`ilic_cli.diagnosis.stats.folds_either_side`); ``None`` when none is."""
    for st in steps:
        if st.effect.scan is not None and st.effect.scan.of_the_whole_log and st.value is not None:
            return float(st.value)
    return None


def moving_rows(data: IDIMData) -> np.ndarray:
    """Decimated rows used by the diagnosis (boolean mask over ``data``'s rows).

    ``data``'s rows are already those every fit uses (:func:`ilic_cli.usable.with_rest`: no standstill, no
    saturated drive, the one definition ``identify`` uses too). Left out here, for the diagnosis's timing:
    mirroring the samples the procedure drops at the start, the rows within as many samples of either end of
    the trimmed record, where the zero-phase filters have their edge transients; and the rows whose decimation
    span touches a velocity reversal, where the Coulomb switch is timed only through the filtered velocity
    (:mod:`ilic_cli.diagnosis.baseline`). A run without dwells (the EMPS recordings) loses only those edge and
    reversal rows.
    """
    n = len(data.kin.qd)
    r = data.settings.decimation
    kept = kept_indices(n, r)
    edge = data.settings.trim
    moving = (kept >= edge) & (kept < n - edge) & valid_rows(~reversal_samples(data.kin.qd), r)
    return moving if data.rows is None else moving[data.rows]


def shifted_force(data: IDIMData, delay_s: float, *, remember: bool = True) -> np.ndarray:
    """Decimated force ``tau(t + delay)``: the plant's ``delay`` (logged force = applied force ``delay`` earlier)."""
    t = data.kin.t
    assert t is not None
    full = lambda: evaluated_later(t, data.tau, delay_s)  # noqa: E731
    return data.decimate_once(("shift", delay_s), full) if remember else data.decimate(full())


def shift_slope(data: IDIMData, delay_s: float, rows: np.ndarray) -> np.ndarray:
    """On ``rows``, the decimated force's slope with respect to a time shift at ``delay_s`` (a central difference of
    :func:`shifted_force` over a tenth of the log's period), one column: the force a small change of that shift adds."""
    h = 0.1 / data.fs_hz
    slope = (shifted_force(data, delay_s + h, remember=False) - shifted_force(data, delay_s - h, remember=False)) / (2 * h)
    return slope[rows][:, None]


def shift_slopes(data: IDIMData, steps: list[Step] | tuple[Step, ...], rows: np.ndarray) -> np.ndarray:
    """:func:`shift_slope` at each time shift among ``steps``, one column each: what a fit at the shift's value cannot otherwise
    take up (none: zero columns)."""
    cols = [shift_slope(data, float(s.value or 0.0), rows) for s in steps if s.effect.shift]
    return np.hstack(cols) if cols else np.empty((int(np.count_nonzero(rows)), 0))


def shift_value(steps: list[Step] | tuple[Step, ...]) -> float:
    """The time shift :func:`system` applies for ``steps`` (s; 0: none)."""
    return next((float(s.value or 0.0) for s in reversed(steps) if s.effect.shift), 0.0)


def effect_columns(data: IDIMData, effect: Effect, value: Any = None, *, remember: bool = True) -> np.ndarray:
    """Decimated columns of ``effect`` at ``value`` on ``data``.

    ``remember``: decimate each (effect, value) once on this data (the steps of
    the model and the linear effects, asked for at every step and fold); the
    values tried while refining a nonlinear parameter are not kept.
    """
    full = lambda: effect.matrix(data.kin, value, data.fs_hz)  # noqa: E731
    return data.decimate_once((effect.id, value), full) if remember else data.decimate(full())


def extended(base: Model, steps: list[Step] | tuple[Step, ...], fs_hz: float) -> Model:
    """The regressor of ``base`` plus the columns of ``steps`` (a time shift adds none, nor a step whose level is held)."""
    columns = [c for s in steps if s.level is None for c in s.effect.regressor_columns(s.value, fs_hz)]
    return base.extend(*columns, name=base.name + "".join(f"+{s.effect.id}" for s in steps)) if columns else base


def system(data: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...], rows: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The decimated system ``(W, y, names)`` of :func:`extended` ``(base, steps)`` on ``data``.

    ``data`` must have been prepared with ``base`` (its ``W`` holds the base
    columns, decimated once); each step's columns are decimated once on
    ``data`` (:func:`effect_columns`) and join them in the order of the
    extended model. ``rows`` (default :func:`moving_rows`) selects the rows.
    A step whose ``level`` is held adds no column: its force is taken off ``y``.
    """
    model = extended(base, steps, data.fs_hz)
    y = data.y
    cols = [data.W]
    if any(s.effect.shift for s in steps):
        y = shifted_force(data, shift_value(steps))
    for s in steps:
        if s.level is not None:
            y = y - effect_columns(data, s.effect, s.value) @ np.asarray(s.level, dtype=np.float64)
        elif not s.effect.shift:
            cols.append(effect_columns(data, s.effect, s.value))
    keep = moving_rows(data) if rows is None else rows
    W = np.hstack(cols)
    assert W.shape[1] == len(model.names)
    return W[keep], y[keep], model.names


@dataclass(frozen=True)
class SystemFit:
    """The least-squares fit of :func:`system` ``(data, base, steps, rows)``: the system and its estimate."""

    names: tuple[str, ...]
    theta: np.ndarray
    W: np.ndarray
    y: np.ndarray


NOISE_REALISATIONS = 6
"""Realisations of the position's noise whose columns give their covariance (:func:`column_noise`)."""


def column_noise(data: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...], rows: np.ndarray | None = None) -> np.ndarray | None:
    """The noise the measured position puts in the columns of ``base + steps`` (:func:`system`), realised
    :data:`NOISE_REALISATIONS` times, shape ``(K, rows, columns)``; ``None`` when no step has noisy columns
    (:attr:`ilic_cli.effects.Effect.noisy_columns`) or the position's noise is not known.

    Each realisation is the system built on the kinematics plus those of white noise of the log's position noise
    (:func:`ilic_cli.diagnosis.column_noise.noise_kinematics`), less the system itself: exact for the columns linear in the
    kinematics, and for the others what the noise changes. Computed once per model on ``data``.
    """
    if not data.position_noise_std > 0 or not any(s.level is None and s.effect.noisy_columns for s in steps):
        return None
    keep = moving_rows(data) if rows is None else rows
    # by the columns only: a shift or a held level changes the force, not the columns (a lag's values searched per fold)
    key = ("column noise", base.name, tuple((s.effect.id, s.value) for s in steps if s.level is None and not s.effect.shift), keep.tobytes())
    if key not in data.memo:
        W, _, _ = system(data, base, steps, keep)
        k = data.kin
        out = []
        for seed in range(NOISE_REALISATIONS):
            n = noise_kinematics(data, seed)
            q = None if k.q is None or n.q is None else k.q + n.q
            noisy = Kinematics(qd=k.qd + n.qd, qdd=k.qdd + n.qdd, q=q, t=k.t, sign_qd=k.sign_qd, extra=k.extra, speed_noise=k.speed_noise)
            out.append(system(rebuilt(data, base, noisy), base, steps, keep)[0] - W)
        data.memo[key] = np.stack(out)
    return data.memo[key]


def fit_system(data: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...], rows: np.ndarray | None = None, train: np.ndarray | None = None) -> SystemFit:
    """Fit ``base + steps`` on ``data``'s ``rows`` (default :func:`moving_rows`) by least squares, on ``train`` of them when given.

    The one inverse-model fit of the diagnosis (the IDIM estimate, eq. (8) of the
    paper, with the effect columns beside the rigid ones); ``W`` and ``y`` are
    the whole selected system, ``train`` or not. A model with columns that carry
    the position's noise amplified (a flexibility) is fitted by least squares
    corrected for it (:func:`column_noise`, :func:`ilic_cli.lsq.noise_corrected_lstsq`).
    """
    W, y, names = system(data, base, steps, rows)
    sel = slice(None) if train is None else train
    noise = column_noise(data, base, steps, rows)
    theta, _ = lstsq(W[sel], y[sel]) if noise is None else noise_corrected_lstsq(W[sel], y[sel], noise[:, sel])
    return SystemFit(names, theta, W, y)
