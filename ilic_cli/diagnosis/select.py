"""Forward selection of catalogue effects on the IDIM least-squares problem.

Starting from the rigid model, every effect of the catalogue not yet in the
model is fitted (nonlinear parameter: grid, then 1-D refinement; the rest by
least squares on the decimated IDIM system, whose solver is unchanged) and
tested against the current model with a prewhitened nested F-test,
Bonferroni-corrected for the number of candidates and of grid points. The
most significant candidate is accepted only when it also lowers the error on
held-out data (blocked cross-validation over time, and the validation log
when one is given); the search stops when no candidate passes both.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.evaluation import Candidate, Evaluation
from ilic_cli.diagnosis.rivals import beside_an_edge, parsimonious_first
from ilic_cli.diagnosis.search import (
    DEFAULT_STEPS,
    EDGE_STEPS,
    EXACT_GRID_MAX,
    SEARCH_STEPS,
    SECONDARY_EDGE,
    LogRate,
    Searcher,
    at_edge,
    minimise,
    search_range,
    searched_at_log_rate,
)
from ilic_cli.diagnosis.stats import blocked_folds, folds_either_side, heldout_errors, heldout_fall_p, nested_f_test
from ilic_cli.diagnosis.system import Step, SystemFit, change_time, effect_columns, extended, fit_system, moving_rows, shifted_force, system
from ilic_cli.diagnosis.verdicts import Selection
from ilic_cli.effects import EFFECTS, Effect, applicable, catalogue_ids
from ilic_cli.idim_ls import IDIMData
from ilic_cli.lsq import lstsq, relative_error_pct
from ilic_cli.regressor import Model

__all__ = [  # the selection's own names, and the system's and the search's, importable from here as before the split
    "DEFAULT_STEPS",
    "EDGE_STEPS",
    "EXACT_GRID_MAX",
    "HELDOUT_UNCONFIRMED",
    "Selection",
    "SEARCH_STEPS",
    "SECONDARY_EDGE",
    "Evaluation",
    "Searcher",
    "SelectSettings",
    "SelectionResult",
    "Step",
    "SystemFit",
    "at_edge",
    "effect_columns",
    "extended",
    "fit_system",
    "forward_select",
    "minimise",
    "moving_rows",
    "search_range",
    "shifted_force",
    "system",
    "validation_error",
]


@dataclass(frozen=True)
class SelectSettings:
    """Settings of the forward selection.

    Attributes
    ----------
    alpha : float
        Family-wise level of each step's F-test (after Bonferroni).
    alpha_heldout : float
        Level of the one-sided Diebold-Mariano test that the held-out
        errors drop: a proposal's confirmation, at the usual 0.05 (the
        closed-loop replay decides, at :data:`ilic_cli.diagnosis.null.REPLAY_ALPHA`).
    alpha_confirm : float
        Held-out level below which the inverse model's estimate of an effect the closed loop can also estimate (Stribeck
        friction, :mod:`ilic_cli.diagnosis.strategies`) is its own; confirmed only at a larger p, the closed loop estimates it
        (the EMPS reference with a flexibility beside it, seed 1303: held-out p = 0.027, the inverse model's Stribeck peak 130 %
        off, the closed loop's within 10 %). Which estimator values an effect, not whether it is one: the replay decides that.
    folds : int
        Contiguous cross-validation blocks over time.
    guard : int
        Decimated rows left out of training on each side of a test block.
    max_effects : int
        At most this many effects are added.
    effects : tuple of str
        Catalogue ids that may be added.
    """

    alpha: float = 0.001
    alpha_heldout: float = 0.05
    alpha_confirm: float = 0.01
    folds: int = 5
    guard: int = 10
    max_effects: int = 4
    effects: tuple[str, ...] = field(default_factory=catalogue_ids)

    def to_dict(self) -> dict[str, Any]:
        return {
            "alpha": self.alpha,
            "alpha_heldout": self.alpha_heldout,
            "alpha_confirm": self.alpha_confirm,
            "folds": self.folds,
            "guard_rows": self.guard,
            "max_effects": self.max_effects,
            "effects": list(self.effects),
        }


HELDOUT_UNCONFIRMED = Selection.HELDOUT_UNCONFIRMED.value
"""The reason of a candidate whose F-test passed but whose held-out test did not confirm it (:attr:`Selection.HELDOUT_UNCONFIRMED`)."""


@dataclass
class SelectionResult:
    """Accepted steps in order, and every evaluation made on the way."""

    rows: np.ndarray | None = None
    steps: list[Step] = field(default_factory=list)
    accepted: list[Evaluation] = field(default_factory=list)
    tried: list[list[Evaluation]] = field(default_factory=list)

    def last_at(self, effect_id: str) -> tuple[int, int] | None:
        """Where in ``tried`` the last evaluation of ``effect_id`` is (round, position); ``None`` when it was never tried."""
        return next(((k, i) for k in reversed(range(len(self.tried))) for i, ev in enumerate(self.tried[k]) if ev.effect == effect_id), None)

    def last_word(self, effect_id: str) -> Evaluation | None:
        """The last evaluation of ``effect_id`` (``None`` when it was never tried)."""
        at = self.last_at(effect_id)
        return None if at is None else self.tried[at[0]][at[1]]

    def unconfirmed(self, effect_id: str, level: float | None = None) -> bool:
        """Whether the last evaluation of ``effect_id`` passed its F-test but its held-out test did not confirm it (at ``level``:
        :meth:`Evaluation.unconfirmed_at`)."""
        ev = self.last_word(effect_id)
        return ev is not None and ev.unconfirmed_at(level)


def forward_select(
    data: IDIMData,
    base: Model,
    fs_hz: float,
    settings: SelectSettings = SelectSettings(),
    *,
    validation: IDIMData | None = None,
    known: list[Step] | None = None,
    given: np.ndarray | None = None,
) -> SelectionResult:
    """Add catalogue effects to ``base`` one at a time while they are significant and predict better.

    Each round ranks the candidates by the prewhitened test's BIC change (``FTest.delta_bic``), not the raw error (corpus
    s9710: gravity's 1.93 %, F = 47, ran ahead of a payload's step, 2.12 %, F = 371, and the spring was named gravity).

    Parameters
    ----------
    data : IDIMData
        The fitting log, prepared with ``base`` (:func:`ilic_cli.idim_ls.lsq_rows`).
    base : Model
        The starting regressor.
    fs_hz : float
        Sampling frequency of the log.
    settings : SelectSettings
        Level, folds, candidates.
    validation : IDIMData, optional
        Another log prepared with ``base``: a candidate must not raise the
        error of the fitted model there.
    known : list of Step, optional
        Effects already in the model (from a model file): kept, not tried.
    given : ndarray, optional
        Columns on the selection's rows already in the model that are no catalogue effect's (a friction drift's trend
        columns, :func:`ilic_cli.diagnosis.propose.drift_given`): every candidate is fitted and tested, and held out,
        with them. A drift left out of the model moves the residual over time, so the blocked folds over time see
        it in every candidate's held-out error (corpus s731, s732: gravity's F-test passed, its held-out test did not).
    """
    rows = moving_rows(data)
    searcher = Searcher(data, fs_hz, rows)
    out = SelectionResult(rows=rows)
    known = list(known or [])
    W, y, names = system(data, base, known, rows)
    if given is not None and given.shape[1]:
        W = np.c_[W, given]
    folds = blocked_folds(len(y), settings.folds, settings.guard)
    while len(out.steps) < settings.max_effects:
        in_model = {s.effect.id for s in [*known, *out.steps]}
        cands = [EFFECTS[i] for i in settings.effects if i in EFFECTS and EFFECTS[i].identifiable and i not in in_model and applicable(EFFECTS[i], names)]
        if not cands:
            break
        # an effect searched at the log's rate is searched on the model so far there (the given columns too)
        factors = {searcher.rate_factor(e) for e in cands if searcher.at_log_rate(e)}
        assert len(factors) <= 1, factors  # one effect searched there (a resonance)
        at = searcher.log_rate(base, [*known, *out.steps], given, factors.pop()) if factors else None
        # the candidate the prewhitened evidence favours most first (the docstring); significance and held-out error gate it
        evals = sorted((_candidate(searcher, eff, W, y, len(cands), at) for eff in cands), key=lambda e: e[0].test.delta_bic)
        evals = parsimonious_first(evals, W, y, settings.alpha)
        tried: list[Evaluation] = []
        chosen = None
        for ev, eff, W1, y1 in evals:
            if ev.outcome.never_a_finding:  # impossible physics, or an estimate on the edge of its search range: never a finding
                tried.append(ev)
            elif chosen is not None or ev.test.p_adjusted >= settings.alpha:
                tried.append(ev.decided(Selection.NOT_SIGNIFICANT if ev.test.p_adjusted >= settings.alpha else Selection.ANOTHER_FIRST))
            elif (stronger := _beside_stronger(searcher, ev, eff, evals, len(cands), settings.alpha)) is not None:
                tried.append(ev.decided(Selection.BESIDE_STRONGER, stronger))
            else:
                prior = [*known, *out.steps]
                judged_on = _folds_for(searcher, eff, ev.value, folds, settings, prior)
                ev = _heldout_judged(
                    ev, searcher, eff, W, y, judged_on, settings.alpha_heldout, (data, validation, base, prior) if validation is not None else None, at
                )
                tried.append(ev)
                if ev.accepted:
                    chosen = (ev, eff, W1, y1)
        if chosen is not None and (rival := beside_an_edge(chosen[0], tried, settings.alpha)) is not None:
            chosen = (replace(chosen[0], indistinct_from=rival.effect, beside_edge=rival), *chosen[1:])
            tried = [chosen[0] if ev.effect == chosen[0].effect else ev for ev in tried]
        out.tried.append(tried)
        if chosen is None:
            break
        ev, eff, W, y = chosen
        out.steps.append(Step(eff, ev.value))
        out.accepted.append(ev)
        names = names + eff.column_names
    return out


def _beside_stronger(searcher: Searcher, ev: Evaluation, eff: Effect, evals: list[Candidate], n_candidates: int, alpha: float) -> str | None:
    """Why ``eff``, significant, is not significant in the model with a candidate of the same step whose F-test is stronger (a smaller
    p after its multiplicity), else ``None``.

    The candidates are tried in the order of the error they leave, but each is tested alone on the model so far. A weaker one may
    owe its F-test to the force of a stronger one that its held-out test or the replay then judges (corpus, Stribeck friction six
    times the Coulomb level on the 0.5 kg·m² joint's trapezoid, s3461: Stribeck friction p = 3.9e-13, unconfirmed held out on the
    inverse model's biased vs; a drive lag p = 0.00027, accepted in its place and kept by the replay; in the model with the
    Stribeck friction the lag's p is 0.44). Each stronger one's system gets the candidate fitted and tested again on top of it;
    not significant there, it is no proposal. Candidates searched at the log's rate (a resonance) are not tested again: their
    search runs on the model so far at that rate; nor two linear effects against each other, which the J-test of
    :func:`~ilic_cli.diagnosis.rivals.parsimonious_first` orders and may state as indistinct (corpus s12711: a spring the data cannot tell from gravity,
    not significant beside gravity's two columns, would have been named gravity).
    """
    if searcher.at_log_rate(eff):
        return None
    for rev, reff, W_r, y_r in evals:
        if rev.effect == ev.effect or rev.outcome.never_a_finding or not rev.test.p_adjusted < min(ev.test.p_adjusted, alpha):
            continue
        if not (eff.nonlinear or eff.shift or reff.nonlinear or reff.shift):
            continue  # two linear effects: :func:`~ilic_cli.diagnosis.rivals.parsimonious_first` decides between them (a spring, or gravity, or either)
        beside = _candidate(searcher, eff, W_r, y_r, n_candidates)[0]
        if beside.test.p_adjusted >= alpha:
            return f"p = {beside.test.p_adjusted:.2g} in the model with {rev.effect} (p = {rev.test.p_adjusted:.2g} alone)"
    return None


def _candidate(searcher: Searcher, eff: Effect, W: np.ndarray, y: np.ndarray, n_candidates: int, at: LogRate | None = None) -> Candidate:
    """``eff`` fitted on top of ``(W, y)``: its nonlinear value searched (at the log's rate on ``at``, the same model there, for an
    effect searched there), its F-test (Bonferroni over the candidates and the grid points), and, before any test, whether its
    estimate is outside its physics or on the edge of its search range."""
    value, vstd = None, None
    if eff.nonlinear:
        value = searcher.scan(eff, W, y, at=at)
        value, vstd = searcher.refine(eff, W, y, value, at=at)
    # Bonferroni over the candidates and, for a searched parameter, its grid points (a shift's too)
    trials = n_candidates * (len(searcher.grid_values(eff)) if eff.nonlinear else 1)
    if eff.shift:
        W1, y1, q = W, searcher.exact(eff, value), 1
    else:
        W1 = np.hstack([W, searcher.exact(eff, value) if eff.nonlinear else searcher.exact_linear(eff)])
        # a secondary nonlinear parameter is one more degree of freedom
        y1, q = y, len(eff.columns) + (1 if eff.scan is not None and eff.scan.secondary else 0)
    test = nested_f_test(W, y, W1, y1, q, trials)
    theta1, _ = lstsq(W1, y1)
    ev = Evaluation(eff.id, value, vstd, test, relative_error_pct(y1, W1 @ theta1))
    why = eff.impossible(theta1[W.shape[1] :], value, searcher.data.joint) if eff.impossible is not None else None
    if why:
        ev = ev.decided(Selection.IMPOSSIBLE, why)
    elif eff.nonlinear and (edge := at_edge(eff, searcher.grid_values(eff), value, searcher.data.joint)):
        ev = ev.decided(Selection.AT_SEARCH_EDGE, edge)
    return ev, eff, W1, y1


def still_proposed(
    data: IDIMData,
    base: Model,
    rows: np.ndarray,
    model: list[Step],
    st: Step,
    n_candidates: int,
    given: np.ndarray | None = None,
) -> Evaluation | None:
    """``st`` tried by the inverse model again on the model of ``model``'s effects (a closed-loop proposal's level held: its force taken
    off, a shifted force's too), as at a step of the selection (its nonlinear value searched there, :func:`_candidate`); ``None``
    for an effect searched at the log's rate (its search runs on that rate's system, not built here).

    The selection proposes on the model of the effects accepted before; an effect the closed loop proposes later (Stribeck friction
    valued at the dwells) was not in it (:func:`ilic_cli.diagnosis.decide.decide` asks again once the replay has kept one).
    ``given``: the selection's given columns on ``rows`` (a friction drift's trends)."""
    if searched_at_log_rate(st.effect, data):
        return None
    levels = [effect_columns(data, s.effect, s.value)[rows] @ np.asarray(s.level, dtype=np.float64) for s in model if s.level is not None]
    searcher = Searcher(data, data.fs_hz, rows, held=np.sum(levels, axis=0) if levels else None)
    W, y, _ = system(data, base, model, rows)
    if given is not None and given.shape[1]:
        W = np.c_[W, given]
    return _candidate(searcher, st.effect, W, y, n_candidates)[0]


def _folds_for(
    searcher: Searcher, eff: Effect, value: Any, folds: list[tuple[np.ndarray, np.ndarray]], settings: SelectSettings, prior: list[Step]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The held-out folds that judge ``eff`` at ``value`` on the model of ``prior``: ``folds``, or, when the model with it holds a time
    of the log (a payload's change, the candidate's or one accepted before), the same blocks laid on each side of it
    (:func:`folds_either_side`). Blocked over the whole log, a fold whose training blocks hold a few rows after an accepted change
    fits the change's size to their noise (corpus s710, a spring after a change at 6.5 s: held-out error 191 % -> 188 %)."""
    change = change_time([*prior, Step(eff, value)])
    return folds if change is None else folds_either_side(searcher.data.t_dec[searcher.keep], change, settings.folds, settings.guard)


