"""Rival effects: two the data cannot tell apart, and an effect accepted beside a better fit at its search's edge.

The selection (:func:`ilic_cli.diagnosis.select.forward_select`) names one effect a step; where another explains the same
force, the finding says so (:attr:`ilic_cli.diagnosis.evaluation.Evaluation.indistinct_from`) rather than a bare name the data do
not decide: gravity or a spring over a short swing (:func:`parsimonious_first`, by the J-test :func:`rival_test`), or an effect
accepted in place of a candidate whose estimate is on the edge of its search range (:func:`beside_an_edge`). The finding's
words: :func:`indistinct_note`, :func:`finding_title`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ilic_cli.diagnosis.evaluation import Candidate, Evaluation
from ilic_cli.diagnosis.stats import FTest, nested_f_test
from ilic_cli.diagnosis.verdicts import Selection
from ilic_cli.effects import EFFECTS, Effect
from ilic_cli.lsq import lstsq


def parsimonious_first(evals: list[Candidate], W: np.ndarray, y: np.ndarray, alpha: float) -> list[Candidate]:
    """Of two linear candidates of different column counts, put the simpler first unless the larger one's force adds to it.

    Two linear effects can span nearly the same force over the range a log covers: gravity on a
    revolute joint, ``g (MX cos q - MY sin q)``, is a straight line in ``q`` plus a curvature a spring
    (``k q``) lacks, which over a swing of a radian or so is a few per cent of the force. The two-column
    effect then always fits at least as well. Each is tested against the other by the non-nested J-test
    (Davidson and MacKinnon): the rival's fitted force, one column, added to the model with the effect
    (:func:`rival_test`). A gravity makes its curvature and its slope from the same two moments, so its
    fitted force points where a true gravity's curvature is; the two columns apart would spend a degree
    of freedom on any curvature, gravity's or not (corpus s480, a spring at 500 Hz: gravity's two columns
    beyond the spring p = 0.0007, a wrong name; its fitted force p = 0.35, and the spring's beyond gravity
    p = 0.0002). When the larger effect's force adds nothing significant (at ``alpha``) to the model with
    the simpler one, the simpler one is proposed first (parsimony); where the swing shows the curvature
    the larger one stays first. When, besides, the simpler one's adds nothing to the model with the larger
    one, neither explains anything the other does not: the simpler one is proposed with the larger one as
    :attr:`Evaluation.indistinct_from`, a stated ambiguity rather than a name the data do not decide. A larger one
    that fits no better than the simpler stands for nothing. Whichever the ranking puts first, the decision is the same.
    """
    ok = [i for i, (ev, eff, _, _) in enumerate(evals) if not ev.outcome.never_a_finding and ev.test.p_adjusted < alpha]
    if not ok:
        return evals
    top_ev, top, W_top, y_top = evals[t := ok[0]]
    if top.nonlinear or top.shift:
        return evals
    k = W.shape[1]
    for i in ok[1:]:
        ev, eff, W_e, y_e = evals[i]
        if eff.nonlinear or eff.shift or len(eff.columns) == len(top.columns):
            continue
        if len(eff.columns) < len(top.columns):  # a simpler one behind the top: first when the top's force adds nothing beyond it
            if rival_test(W_e, W_top, k, y).p_value >= alpha:
                indistinct = rival_test(W_top, W_e, k, y).p_value >= alpha
                return [(replace(ev, indistinct_from=top_ev.effect) if indistinct else ev, eff, W_e, y_e), *evals[:i], *evals[i + 1 :]]
            continue
        # a larger one behind the top: no better fit, nothing; else the two tests as above, the other way round
        if ev.relative_error_pct >= top_ev.relative_error_pct:
            return evals
        if rival_test(W_top, W_e, k, y).p_value < alpha:
            return [evals[i], *evals[:i], *evals[i + 1 :]]
        if rival_test(W_e, W_top, k, y).p_value >= alpha:
            return [*evals[:t], (replace(top_ev, indistinct_from=ev.effect), top, W_top, y_top), *evals[t + 1 :]]
        return evals
    return evals


def rival_test(W_own: np.ndarray, W_rival: np.ndarray, k: int, y: np.ndarray) -> FTest:
    """The J-test (Davidson and MacKinnon 1981) of a rival effect against the model with one's own: the rival's fitted force,
    ``W_rival[:, k:] @ theta[k:]`` of the least-squares fit of ``y`` on ``W_rival`` (its first ``k`` columns the model both
    share), added to ``W_own`` as one column, by the prewhitened nested F-test on one degree of freedom."""
    theta, _ = lstsq(W_rival, y)
    force = W_rival[:, k:] @ theta[k:]
    return nested_f_test(W_own, y, np.c_[W_own, force], y, 1)


def beside_an_edge(chosen: Evaluation, tried: list[Evaluation], alpha: float) -> Evaluation | None:
    """The significant candidate of the same step whose estimate is on the edge of its search range and which leaves less error
    than ``chosen`` (the least such), else ``None``.

    An edge estimate is never a finding: the truth may lie beyond the range searched. But the force it fits is in the log, and
    the effect accepted in its place may owe its significance to part of that force (the independent simulator's 0.5 kg·m²
    joint, a chirp over 0.232 rad at 1 kHz with a ripple of period 0.24 rad, seed 41: the ripple at the grid's end, the stroke,
    left 1.09 % of the force; gravity, accepted and kept by the replay, 4.11 %, with MX = 4.4 kg·m that an offset of -44 N·m
    cancels). The finding is then stated as indistinct from it: the log cannot decide a value it does not visit.
    """
    edge = [ev for ev in tried if ev.outcome is Selection.AT_SEARCH_EDGE and ev.test.p_adjusted < alpha and ev.relative_error_pct < chosen.relative_error_pct]
    return min(edge, key=lambda ev: ev.relative_error_pct) if edge and chosen.indistinct_from is None else None


def indistinct_note(effect: Effect, ev: Evaluation) -> str:
    """The stated ambiguity of a finding the data cannot tell from another effect (:attr:`Evaluation.indistinct_from`), or ``""``."""
    if ev.indistinct_from is None:
        return ""
    if (edge := ev.beside_edge) is not None:
        return (
            f"{effect.id} or {edge.effect}: {edge.effect}'s fit, {edge.reason}, leaves {edge.relative_error_pct:.3g} % of the force "
            f"where {effect.id} leaves {ev.relative_error_pct:.3g} %; its value lies beyond the range searched, which the log does not "
            f"decide, and {effect.id} may stand for part of its force"
        )
    return (
        f"{effect.id} or {ev.indistinct_from}: the data cannot tell them apart over the range the log visits (neither's fitted force "
        f"adds significantly to the model with the other's); a log over a wider range decides"
    )


def finding_title(effect: Effect, ev: Evaluation) -> str:
    """A finding's catalogue title, and the effect it is stated as indistinct from (``gravity or position-dependent force ripple``)."""
    other = ev.indistinct_from
    return effect.title if other is None else f"{effect.title} or {EFFECTS[other].title if other in EFFECTS else other}"
