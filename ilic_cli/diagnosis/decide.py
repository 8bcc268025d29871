"""The replay decides: a candidate the inverse model proposes is kept only when the closed loop agrees.

The inverse-model statistics (:mod:`ilic_cli.diagnosis.select`) propose and
rank effects; on closed-loop data they also accept artefacts that are present
all along (discretisation, stick at reversals), since held-out blocks of the
same recording share them. Here each proposed effect, in the order accepted,
is refitted without each of ``k`` contiguous time blocks, the recorded
reference is replayed through the plant (:func:`ilic_cli.simulation.replay.replay`)
with and without it (with the recording's own position noise and
quantisation, corrected for the loop on the baseline's replay, one realisation
shared by every replay: :func:`decision_sensor`),
and the simulated force and position are compared with
the recording on the block left out (the force in the band of the inverse
model: the error decimated as the IDIM system is). A value the inverse model
is known to bias (a drive lag, Stribeck ``vs``) is first searched on each
fold's training blocks in closed loop (:func:`fold_value`), so the replay
judges the effect at a value the held-out block did not shape. The effect is
kept when the held-out simulated force error falls (one-sided
Diebold-Mariano on the held-out errors at the decimated rows, Newey-West
variance), the held-out position error does not rise, and, with a validation
log, its replay error does not rise either.
A rejected effect is left out and the next one is tried against the model
kept so far.

Before any replay, materiality (:func:`materiality`): an effect whose force is
below :data:`MATERIAL_FORCE` of the force (the inverse model's own
discretisation residual) wherever the replay may put it, is not a finding. A
drive lag shorter than a sample is judged like any other: on the corpus the
replay keeps one of the current loop's size (0.23 ms) on every log with that
loop and the EMPS, paper or trapezoid reference, and on none without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.diagnosis import dwell
from ilic_cli.diagnosis.select import SEARCH_STEPS, Step, SystemFit, at_edge, fit_system, minimise, search_range, system
from ilic_cli.diagnosis.sensor import recorded_sensor
from ilic_cli.diagnosis.stats import blocked_folds, diebold_mariano
from ilic_cli.errors import ParameterError
from ilic_cli.filtering import decimate_matlab, kept_indices
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.lsq import relative_error_pct
from ilic_cli.parallel import ordered_map
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import relative_errors, replay

if TYPE_CHECKING:
    from ilic_cli.diagnosis.null import MonteCarloNull, NullDistribution

MATERIAL_FORCE = 0.003
"""An effect whose force (RMS over the rows used) is below this share of the RMS force is not a finding.

Origin: on noise-free closed-loop logs of the plant without any effect (PD on
the EMPS reference and on seeded exciting cycles, Fc = 0 and Fc = 20 N), the
rigid fit with the hold in the baseline leaves 0.18-0.25 % of the force
(the IDIM filters, differentiation and the plant's integration): an effect
whose force is below that whole residual cannot be told from it. The
spurious effects it leaves measured 0.06-0.24 %; a concealed effect that
raises the rigid error by 0.2 points from 1 % has about 0.66 %."""

FOLD_XATOL_STEPS = 0.1
"""Tolerance of :func:`fold_value`'s search, in steps of the effect's grid (a drive lag: 0.05 ms on its 0.5 ms grid)."""

REPLAY_SEED = 0
"""Seed of the sensor noise in the replays that decide: one realisation, the same in every replay (common random numbers),
so that a fall of the error is the effect's, not the noise's."""

DM_TEST = "Diebold-Mariano, one-sided, Newey-West variance, held-out replay force errors"

PlantOf = Callable[[list[Step], tuple[str, ...], np.ndarray], tuple[dict[str, float], dict[str, Any]]]
"""``(steps, names, theta) -> (rigid parameters, plant effects)``."""


PROPOSED_BY_INVERSE = "inverse model"
"""``ReplayVerdict.proposed_by`` of a candidate the inverse model proposed (:mod:`ilic_cli.diagnosis.select`)."""


@dataclass(frozen=True)
class ReplayVerdict:
    """The closed-loop replay's judgement of one proposed effect (held-out relative errors, %)."""

    effect: str
    force_before: float | None
    force_after: float | None
    position_before: float | None
    position_after: float | None
    p_value: float | None
    validation_before: float | None
    validation_after: float | None
    accepted: bool
    reason: str
    null: NullDistribution | None = None
    searched: tuple[Any, ...] | None = None
    """The value used in each fold when it was searched on the fold's training blocks (:func:`fold_value`);
    a closed-loop proposal's ``(vs, Fs)`` per fold, ``None`` where a fold found none (:mod:`ilic_cli.diagnosis.dwell`)."""
    proposed_by: str = PROPOSED_BY_INVERSE
    """Who proposed the effect: the inverse model, or the closed loop (:data:`ilic_cli.diagnosis.dwell.METHOD`)."""

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "heldout_simulated_force_relative_error_pct": {"before": self.force_before, "after": self.force_after},
            "heldout_simulated_position_relative_error_pct": {"before": self.position_before, "after": self.position_after},
            "test": self._test(),
            "validation_simulated_force_relative_error_pct": None
            if self.validation_before is None
            else {"before": self.validation_before, "after": self.validation_after},
            "fold_values": None if self.searched is None else list(self.searched),
            "proposed_by": self.proposed_by,
            "accepted": self.accepted,
            "reason": self.reason,
        }

    def _test(self) -> dict[str, Any] | None:
        """The test that decided (``None``: none ran), with the Monte-Carlo null's summary when it was that one."""
        if self.null is not None:
            from ilic_cli.diagnosis.null import MC_TEST

            return {
                "test": f"{MC_TEST}; and {DM_TEST}",
                "p_value": self.p_value,
                "diebold_mariano_p_value": self.null.dm_p_value,
                "replicates": len(self.null.t_null),
                "null_distribution": self.null.to_dict(),
            }
        return None if self.p_value is None else {"test": DM_TEST, "p_value": self.p_value}