def _heldout_judged(
    ev: Evaluation,
    searcher: Searcher,
    eff: Effect,
    W: np.ndarray,
    y: np.ndarray,
    folds: list[tuple[np.ndarray, np.ndarray]],
    alpha_heldout: float,
    validation: tuple[IDIMData, IDIMData, Model, list[Step]] | None,
    at: LogRate | None = None,
) -> Evaluation:
    """``ev``, whose F-test passed, judged on the held-out blocks (one-sided Diebold-Mariano at ``alpha_heldout``) and on the validation log
    (``(data, validation, base, steps so far)``): accepted, or why not."""
    e_before = heldout_errors(W, y, folds)
    e_after = _heldout_candidate(searcher, eff, W, y, folds, ev.value, at)
    before, after = relative_error_pct(y, y - e_before), relative_error_pct(y, y - e_after)
    p_cv = heldout_fall_p(e_before, e_after)
    vb = va = None
    if validation is not None:
        data, vdata, base, prior = validation
        vb = validation_error(data, vdata, base, prior)
        va = validation_error(data, vdata, base, [*prior, Step(eff, ev.value)])
    if not after < before or p_cv >= alpha_heldout:
        outcome = Selection.HELDOUT_UNCONFIRMED
    elif va is not None and vb is not None and va > vb:
        outcome = Selection.RAISES_VALIDATION
    else:
        outcome = Selection.ACCEPTED
    return ev.decided(outcome, heldout_before_pct=before, heldout_after_pct=after, heldout_p_value=p_cv, validation_before_pct=vb, validation_after_pct=va)


