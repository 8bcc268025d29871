"""The replay decides: a candidate the inverse model proposes is kept only when the closed loop agrees (:func:`replay_decide`).

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
fold's training blocks in closed loop (:func:`~ilic_cli.diagnosis.search.fold_value`), so the replay
judges the effect at a value the held-out block did not shape. The effect is
kept when the held-out simulated force error falls (one-sided
Diebold-Mariano on the held-out errors at the decimated rows, Newey-West
variance), the held-out position error does not rise, and, with a validation
log, its replay error does not rise either.
A rejected effect is left out and the next one is tried against the model
kept so far.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ilic_cli.diagnosis.compare import band_force_error, band_force_error_pct
from ilic_cli.diagnosis.drift import GivenDrift
from ilic_cli.diagnosis.dwell import IN_MOTION_ALPHA, reference_moving
from ilic_cli.diagnosis.fold_plant import MIN_PLANT_FOLDS, fitted_plant, fold_fit, not_a_plant
from ilic_cli.diagnosis.materiality import MIN_DELAY_PERIODS, below_period
from ilic_cli.diagnosis.replay_again import Heldout, judged_again
from ilic_cli.diagnosis.search import FOLD_XATOL_STEPS, SEARCH_STEPS, FoldValue, fold_value
from ilic_cli.diagnosis.sensor import recorded_sensor
from ilic_cli.diagnosis.stats import contiguous_runs, folds_either_side, heldout_fall_p
from ilic_cli.diagnosis.strategies import IdentificationStrategy, strategy_of
from ilic_cli.diagnosis.system import Step, SystemFit, change_time, fit_system
from ilic_cli.diagnosis.verdicts import PROPOSED_BY_INVERSE, PlantOf, ReplayNull, ReplayVerdict, Verdict, replay_verdict
from ilic_cli.errors import DivergedError, ParameterError
from ilic_cli.filtering import decimate_matlab, kept_indices
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.lsq import relative_error_pct
from ilic_cli.parallel import ordered_map
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import relative_errors, replay

REPLAY_SEED = 0
"""Seed of the sensor noise in the replays that decide: one realisation, the same in every replay (common random numbers),
so that a fall of the error is the effect's, not the noise's."""


def _replayed(log: RunLog, plant_of: PlantOf, steps: list[Step], fit: SystemFit, sensor: dict[str, Any]) -> RunLog | None:
    return _replayed_plant(log, plant_of(steps, fit.names, fit.theta), sensor)


def _replayed_plant(log: RunLog, plant: tuple[dict[str, float], dict[str, Any]], sensor: dict[str, Any]) -> RunLog | None:
    """The replay of ``plant`` on ``log``; ``None`` when it is no plant (a parameter out of its range) or it diverges in the
    recording's loop, which the recording did not (corpus s9722: a Stribeck level of the dwells' search beside a flexibility,
    at 12 ms; before, the whole diagnosis stopped with an error)."""
    rigid, effects = plant
    try:
        return replay(log, rigid, {**sensor, **effects}, seed=REPLAY_SEED)
    except (ParameterError, DivergedError):
        return None


def noisy_output_error(log: RunLog, ls: LSSettings, rigid: dict[str, float], effects: dict[str, Any], sensor: dict[str, Any]) -> float:
    """The closed-loop output error (%) of a plant replayed with the deciding replays' ``sensor`` noise (seed :data:`REPLAY_SEED`).

    The replayed force against the recorded one in the inverse model's band (:func:`band_force_error`), the
    filters' edges (``ls.trim`` samples each side) left out; ``inf`` when the plant does not simulate.
    """
    sim = _replayed_plant(log, (rigid, effects), sensor)  # None: no plant, or one the recording's loop does not hold
    return float("inf") if sim is None else band_force_error_pct(log, sim, ls)


def decision_sensor(
    log: RunLog, ls: LSSettings, data: IDIMData, base: Model, known: list[Step], rows: np.ndarray, plant_of: PlantOf, drift: GivenDrift | None = None
) -> dict[str, Any]:
    """The sensor effects the deciding replays on ``log`` carry: :func:`~ilic_cli.diagnosis.sensor.recorded_sensor`, loop-corrected on the baseline.

    The baseline is ``base + known`` fitted on ``data``'s ``rows`` (with a ``drift`` found on the rigid model: :func:`fitted_plant`),
    replayed on ``log`` (seed :data:`REPLAY_SEED`), as every deciding replay is. ``log`` is
    the recording of ``data``, or a validation log (with its own ``ls``; no drift: it is the fitting log's).
    """
    baseline = fitted_plant(data, base, known, rows, plant_of, drift=drift)
    return recorded_sensor(log, ls, lambda sensor: _replayed_plant(log, baseline, sensor))


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
    null: ReplayNull | None = None,
    sensor_noise: bool = True,
    sensor: dict[str, Any] | None = None,
    min_delay_periods: float = MIN_DELAY_PERIODS,
    fold_xatol_steps: float = FOLD_XATOL_STEPS,
    drift: GivenDrift | None = None,
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
    min_delay_periods : float
        A judged delay shorter than this share of the sample period is not a finding (:func:`~ilic_cli.diagnosis.materiality.below_period`).
    fold_xatol_steps : float
        Tolerance of the per-fold search of a biased value (:func:`~ilic_cli.diagnosis.search.fold_value`), in grid steps.
    drift : GivenDrift, optional
        A friction drift found on the rigid model (:func:`ilic_cli.diagnosis.propose.drift_given`): every fold's fit has its
        trends' columns, every replayed plant its ``friction_drift`` (:func:`fitted_plant`), the baseline's and the sensor noise's too.

    Returns
    -------
    (list of Step, list of ReplayVerdict)
        The steps kept (``known`` first) and one verdict per proposed step.
    """
    if not sensor_noise:
        sensor = {}
    elif sensor is None:
        sensor = decision_sensor(log, data.settings, data, base, known, rows, plant_of, drift)
    vsensor = decision_sensor(*validate, data, base, known, rows, plant_of) if sensor_noise and validate is not None else {}
    replays = HeldoutReplays(log, data, base, rows, plant_of, folds, sensor, change_time([*known, *proposed]))
    replays.drift = drift
    replays.min_delay_periods, replays.fold_xatol_steps = min_delay_periods, fold_xatol_steps
    kept = list(known)
    current = replays.heldout(kept)
    verdicts: list[ReplayVerdict] = []
    for st in proposed:
        proposed_here = st.level is not None  # a closed-loop proposal (:mod:`ilic_cli.diagnosis.dwell`): its level and value searched per fold
        by = _strategy(st).method if proposed_here else PROPOSED_BY_INVERSE
        search = proposed_here or (st.effect.id in SEARCH_STEPS and st.effect.scan is not None and not isinstance(st.value, tuple))
        after = replays.heldout([*kept, st], search) if current is not None else None
        if current is None or after is None:
            verdicts.append(ReplayVerdict.unjudged(st.effect.id, Verdict.NO_PLANT, "the fitted model is not a valid plant: no replay", by))
            continue
        verdict, judged = replays.judge(st, kept, current, after, search, by, alpha, null, (validate, vsensor) if validate is not None else None)
        verdicts.append(verdict)
        if verdict.accepted:
            assert judged is not None
            kept.append(judged if proposed_here else st)
            # the next candidate is judged against the model as kept: ``after`` replayed each fold at the value searched
            # there, the kept step has one value (measured: on a clean current-loop trapezoid the kept lag's own value
            # gave a held-out error of 0.869 %, the per-fold values 0.892 %, a fall a next candidate would be credited with)
            current = replays.heldout(kept) if search and st is not proposed[-1] else after
    return judged_again(replays, proposed, kept, verdicts, alpha, null, (validate, vsensor) if validate is not None else None)


class HeldoutReplays:
    """The held-out replays of one recording: its ``k`` contiguous blocks (laid on each side of a change at ``change_s``,
    :func:`~ilic_cli.diagnosis.stats.folds_either_side`), each judged by a model fitted without it.

    ``sensor``: the sensor noise every judged replay carries (:func:`decision_sensor`; ``{}``: noise-free).
    """

    def __init__(
        self, log: RunLog, data: IDIMData, base: Model, rows: np.ndarray, plant_of: PlantOf, folds: int, sensor: dict[str, Any], change_s: float | None = None
    ) -> None:
        self.log, self.data, self.base, self.rows, self.plant_of, self.folds, self.sensor = log, data, base, rows, plant_of, folds, sensor
        t_rows = data.t_dec[rows]
        t = np.asarray(log.t)
        # each fold's held-out samples: one span of the log, or one each side of a change (``change_s``, folds_either_side)
        self.blocks = [
            [(int(np.searchsorted(t, t_rows[run[0]])), int(np.searchsorted(t, t_rows[run[-1]], side="right"))) for run in contiguous_runs(test)]
            for _, test in folds_either_side(t_rows, change_s, folds, 0)
        ]
        self.trains = [train for train, _ in folds_either_side(t_rows, change_s, folds, 10)]
        tau = np.asarray(log["tau"])
        self.q = np.asarray(log["q"])
        self.n = len(log)
        self.step_dec = max(data.settings.decimation, 1)
        # the force is compared in the band the inverse model sees (its parallel
        # decimation): a recorded closed-loop force carries the controller's answer
        # to position noise, which no noise-free replay reproduces and which would
        # otherwise hide any effect (measured: 22 % raw error on a clean PD log)
        at = kept_indices(self.n, self.step_dec)
        self.in_block = [np.any([(at >= a) & (at < b) for a, b in spans], axis=0) for spans in self.blocks]
        self.tau_dec = decimate_matlab(tau, self.step_dec)
        self.others_of = [np.any([sel for j, sel in enumerate(self.in_block) if j != fold], axis=0) for fold in range(len(self.in_block))]
        self.idx_tau = np.concatenate([np.flatnonzero(sel) for sel in self.in_block])
        self.idx_q = np.concatenate([np.arange(a, b) for spans in self.blocks for a, b in spans])
        self.moving_tau = reference_moving(np.asarray(log["q_ref"]), self.step_dec)[self.idx_tau]
        """Whether the reference moves at each held-out force sample (:func:`~ilic_cli.diagnosis.dwell.reference_moving`)."""
        self.min_delay_periods = MIN_DELAY_PERIODS
        """A judged delay shorter than this share of the sample period is not a finding (:func:`~ilic_cli.diagnosis.materiality.below_period`)."""
        self.fold_xatol_steps = FOLD_XATOL_STEPS
        """Tolerance of :func:`fold_value`'s search (grid steps)."""
        self.drift: GivenDrift | None = None
        """A friction drift found on the rigid model: in every fold's fit and plant (:func:`fitted_plant`)."""

    def fold_replay(self, steps: list[Step], train: np.ndarray, noise: dict[str, Any] | None = None) -> RunLog | None:
        """The replay of the model fitted on ``train`` (with the sensor ``noise``, default :attr:`sensor`), or ``None`` when it is no valid plant."""
        plant = fitted_plant(self.data, self.base, steps, self.rows, self.plant_of, train, self.drift)
        sim = _replayed_plant(self.log, plant, self.sensor if noise is None else noise)
        return sim if sim is not None and len(sim) == self.n else None

    def force_error(self, sim: RunLog) -> np.ndarray:
        """Simulated minus recorded force, decimated as the IDIM system is (all the log's decimated samples)."""
        return band_force_error(self.log, sim, self.step_dec)

    def percent(self, held: Heldout) -> tuple[float, float]:
        """The held-out simulated force and position errors of :meth:`heldout` as relative errors (%), on the folds it has."""
        return _heldout_pct(held[0], self.tau_dec, self.idx_tau), _heldout_pct(held[1], self.q, self.idx_q)

    @staticmethod
    def paired(current: Heldout, after: Heldout) -> tuple[Heldout, Heldout, float]:
        """``current`` and ``after`` on the folds both have (:meth:`heldout` leaves out, ``nan``, a fold whose fit is no plant of
        an effect), and the share of the held-out force samples left out."""
        force, position = np.isnan(current[0]) | np.isnan(after[0]), np.isnan(current[1]) | np.isnan(after[1])
        if not (force.any() or position.any()):
            return current, after, 0.0
        out = [(np.where(force, np.nan, h[0]), np.where(position, np.nan, h[1]), h[2]) for h in (current, after)]
        return out[0], out[1], float(force.mean())

    def compared(self, current: Heldout, after: Heldout, moving: bool = False) -> tuple[tuple[float, float], tuple[float, float], float, float]:
        """The held-out force and position errors (%) without and with (:meth:`percent`) on the folds both have
        (:meth:`paired`), the held-out test's p that ``after``'s are the smaller (:func:`heldout_fall_p`), and the share of
        the held-out force samples left out. ``moving``: compared where the reference moves only (:attr:`moving_tau`; the positions
        at full rate)."""
        current, after, left_out = self.paired(current, after)
        if moving:
            moving_q = reference_moving(np.asarray(self.log["q_ref"]), 1)[self.idx_q]
            current, after = ((np.where(self.moving_tau, h[0], np.nan), np.where(moving_q, h[1], np.nan), h[2]) for h in (current, after))
        (fb, pb), (fa, pa) = self.percent(current), self.percent(after)
        both = np.isfinite(current[0]) & np.isfinite(after[0])
        return (fb, fa), (pb, pa), heldout_fall_p(current[0][both], after[0][both]), left_out

    def in_motion(self, current: Heldout, after: Heldout, agrees: str) -> tuple[Verdict, str]:
        """The verdict on a friction at low speed found at the dwells whose replay agrees (sentence ``agrees``): kept where the
        held-out force error falls where the reference moves too, at :data:`~ilic_cli.diagnosis.dwell.IN_MOTION_ALPHA`."""
        cur, aft, _ = self.paired(current, after)
        moving = np.isfinite(cur[0]) & np.isfinite(aft[0]) & self.moving_tau
        p = heldout_fall_p(cur[0][moving], aft[0][moving]) if moving.sum() > 1 else 1.0
        if p <= IN_MOTION_ALPHA:
            return Verdict.AGREES, f"{agrees}; where the reference moves p = {p:.2g}"
        (rb, ra), (mb, ma) = [[_heldout_pct(e[sel], self.tau_dec, self.idx_tau[sel]) for e in (cur[0], aft[0])] for sel in (~self.moving_tau, self.moving_tau)]
        return Verdict.AT_REST_ONLY, (
            f"rejected by the replay: the held-out simulated force error falls where the reference rests ({rb:.3g} % -> {ra:.3g} %) and not "
            f"significantly where it moves ({mb:.3g} % -> {ma:.3g} %, p = {p:.2g}, against {IN_MOTION_ALPHA:g}): a friction at low speed acts "
            "as the axis leaves and nears rest, and a fall at the dwells alone is a model that stops the axis elsewhere"
        )

    def fold_search(self, train: np.ndarray, fold: int, noise: dict[str, Any]) -> tuple[Callable[[list[Step]], RunLog | None], Callable[[list[Step]], float]]:
        """A fold's replay of a model fitted on ``train`` with the sensor ``noise`` (each model once), and its training error."""
        sims: dict[Any, RunLog | None] = {}

        def replay_of(steps: list[Step]) -> RunLog | None:
            key = (len(steps), steps[-1].value, steps[-1].level) if steps else None
            if key not in sims:
                sims[key] = self.fold_replay(steps, train, noise)
            return sims[key]

        def training_error(steps: list[Step]) -> float:
            sim = replay_of(steps)
            if sim is None:
                return np.inf
            e = self.force_error(sim)[self.others_of[fold]]
            return float(e @ e)

        return replay_of, training_error

    def searched_fold(self, given: list[Step], grid: np.ndarray, train: np.ndarray, fold: int) -> tuple[list[Step], RunLog | None, FoldValue]:
        """``given`` with its last step's value searched on the fold's training blocks, its replay, and the search
        (:func:`~ilic_cli.diagnosis.search.fold_value`).

        The search replays noise-free: a value is estimated there, and the replay's own answer to its sensor noise,
        which the recording does not share, would pull it (a 1.0 ms drive lag: searched at 0.71-0.84 ms with the
        noise, 0.94-1.0 ms without). The replay returned, which the held-out block judges, has the noise.
        """
        replay_at, training_error = self.fold_search(train, fold, {})
        found = fold_value(given[:-1], given[-1], grid, training_error, self.fold_xatol_steps)
        steps = [*given[:-1], found.step]
        return steps, self.fold_replay(steps, train) if self.sensor else replay_at(steps), found

    def dwell_fold(self, given: list[Step], train: np.ndarray, fold: int) -> tuple[list[Step], RunLog | None, Step | None]:
        """``given`` with its last step, a closed-loop proposal, searched on the fold's training blocks (:func:`ilic_cli.diagnosis.dwell.search`).

        With the sensor noise, as the recording has it: the creep at the dwells is the noise's. Without an estimate
        the fold keeps the model without the step.
        """
        prefix, step = given[:-1], given[-1]
        replay_of, training_error = self.fold_search(train, fold, self.sensor)
        rigid = fit_system(self.data, self.base, prefix, self.rows, train)
        grid = step.effect.scan.grid(self.data.kin, self.data.fs_hz) if step.effect.scan is not None else np.array([])
        found = _strategy(step).scan(step, rigid, grid, lambda st: training_error(prefix if st is None else [*prefix, st]))
        steps = prefix if found is None else [*prefix, found]
        return steps, replay_of(steps), found

    def heldout(self, steps: list[Step], search: bool = False) -> Heldout | None:
        """Held-out simulated force (decimated) and position errors (blocks concatenated), or ``None`` when a fold is no valid plant.

        ``search``: the last step's nonlinear value is searched on each fold's training blocks first (:func:`~ilic_cli.diagnosis.search.fold_value`);
        the third item lists the values used, one per fold (each fold's :class:`~ilic_cli.diagnosis.search.FoldValue` when searched; ``None``: left out).
        """
        given = list(steps)
        level = search and given[-1].level is not None
        grid = given[-1].effect.scan.grid(self.data.kin, self.data.fs_hz) if search and not level and given[-1].effect.scan is not None else None

        def fold(i: int) -> tuple[np.ndarray, np.ndarray, Any] | None:
            spans, train, sel = self.blocks[i], self.trains[i], self.in_block[i]
            used: Any  # a closed-loop proposal's Step, a searched value's FoldValue, else the value (None: none)
            if level:
                fold_steps, sim, used = self.dwell_fold(given, train, i)
            elif grid is not None:
                fold_steps, sim, used = self.searched_fold(given, grid, train, i)
            else:
                fold_steps, sim = given, self.fold_replay(given, train)
                used = fold_steps[-1].value if fold_steps else None
            if sim is None:
                return None
            if not_a_plant(fold_steps, *fold_fit(self.data, self.base, fold_steps, self.rows, train, self.drift)[:2]):
                # the fold's fit is no plant of an effect: its replay would leave the effect out; the fold is left out (NaN)
                return np.full(int(sel.sum()), np.nan), np.full(sum(b - a for a, b in spans), np.nan), None
            return self.force_error(sim)[sel], np.concatenate([np.asarray(sim["q"][a:b]) - self.q[a:b] for a, b in spans]), used

        out = ordered_map(fold, range(len(self.blocks)))  # the folds are independent: side by side
        if any(r is None for r in out) or sum(np.isfinite(r[0]).any() for r in out if r is not None) < MIN_PLANT_FOLDS:
            return None
        done = [r for r in out if r is not None]
        return np.concatenate([r[0] for r in done]), np.concatenate([r[1] for r in done]), [r[2] for r in done]

    def judge(
        self,
        st: Step,
        kept: list[Step],
        current: Heldout,
        after: Heldout,
        search: bool,
        by: str,
        alpha: float,
        null: ReplayNull | None,
        validate: tuple[tuple[RunLog, LSSettings], dict[str, Any]] | None,
    ) -> tuple[ReplayVerdict, Step | None]:
        """The verdict on ``st`` added to ``kept`` from the held-out errors without it (``current``) and with it (``after``), and the step
        judged (the folds' value for a searched one); ``None`` when a closed-loop proposal found too few estimates."""
        proposed_here = st.level is not None
        (fb, fa), (pb, pa), p, left_out = self.compared(current, after)
        p_dm = p
        mc, significant = None, p < alpha
        judged, searched = st, ""
        fold_values: tuple[Any, ...] | None = None  # the value each fold used, for the verdict's record
        if proposed_here:
            judged_step, searched_text = _strategy(st).judged(after[2], self.data.joint)
            if judged_step is None:
                return ReplayVerdict(
                    st.effect.id,
                    fb,
                    fa,
                    pb,
                    pa,
                    None,
                    None,
                    None,
                    False,
                    f"rejected by the replay: {searched_text}",
                    proposed_by=by,
                    verdict=Verdict.NO_DWELL_ESTIMATE,
                ), None
        if null is not None and significant and fa < fb and not proposed_here:
            # both tests must agree: the Monte-Carlo null catches what is present all along (its replicates have it too),
            # the Diebold-Mariano test what the null's rough noise model makes of a small fall (null_calibration: the
            # Monte-Carlo p alone <= 0.05 on 23 of 104 spurious candidates, both on 5)
            mc = null.distribution(self.log, self.data, self.base, kept, st, self.rows, self.plant_of, self.folds, p)
            p = mc.p_value
            significant = p <= alpha * (1 + 1e-9)
        p_text = f"p = {p:.2g}" if mc is None else f"Monte-Carlo p = {p:.2g}, B = {len(mc.t_null)}; Diebold-Mariano p = {p_dm:.2g}"
        if proposed_here:
            assert judged_step is not None  # refused above when None
            judged = judged_step
            fold_values = tuple(_strategy(st).fold_values(after[2]))
            null_note = " (the Monte-Carlo null re-proposes through the inverse model, which cannot: Diebold-Mariano alone)" if null is not None else ""
            searched = "; " + searched_text + null_note
        elif search:
            scan = st.effect.scan
            assert scan is not None
            found: list[FoldValue] = [v for v in after[2] if v is not None]
            values = np.asarray([float(v.step.value) for v in found], dtype=np.float64)
            fold_values = tuple(float(v) for v in values)
            unit = st.effect.unit_on(scan.unit, self.data.joint)
            judged = Step(st.effect, float(np.median(values)))
            searched = (
                f"; {scan.name} searched on the closed loop of each fold's training blocks: "
                f"{_fmt(values.min(), unit)} to {_fmt(values.max(), unit)} (inverse model {_fmt(float(st.value), unit)})"
            )
            if edges := [v.edge for v in found if v.edge is not None]:
                searched += (
                    f"; in {len(edges)} of {len(after[2])} folds the search's optimum lay on the edge of the range searched "
                    f"({_fmt(min(edges), unit)} to {_fmt(max(edges), unit)}): no estimate there, the inverse model's value replayed"
                )
        vb = va = None
        if validate is not None:
            (vlog, vls), vsensor = validate
            sims = [_replayed(vlog, self.plant_of, s, fit_system(self.data, self.base, s, self.rows), vsensor) for s in (kept, [*kept, judged])]
            if sims[0] is not None and sims[1] is not None:
                vb, va = relative_errors(vlog, sims[0], vls)["force"], relative_errors(vlog, sims[1], vls)["force"]
        # the period rule on the value judged and on the value kept, which the findings report (an inverse-model proposal's own)
        fs, least = self.data.fs_hz, self.min_delay_periods
        short = below_period(judged, fs, least) or (None if proposed_here else below_period(st, fs, least))
        verdict, why = replay_verdict((fb, fa), (pb, pa), (vb, va), significant, p_text, short)
        if proposed_here and verdict is Verdict.AGREES:
            verdict, why = self.in_motion(current, after, why)
        ok = verdict is Verdict.AGREES
        if left_out:
            searched += f"; judged on the folds whose fit is a plant of every effect ({1.0 - left_out:.0%} of the held-out samples)"
        return ReplayVerdict(st.effect.id, fb, fa, pb, pa, p, vb, va, ok, why + searched, mc, fold_values, by, verdict), judged


def _strategy(step: Step) -> IdentificationStrategy:
    """The identification strategy of a closed-loop proposal (a step whose level is held: only a strategy proposes one)."""
    strategy = strategy_of(step.effect)
    assert strategy is not None, step.effect.id
    return strategy


def _heldout_pct(e: np.ndarray, ref: np.ndarray, idx: np.ndarray) -> float:
    """The held-out relative error (%) of the simulated errors ``e`` against the recorded ``ref`` at the held-out samples ``idx``
    (those of a fold left out, ``nan``, are not counted)."""
    ok = np.isfinite(e)
    return relative_error_pct(ref[idx][ok], ref[idx][ok] + e[ok])


def _fmt(value: float, unit: str) -> str:
    """A searched value for the report (a time in ms)."""
    return f"{value * 1e3:.3g} ms" if unit == "s" else f"{value:.4g} {unit}".strip()