def immaterial(force_rms: float, total_rms: float) -> str | None:
    """Why an effect adding ``force_rms`` to a force of ``total_rms`` (N RMS, rows used) is below :data:`MATERIAL_FORCE`, else ``None``."""
    if total_rms > 0 and force_rms < MATERIAL_FORCE * total_rms:
        return f"not material: its force ({force_rms:.3g} N RMS) is below {100 * MATERIAL_FORCE:g} % of the force ({total_rms:.3g} N RMS)"
    return None


MIN_DELAY_PERIODS = 0.1
"""A drive lag shorter than this share of the log's sample period is not a finding. The baseline already holds the
force half a period (:mod:`ilic_cli.diagnosis.baseline`) and the delay's grid steps by half a period
(:func:`ilic_cli.effects`' ``delay`` scan): below a tenth of a period the rows cannot tell a lag from the sample
timing (a clean 2 kHz log got -1.0 us, 0.2 % of a period). The lags that are physics are well above it: the
corpus's 700 Hz current loop lags 0.23 ms, 23 % of its 1 kHz period."""


def below_period(step: Step, fs_hz: float) -> str | None:
    """Why ``step`` is a delay too short to be a finding (:data:`MIN_DELAY_PERIODS`), else ``None``."""
    if step.effect.id != "delay" or step.value is None or isinstance(step.value, tuple):
        return None
    lag, period = abs(float(step.value)), 1.0 / fs_hz
    if lag < MIN_DELAY_PERIODS * period:
        return (
            f"not a finding: a delay of {1e6 * lag:.3g} us is below {MIN_DELAY_PERIODS:g} of the log's sample period ({1e6 * period:.4g} us), "
            "what the rows cannot tell from the sample timing"
        )
    return None


def materiality(data: IDIMData, base: Model, kept: list[Step], step: Step, rows: np.ndarray) -> str | None:
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
    return immaterial(force, total)


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


def _replayed(log: RunLog, plant_of: PlantOf, steps: list[Step], fit: SystemFit, sensor: dict[str, Any]) -> RunLog | None:
    rigid, effects = plant_of(steps, fit.names, fit.theta)
    try:
        return replay(log, rigid, {**sensor, **effects}, seed=REPLAY_SEED)
    except ParameterError:
        return None


def band_force_error(rec: RunLog, sim: RunLog, decimation: int) -> np.ndarray:
    """Simulated minus recorded force, decimated as the IDIM system is (every decimated sample of the log)."""
    return decimate_matlab(np.asarray(sim["tau"]) - np.asarray(rec["tau"]), max(decimation, 1))


