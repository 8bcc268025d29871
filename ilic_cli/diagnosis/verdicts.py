"""The typed decisions of the diagnosis: what each stage decided about a candidate, as an enum, and the sentence derived from it.

The stages (propose: :mod:`ilic_cli.diagnosis.select` and :mod:`ilic_cli.diagnosis.dwell`; decide:
:mod:`ilic_cli.diagnosis.decide`; refit: :mod:`ilic_cli.diagnosis.refit`; report: :mod:`ilic_cli.diagnosis.report`)
pass these values to each other and read the outcome, never the sentence: the sentence (``reason``) is what the
report and the JSON say, the outcome is what the code decides on.

The lowest module of the package: it imports none of the stages, so that the replay's test
(:mod:`ilic_cli.diagnosis.decide`) and the Monte-Carlo null (:mod:`ilic_cli.diagnosis.null`) share it without a cycle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any, Protocol

import numpy as np

from ilic_cli.diagnosis.stats import HELDOUT_FALL_TEST


class Selection(Enum):
    """The inverse model's decision on one candidate at one step of the forward selection (:mod:`ilic_cli.diagnosis.select`)."""

    PENDING = ""
    """Not decided yet (a candidate just fitted)."""
    IMPOSSIBLE = "physically impossible"
    """Its estimate is outside the effect's physics (:attr:`ilic_cli.effects.Effect.impossible`, e.g. a flexibility's negative mass)."""
    AT_SEARCH_EDGE = "at the edge of its search range"
    """Its nonlinear estimate is on the edge of its search (:func:`ilic_cli.diagnosis.select.at_edge`)."""
    NOT_SIGNIFICANT = "not significant"
    """Its F-test does not pass."""
    ANOTHER_FIRST = "another effect was accepted first"
    """Another candidate of the same step was accepted before it."""
    BESIDE_STRONGER = "not significant beside a stronger candidate"
    """Its F-test passed, but not in the model with a candidate of the same step whose F-test is stronger: what it explains is that
    one's force (:func:`ilic_cli.diagnosis.select.forward_select`)."""
    HELDOUT_UNCONFIRMED = "does not lower the held-out error significantly"
    """Its F-test passed, its held-out test did not confirm it."""
    RAISES_VALIDATION = "raises the error on the validation log"
    """It raises the error of the fitted model on the validation log."""
    ACCEPTED = "significant, and lowers the held-out error"
    """Proposed to the replay."""

    def sentence(self, detail: str | None = None) -> str:
        """The reason the report gives: the outcome's words, with ``detail`` after a colon when it has one."""
        return f"{self.value}: {detail}" if detail else self.value

    @property
    def never_a_finding(self) -> bool:
        """Impossible physics, or an estimate on the edge of its search range: decided before the F-test."""
        return self in (Selection.IMPOSSIBLE, Selection.AT_SEARCH_EDGE)


class Verdict(Enum):
    """The decision on one proposed effect by materiality and the replay (:mod:`ilic_cli.diagnosis.decide`)."""

    NOT_MATERIAL = "not material"
    """Its force is below the materiality threshold wherever the replay may put it."""
    BELOW_PERIOD = "below the sample period"
    """A delay too short for the rows to tell it from the sample timing."""
    NO_PLANT = "no valid plant"
    """The fitted model is no valid plant: no replay."""
    NO_DWELL_ESTIMATE = "too few folds"
    """A closed-loop proposal whose search finds an estimate in too few folds."""
    NO_FALL = "no fall"
    """The held-out simulated force error does not fall."""
    NOT_SIGNIFICANT = "not significant"
    """It falls, not significantly."""
    POSITION_RISES = "position rises"
    """The held-out simulated position error rises."""
    VALIDATION_RISES = "validation rises"
    """The validation log's simulated force error rises."""
    AT_REST_ONLY = "at rest only"
    """A friction at low speed found at the dwells whose held-out fall is at rest only, not where the reference moves."""
    AGREES = "the replay agrees"
    """Kept: a finding."""
    REFUTED = "refuted"
    """Kept by the replay, then refuted by the open-loop segments' fit (:mod:`ilic_cli.diagnosis.segments`)."""
    NOT_PROPOSED_AGAIN = "no longer proposed"
    """Kept by the replay, then no longer proposed by the inverse model on the model with a closed-loop proposal kept after it
    (:func:`ilic_cli.diagnosis.decide.proposed_again`)."""


class RefitOutcome(Enum):
    """What the refit stage did with the effects the replay kept (:mod:`ilic_cli.diagnosis.refit`)."""

    NO_PLANT = "no plant"
    """The inverse model's estimate is no plant: no refit."""
    FAILED = "failed"
    """DIDIM failed at the inverse model's values."""
    DIDIM = "DIDIM"
    """Refitted by DIDIM, its values searched on the closed loop."""
    NOT_LOWERED = "not lowered"
    """DIDIM does not lower the closed-loop output error, and nothing else kept: the inverse model's estimates stand."""
    OUTPUT_ERROR = "output error"
    """Refitted by the output-error Levenberg-Marquardt (:data:`ilic_cli.diagnosis.refit.OE_METHOD`)."""
    VALUE_SEARCH = "value search"
    """The values searched on the closed loop, the linear parameters the inverse model's (:data:`ilic_cli.diagnosis.refit.INVERSE_METHOD`)."""
    AT_DWELLS = "at dwells"
    """Stribeck friction found at the dwells keeps its closed-loop search's estimate (the open-loop segments' fit not used)."""
    SEGMENTS = "segments"
    """Stribeck friction found at the dwells, estimated on the open-loop segments (:mod:`ilic_cli.diagnosis.segments`)."""
    SEGMENTS_REFUTED = "segments refuted"
    """The open-loop segments' fit refutes the Stribeck friction found at the dwells."""
    DRIFT = "drift"
    """A friction drift given to the decisions is found on the final model too: the refit's plant has none; the inverse model's estimates stand."""
    DRIFT_VALUES = "drift, the replays' values"
    """As :attr:`DRIFT`, but a value the inverse model biases is the median of the decisions' replays' (which carry the drift), the
    linear parameters the inverse model's there (:func:`ilic_cli.diagnosis.refit.at_the_replays_values`)."""

    @property
    def quotes_output_error(self) -> bool:
        """Whether the refit compared closed-loop output errors (DIDIM ran), so that its reason quotes them."""
        return self in (RefitOutcome.DIDIM, RefitOutcome.NOT_LOWERED, RefitOutcome.OUTPUT_ERROR, RefitOutcome.VALUE_SEARCH)


