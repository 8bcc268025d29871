"""One candidate effect tried at one step of the selection (:class:`Evaluation`), the type the selection
(:mod:`ilic_cli.diagnosis.select`) and its rivals (:mod:`ilic_cli.diagnosis.rivals`) share."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli.diagnosis.stats import HELDOUT_FALL_TEST, FTest
from ilic_cli.diagnosis.verdicts import Selection
from ilic_cli.effects import Effect


@dataclass(frozen=True)
class Evaluation:
    """One candidate effect tried at one step of the selection."""

    effect: str
    value: Any
    value_std: float | None
    test: FTest
    relative_error_pct: float = float("nan")
    heldout_before_pct: float | None = None
    heldout_after_pct: float | None = None
    heldout_p_value: float | None = None
    validation_before_pct: float | None = None
    validation_after_pct: float | None = None
    accepted: bool = False
    reason: str = ""
    outcome: Selection = Selection.PENDING
    """The inverse model's decision, typed (``reason`` says it in words, and later stages may add to it)."""
    indistinct_from: str | None = None
    """An effect the data cannot tell from this one (:func:`ilic_cli.diagnosis.rivals.parsimonious_first`): neither's fitted
    force adds significantly to the model with the other's, over the range the log visits; or one whose fit, on the edge of its
    search range, leaves less error (:attr:`beside_edge`); ``None``: none. A typed ambiguity, stated with the finding."""
    beside_edge: Evaluation | None = None
    """The candidate :attr:`indistinct_from` names when it is one of the same step whose estimate is on the edge of its search range
    and leaves less error than this one (:func:`ilic_cli.diagnosis.rivals.beside_an_edge`), else ``None``."""

    def unconfirmed_at(self, level: float | None = None) -> bool:
        """Whether its F-test passed but its held-out test did not confirm it (:attr:`Selection.HELDOUT_UNCONFIRMED`), or, given a
        ``level``, confirmed it on a p-value not below that level (a proposal, not confirmed at the level that decides)."""
        if self.outcome is Selection.HELDOUT_UNCONFIRMED:
            return True
        return level is not None and self.outcome is Selection.ACCEPTED and self.heldout_p_value is not None and self.heldout_p_value >= level

    def decided(self, outcome: Selection, detail: str | None = None, **figures: Any) -> Evaluation:
        """This evaluation decided: ``outcome``, its sentence (:meth:`~ilic_cli.diagnosis.verdicts.Selection.sentence`) as the reason."""
        return replace(self, outcome=outcome, reason=outcome.sentence(detail), accepted=outcome is Selection.ACCEPTED, **figures)

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "nonlinear_value": list(self.value) if isinstance(self.value, tuple) else self.value,
            "nonlinear_std": self.value_std,
            **self.test.to_dict(),
            "relative_error_pct": self.relative_error_pct,
            "heldout_relative_error_pct": {"before": self.heldout_before_pct, "after": self.heldout_after_pct},
            "heldout_test": None if self.heldout_p_value is None else {"test": f"{HELDOUT_FALL_TEST}, held-out IDIM rows", "p_value": self.heldout_p_value},
            "validation_relative_error_pct": None
            if self.validation_before_pct is None
            else {"before": self.validation_before_pct, "after": self.validation_after_pct},
            "accepted": self.accepted,
            "reason": self.reason,
            **({"indistinct_from": self.indistinct_from} if self.indistinct_from is not None else {}),
        }


Candidate = tuple[Evaluation, Effect, np.ndarray, np.ndarray]
"""A candidate's evaluation, its effect, and the system ``(W, y)`` with it."""