def noisy_output_error(log: RunLog, ls: LSSettings, rigid: dict[str, float], effects: dict[str, Any], sensor: dict[str, Any]) -> float:
    """The closed-loop output error (%) of a plant replayed with the deciding replays' ``sensor`` noise (seed :data:`REPLAY_SEED`).

    The replayed force against the recorded one in the inverse model's band (:func:`band_force_error`), the
    filters' edges (``ls.trim`` samples each side) left out; ``inf`` when the plant does not simulate.
    """
    try:
        sim = replay(log, rigid, {**sensor, **effects}, seed=REPLAY_SEED)
    except ParameterError:
        return float("inf")
    r = max(ls.decimation, 1)
    edge = slice(ls.trim // r, len(log) // r - ls.trim // r)
    tau = decimate_matlab(np.asarray(log["tau"]), r)[edge]
    return relative_error_pct(tau, tau + band_force_error(log, sim, r)[edge])


def decision_sensor(log: RunLog, ls: LSSettings, data: IDIMData, base: Model, known: list[Step], rows: np.ndarray, plant_of: PlantOf) -> dict[str, Any]:
    """The sensor effects the deciding replays on ``log`` carry: :func:`~ilic_cli.diagnosis.sensor.recorded_sensor`, loop-corrected on the baseline.

    The baseline is ``base + known`` fitted on ``data``'s ``rows``, replayed on
    ``log`` (seed :data:`REPLAY_SEED`), as every deciding replay is. ``log`` is
    the recording of ``data``, or a validation log (with its own ``ls``).
    """
    baseline = fit_system(data, base, known, rows)
    return recorded_sensor(log, ls, lambda sensor: _replayed(log, plant_of, known, baseline, sensor))


def replay_decide(
    log: RunLog,
    data: IDIMData,
    base: Model,
    known: list[Step],
    proposed: list[Step],
    rows: np.ndarray,
    plant_of: PlantOf,
    *,
    folds: int = 5,
    alpha: float = 0.01,
    validate: tuple[RunLog, LSSettings] | None = None,
    null: MonteCarloNull | None = None,
    sensor_noise: bool = True,
    sensor: dict[str, Any] | None = None,
) -> tuple[list[Step], list[ReplayVerdict]]:
    """Keep the proposed steps that lower the held-out closed-loop output error, in order.

    Parameters
    ----------
    log : RunLog
        The recording (with ``q_ref``: the reference replayed through the log's controller).
    data : IDIMData
        Its IDIM system (prepared with ``base``, the baseline of :mod:`ilic_cli.diagnosis.baseline`).
    base : Model
        Rigid structure.
    known : list of Step
        Effects of a model file, kept and not judged.
    proposed : list of Step
        Effects the inverse model accepted, in order.
    rows : ndarray of bool
        Decimated rows used (:func:`ilic_cli.diagnosis.select.moving_rows`).
    plant_of : callable
        Plant parameters of a fit (:func:`ilic_cli.diagnosis.core.model_parameters`).
    folds : int
        Contiguous held-out time blocks.
    alpha : float
        Level of the one-sided test that the held-out force error falls.
    validate : (RunLog, LSSettings), optional
        A validation recording (and the settings of :func:`ilic_cli.simulation.replay.relative_errors`):
        its simulated force error, with the model fitted on ``data``, must not rise.
    null : MonteCarloNull, optional
        A Monte-Carlo null of the closed loop (:mod:`ilic_cli.diagnosis.null`): computed when the error
        falls and the Diebold-Mariano test is significant, whose p must then be at most ``alpha`` too.
    sensor_noise : bool
        Replay with the recording's position noise and quantisation (:func:`ilic_cli.diagnosis.sensor.recorded_sensor`,
        one realisation, seed :data:`REPLAY_SEED`, shared by every replay); ``False``: noise-free replays.
        The noise is loop-corrected on the baseline (:func:`decision_sensor`), the validation log's too.
    sensor : dict, optional
        ``log``'s :func:`decision_sensor` when the caller has it already (used when ``sensor_noise``).

    Returns
    -------
    (list of Step, list of ReplayVerdict)
        The steps kept (``known`` first) and one verdict per proposed step.
    """
    t_rows = data.t_dec[rows]
    n_rows = int(rows.sum())
    t = np.asarray(log.t)
    blocks = [
        (int(np.searchsorted(t, t_rows[test[0]])), int(np.searchsorted(t, t_rows[test[-1]], side="right"))) for _, test in blocked_folds(n_rows, folds, 0)
    ]
    trains = [train for train, _ in blocked_folds(n_rows, folds, 10)]
    tau = np.asarray(log["tau"])
    q = np.asarray(log["q"])
    n = len(log)
    step_dec = max(data.settings.decimation, 1)
    # the force is compared in the band the inverse model sees (its parallel
    # decimation): a recorded closed-loop force carries the controller's answer
    # to position noise, which no noise-free replay reproduces and which would
    # otherwise hide any effect (measured: 22 % raw error on a clean PD log)
    at = kept_indices(n, step_dec)
    in_block = [(at >= a) & (at < b) for a, b in blocks]
    tau_dec = decimate_matlab(tau, step_dec)

    if not sensor_noise:
        sensor = {}
    elif sensor is None:
        sensor = decision_sensor(log, data.settings, data, base, known, rows, plant_of)
    vsensor = decision_sensor(*validate, data, base, known, rows, plant_of) if sensor_noise and validate is not None else {}
    others_of = [np.any([sel for j, sel in enumerate(in_block) if j != fold], axis=0) for fold in range(len(in_block))]

    def fold_replay(steps: list[Step], train: np.ndarray, noise: dict[str, Any] = sensor) -> RunLog | None:
        """The replay of the model fitted on ``train`` (with the sensor ``noise``), or ``None`` when it is no valid plant."""
        sim = _replayed(log, plant_of, steps, fit_system(data, base, steps, rows, train), noise)
        return sim if sim is not None and len(sim) == n else None

    def force_error(sim: RunLog) -> np.ndarray:
        """Simulated minus recorded force, decimated as the IDIM system is (all the log's decimated samples)."""
        return band_force_error(log, sim, step_dec)

    def fold_search(train: np.ndarray, fold: int, noise: dict[str, Any]) -> tuple[Callable[[list[Step]], RunLog | None], Callable[[list[Step]], float]]:
        """A fold's replay of a model fitted on ``train`` with the sensor ``noise`` (each model once), and its training error."""
        sims: dict[Any, RunLog | None] = {}

        def replay_of(steps: list[Step]) -> RunLog | None:
            key = (len(steps), steps[-1].value, steps[-1].level) if steps else None
            if key not in sims:
                sims[key] = fold_replay(steps, train, noise)
            return sims[key]

        def training_error(steps: list[Step]) -> float:
            sim = replay_of(steps)
            if sim is None:
                return np.inf
            e = force_error(sim)[others_of[fold]]
            return float(e @ e)

        return replay_of, training_error

    def searched_fold(given: list[Step], grid: np.ndarray, train: np.ndarray, fold: int) -> tuple[list[Step], RunLog | None]:
        """``given`` with its last step's value searched on the fold's training blocks (:func:`fold_value`), and its replay.

        The search replays noise-free: a value is estimated there, and the replay's own answer to its sensor noise,
        which the recording does not share, would pull it (a 1.0 ms drive lag: searched at 0.71-0.84 ms with the
        noise, 0.94-1.0 ms without). The replay returned, which the held-out block judges, has the noise.
        """
        replay_at, training_error = fold_search(train, fold, {})
        steps = [*given[:-1], fold_value(given[:-1], given[-1], grid, training_error)]
        return steps, fold_replay(steps, train) if sensor else replay_at(steps)

    def dwell_fold(given: list[Step], train: np.ndarray, fold: int) -> tuple[list[Step], RunLog | None, Step | None]:
        """``given`` with its last step, a closed-loop proposal, searched on the fold's training blocks (:func:`ilic_cli.diagnosis.dwell.search`).

        With the sensor noise, as the recording has it: the creep at the dwells is the noise's. Without an estimate
        the fold keeps the model without the step.
        """
        prefix, step = given[:-1], given[-1]
        replay_of, training_error = fold_search(train, fold, sensor)
        rigid = fit_system(data, base, prefix, rows, train)
        fc = dwell.coulomb_N(rigid.names, rigid.theta) or 0.0
        vs, fs = dwell.grids(step.effect.scan.grid(data.kin, data.fs_hz) if step.effect.scan is not None else np.array([]), fc)
        found = dwell.search(step, vs, fs, lambda st: training_error([*prefix, st]), training_error(prefix))
        steps = prefix if found is None else [*prefix, found]
        return steps, replay_of(steps), found

    def heldout(steps: list[Step], search: bool = False) -> tuple[np.ndarray, np.ndarray, list[Any]] | None:
        """Held-out simulated force (decimated) and position errors (blocks concatenated), or ``None`` when a fold is no valid plant.

        ``search``: the last step's nonlinear value is searched on each fold's training blocks first (:func:`fold_value`);
        the third item lists the values used, one per fold.
        """
        given = list(steps)
        level = search and given[-1].level is not None
        grid = given[-1].effect.scan.grid(data.kin, data.fs_hz) if search and not level and given[-1].effect.scan is not None else None

        def fold(i: int) -> tuple[np.ndarray, np.ndarray, Any] | None:
            (a, b), train, sel = blocks[i], trains[i], in_block[i]
            if level:
                fold_steps, sim, used = dwell_fold(given, train, i)
            else:
                fold_steps, sim = searched_fold(given, grid, train, i) if grid is not None else (given, fold_replay(given, train))
                used = fold_steps[-1].value if fold_steps else None
            return None if sim is None else (force_error(sim)[sel], np.asarray(sim["q"][a:b]) - q[a:b], used)

        out = ordered_map(fold, range(len(blocks)))  # the folds are independent: side by side
        if any(r is None for r in out):
            return None
        done = [r for r in out if r is not None]
        return np.concatenate([r[0] for r in done]), np.concatenate([r[1] for r in done]), [r[2] for r in done]

    idx_tau = np.concatenate([np.flatnonzero(sel) for sel in in_block])
    idx_q = np.concatenate([np.arange(a, b) for a, b in blocks])

    def rel(e: np.ndarray, ref: np.ndarray, idx: np.ndarray) -> float:
        return relative_error_pct(ref[idx], ref[idx] + e)

    kept = list(known)
    current = heldout(kept)
    verdicts: list[ReplayVerdict] = []
    for st in proposed:
        proposed_here = st.level is not None  # a closed-loop proposal (:mod:`ilic_cli.diagnosis.dwell`): its level and value searched per fold
        by = dwell.METHOD if proposed_here else PROPOSED_BY_INVERSE
        search = proposed_here or (st.effect.id in SEARCH_STEPS and st.effect.scan is not None and not isinstance(st.value, tuple))
        after = heldout([*kept, st], search) if current is not None else None
        if current is None or after is None:
            verdicts.append(
                ReplayVerdict(st.effect.id, None, None, None, None, None, None, None, False, "the fitted model is not a valid plant: no replay", proposed_by=by)
            )
            continue
        fb, fa = rel(current[0], tau_dec, idx_tau), rel(after[0], tau_dec, idx_tau)
        pb, pa = rel(current[1], q, idx_q), rel(after[1], q, idx_q)
        p_dm = p = diebold_mariano(current[0], after[0])
        mc, significant = None, p < alpha
        if proposed_here:
            judged_step, searched_text = dwell.judged(after[2])
            if judged_step is None:
                verdicts.append(
                    ReplayVerdict(st.effect.id, fb, fa, pb, pa, None, None, None, False, f"rejected by the replay: {searched_text}", proposed_by=by)
                )
                continue
        if null is not None and significant and fa < fb and not proposed_here:
            # both tests must agree: the Monte-Carlo null catches what is present all along (its replicates have it too),
            # the Diebold-Mariano test what the null's rough noise model makes of a small fall (null_calibration: the
            # Monte-Carlo p alone <= 0.05 on 23 of 104 spurious candidates, both on 5)
            mc = null.distribution(log, data, base, kept, st, rows, plant_of, folds, p)
            p = mc.p_value
            significant = p <= alpha * (1 + 1e-9)
        p_text = f"p = {p:.2g}" if mc is None else f"Monte-Carlo p = {p:.2g}, B = {len(mc.t_null)}; Diebold-Mariano p = {p_dm:.2g}"
        searched = ""
        judged = st
        if proposed_here:
            assert judged_step is not None  # refused above when None
            judged = judged_step
            searched = (
                "; "
                + searched_text
                + (" (the Monte-Carlo null re-proposes through the inverse model, which cannot: Diebold-Mariano alone)" if null is not None else "")
            )
        elif search:
            scan = st.effect.scan
            assert scan is not None
            values = np.asarray(after[2], dtype=np.float64)
            judged = Step(st.effect, float(np.median(values)))
            searched = (
                f"; {scan.name} searched on the closed loop of each fold's training blocks: "
                f"{_fmt(values.min(), scan.unit)} to {_fmt(values.max(), scan.unit)} (inverse model {_fmt(float(st.value), scan.unit)})"
            )
        vb = va = None
        if validate is not None:
            vlog, vls = validate
            sims = [_replayed(vlog, plant_of, s, fit_system(data, base, s, rows), vsensor) for s in (kept, [*kept, judged])]
            if sims[0] is not None and sims[1] is not None:
                vb, va = relative_errors(vlog, sims[0], vls)["force"], relative_errors(vlog, sims[1], vls)["force"]
        if not fa < fb:
            ok, why = False, f"rejected by the replay: the held-out simulated force error does not fall ({fb:.3g} % -> {fa:.3g} %)"
        elif not significant:
            ok, why = (
                False,
                (f"rejected by the replay: the held-out simulated force error falls ({fb:.3g} % -> {fa:.3g} %) but not significantly ({p_text})"),
            )
        elif pa > pb:
            ok, why = False, f"rejected by the replay: the held-out simulated position error rises ({pb:.3g} % -> {pa:.3g} %)"
        elif va is not None and vb is not None and va > vb:
            ok, why = False, f"rejected by the replay: the validation log's simulated force error rises ({vb:.3g} % -> {va:.3g} %)"
        elif (short := below_period(judged, data.fs_hz)) is not None:
            ok, why = False, short
        else:
            ok, why = (
                True,
                (f"the replay agrees: held-out simulated force error {fb:.3g} % -> {fa:.3g} % ({p_text}), position {pb:.3g} % -> {pa:.3g} %"),
            )
        fold_values = tuple(float(v) for v in after[2]) if search and not proposed_here else tuple(dwell.fold_values(after[2])) if proposed_here else None
        verdicts.append(ReplayVerdict(st.effect.id, fb, fa, pb, pa, p, vb, va, ok, why + searched, mc, fold_values, by))
        if ok:
            kept.append(judged if proposed_here else st)
            # the next candidate is judged against the model as kept: ``after`` replayed each fold at the value searched
            # there, the kept step has one value (measured: on a clean current-loop trapezoid the kept lag's own value
            # gave a held-out error of 0.869 %, the per-fold values 0.892 %, a fall a next candidate would be credited with)
            current = heldout(kept) if search and st is not proposed[-1] else after
    return kept, verdicts


def _fmt(value: float, unit: str) -> str:
    """A searched value for the report (a time in ms)."""
    return f"{value * 1e3:.3g} ms" if unit == "s" else f"{value:.4g} {unit}".strip()


def fold_value(prefix: list[Step], step: Step, grid: np.ndarray, training_error: Callable[[list[Step]], float]) -> Step:
    """``step`` with its nonlinear value searched on one fold's closed-loop training error (``prefix`` kept before it).

    The inverse model's estimate of some effects is off by several steps of
    its grid on closed-loop data (:data:`ilic_cli.diagnosis.select.SEARCH_STEPS`:
    a drive lag 30-66 % too long), which can hide a real effect from the
    replay. Within that range of ``grid`` around the inverse value, the value
    is searched on the simulated force error of the fold's training blocks
    (the linear parameters refitted by the inverse model at each value), so
    the held-out block still judges a model it did not shape. An optimum on
    the edge of the range, or one that does not lower the training error,
    keeps the inverse value.
    """
    scan = step.effect.scan
    assert scan is not None
    v0 = float(step.value)
    sub = search_range(step.effect, grid, v0)
    lo, hi = float(sub[0]), float(sub[-1])
    if not hi > lo:
        return step
    memo: dict[float, float] = {}

    def err(v: float) -> float:
        if v not in memo:
            memo[v] = training_error([*prefix, Step(step.effect, v)])
        return memo[v]

    best = minimise(err, lo, hi, scan.log and lo > 0, rel_tol=FOLD_XATOL_STEPS / max(len(sub) - 1, 1))
    if at_edge(step.effect, sub, best) or not err(best) < err(v0):
        return step
    return Step(step.effect, best)