def _heldout_candidate(
    searcher: Searcher,
    eff: Effect,
    W: np.ndarray,
    y: np.ndarray,
    folds: list[tuple[np.ndarray, np.ndarray]],
    value: Any = None,
    at: LogRate | None = None,
) -> np.ndarray:
    """Held-out errors of the model with ``eff``, its nonlinear parameter searched on each training set (``value``, the whole
    log's, for a time of the log: :attr:`ilic_cli.effects.Scan.of_the_whole_log`). A fold whose held-out block holds a
    payload's change cannot place it from its training blocks: every time in the gap fits them alike (corpus s402, the change
    at 4.0 s: the fold's search took 6.53 s, by 1 % of its training RSS; that block's held-out error doubled and hid the
    other four's fall from 2.6 % to 0.8 %, p = 0.50)."""
    out = np.full(len(y), np.nan)
    for train, test in folds:
        if eff.scan is not None and eff.scan.of_the_whole_log and value is not None:
            x = searcher.exact(eff, value)
        elif eff.nonlinear:
            v = searcher.scan(eff, W, y, rows=train, at=at)
            v, _ = searcher.refine(eff, W, y, v, rows=train, at=at)
            x = searcher.exact(eff, v)
        else:
            x = searcher.exact_linear(eff)
        if eff.shift:
            W1, y1 = W, x
        else:
            W1, y1 = np.hstack([W, x]), y
        theta, _ = lstsq(W1[train], y1[train])
        out[test] = y1[test] - W1[test] @ theta
    return out


def validation_error(data: IDIMData, validation: IDIMData, base: Model, steps: list[Step] | tuple[Step, ...]) -> float:
    """Relative error (%) on ``validation`` of the model ``base + steps`` fitted on ``data``."""
    theta = fit_system(data, base, steps).theta
    Wv, yv, _ = system(validation, base, steps)
    return relative_error_pct(yv, Wv @ theta)