DM_TEST = f"{HELDOUT_FALL_TEST}, held-out replay force errors"

MC_TEST = "Monte-Carlo null: the kept model simulated in closed loop with the log's noise model, the candidate proposed again on each replicate"

PROPOSED_BY_INVERSE = "inverse model"
"""``ReplayVerdict.proposed_by`` of a candidate the inverse model proposed (:mod:`ilic_cli.diagnosis.select`)."""

PROPOSED_BY_DRIFT = "drift test on every row"
"""``ReplayVerdict.proposed_by`` of a friction drift (:mod:`ilic_cli.diagnosis.drift`: found on the rows after the other effects)."""

PlantOf = Callable[[list[Any], tuple[str, ...], np.ndarray], tuple[dict[str, float], dict[str, Any]]]
"""``(steps, names, theta) -> (rigid parameters, plant effects)``."""


class NullEvidence(Protocol):
    """What a verdict keeps of the Monte-Carlo null that judged it (:class:`ilic_cli.diagnosis.null.NullDistribution`)."""

    t_obs: float
    t_null: np.ndarray
    p_value: float
    dm_p_value: float

    @property
    def noise(self) -> Any: ...

    def to_dict(self) -> dict[str, Any]: ...


class ReplayNull(Protocol):
    """A test the replay calls to judge a candidate beside Diebold-Mariano (:class:`ilic_cli.diagnosis.null.MonteCarloNull`)."""

    def distribution(
        self, log: Any, data: Any, base: Any, kept: list[Any], step: Any, rows: np.ndarray, plant_of: PlantOf, folds: int, p_obs: float
    ) -> NullEvidence: ...


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
    null: NullEvidence | None = None
    searched: tuple[Any, ...] | None = None
    """The value used in each fold when it was searched on the fold's training blocks (:func:`ilic_cli.diagnosis.search.fold_value`);
    a closed-loop proposal's ``(vs, Fs)`` per fold, ``None`` where a fold found none (:mod:`ilic_cli.diagnosis.dwell`)."""
    proposed_by: str = PROPOSED_BY_INVERSE
    """Who proposed the effect: the inverse model, or the closed loop (:data:`ilic_cli.diagnosis.dwell.METHOD`)."""
    verdict: Verdict = Verdict.NO_PLANT
    """The decision, typed (``accepted`` is ``verdict is Verdict.AGREES``; ``reason`` says it in words)."""

    @classmethod
    def unjudged(cls, effect: str, verdict: Verdict, reason: str, proposed_by: str = PROPOSED_BY_INVERSE) -> ReplayVerdict:
        """A rejection before any replay's figures (not material, too short, no plant)."""
        return cls(effect, None, None, None, None, None, None, None, False, reason, proposed_by=proposed_by, verdict=verdict)

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
            return {
                "test": f"{MC_TEST}; and {DM_TEST}",
                "p_value": self.p_value,
                "diebold_mariano_p_value": self.null.dm_p_value,
                "replicates": len(self.null.t_null),
                "null_distribution": self.null.to_dict(),
            }
        return None if self.p_value is None else {"test": DM_TEST, "p_value": self.p_value}


def replay_verdict(
    force: tuple[float, float],
    position: tuple[float, float],
    validation: tuple[float | None, float | None],
    significant: bool,
    p_text: str,
    short: str | None,
) -> tuple[Verdict, str]:
    """The replay's verdict from the held-out force and position errors (%, before and after), the validation log's, the test, and
    :func:`~ilic_cli.diagnosis.materiality.below_period`'s objection; and its sentence."""
    (fb, fa), (pb, pa), (vb, va) = force, position, validation
    if not fa < fb:
        return Verdict.NO_FALL, f"rejected by the replay: the held-out simulated force error does not fall ({fb:.3g} % -> {fa:.3g} %)"
    if not significant:
        return (
            Verdict.NOT_SIGNIFICANT,
            f"rejected by the replay: the held-out simulated force error falls ({fb:.3g} % -> {fa:.3g} %) but not significantly ({p_text})",
        )
    if pa > pb:
        return Verdict.POSITION_RISES, f"rejected by the replay: the held-out simulated position error rises ({pb:.3g} % -> {pa:.3g} %)"
    if va is not None and vb is not None and va > vb:
        return Verdict.VALIDATION_RISES, f"rejected by the replay: the validation log's simulated force error rises ({vb:.3g} % -> {va:.3g} %)"
    if short is not None:
        return Verdict.BELOW_PERIOD, short
    return Verdict.AGREES, f"the replay agrees: held-out simulated force error {fb:.3g} % -> {fa:.3g} % ({p_text}), position {pb:.3g} % -> {pa:.3g} %"
