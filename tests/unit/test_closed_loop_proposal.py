"""Which effect an identification strategy proposes on the closed loop (:func:`ilic_cli.diagnosis.propose.closed_loop_proposal`):
where the reference dwells the strategy values its effect, in place of the inverse model's proposal, material or not; elsewhere
only what the held-out test left unconfirmed and the inverse model did not find immaterial."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

import ilic_cli.diagnosis.propose as propose
from ilic_cli.diagnosis.null import REPLAY_ALPHA
from ilic_cli.diagnosis.select import SelectSettings
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.diagnosis.system import Step
from ilic_cli.effects import EFFECTS

STRIBECK = EFFECTS["stribeck"]


@dataclass
class Strategy:
    dwelling: bool

    def applies(self, log: Any, min_s: float, min_count: int) -> bool:
        return self.dwelling

    def propose(self, effect: Any, data: Any, base: Any, rows: Any) -> Step:
        return Step(effect, 0.01, level=(1.0,))


@dataclass
class Selection:
    unconfirmed_ids: tuple[str, ...] = ()
    levels: list[float | None] = field(default_factory=list)

    def unconfirmed(self, effect_id: str, level: float | None = None) -> bool:
        self.levels.append(level)
        return effect_id in self.unconfirmed_ids


def proposal(
    monkeypatch: pytest.MonkeyPatch, dwelling: bool, known: list[Step], unconfirmed: tuple[str, ...] = (), immaterial: list[Step] | None = None
) -> Step | None:
    """``known``: the model file's effects; ``immaterial``: the inverse model's immaterial ones (an accepted one's last word is
    no unconfirmed test: off the dwells it is never proposed again)."""
    strategy = Strategy(dwelling)
    monkeypatch.setattr(propose, "strategy_of", lambda effect: strategy if effect is STRIBECK else None)
    return propose.closed_loop_proposal(None, None, None, known, immaterial or [], np.ones(3, dtype=bool), DiagnosisSettings(), Selection(unconfirmed))  # type: ignore[arg-type]


def test_at_the_dwells_the_strategy_values_what_the_inverse_model_proposed(monkeypatch: pytest.MonkeyPatch) -> None:
    step = proposal(monkeypatch, True, [])  # proposed by the inverse model and material, or not proposed at all: the dwells suffice
    assert step is not None and step.effect is STRIBECK and step.level == (1.0,)


def test_without_dwells_only_what_the_held_out_test_left_unconfirmed(monkeypatch: pytest.MonkeyPatch) -> None:
    assert proposal(monkeypatch, False, []) is None  # the inverse model's material proposal stands, or nothing to judge
    assert proposal(monkeypatch, False, [], ("stribeck",)) is not None  # an F-test passed, the held-out test not


def test_unconfirmed_means_at_the_confirming_level(monkeypatch: pytest.MonkeyPatch) -> None:
    """A proposal the held-out test confirms at 0.05 but not at 0.01 (``SelectSettings.alpha_confirm``, not the replay's level)
    is the closed loop's to value (EMPS s1303)."""
    strategy = Strategy(False)
    monkeypatch.setattr(propose, "strategy_of", lambda effect: strategy if effect is STRIBECK else None)
    selection = Selection()
    propose.closed_loop_proposal(None, None, None, [], [], np.ones(3, dtype=bool), DiagnosisSettings(), selection)  # type: ignore[arg-type]
    assert selection.levels == [SelectSettings().alpha_confirm] == [0.01] and REPLAY_ALPHA != 0.01


def test_a_model_file_s_effect_is_never_proposed_again(monkeypatch: pytest.MonkeyPatch) -> None:
    assert proposal(monkeypatch, True, [Step(STRIBECK, 0.01)]) is None
    assert proposal(monkeypatch, False, [Step(STRIBECK, 0.01)], ("stribeck",)) is None


def test_one_found_immaterial_on_the_rows_is_proposed_again_only_at_the_dwells(monkeypatch: pytest.MonkeyPatch) -> None:
    """The rows leave the dwells out, where the strategy's effect acts: its force there is no measure of it (the independent
    simulator's tanh trapezoid at 500 Hz, 0.16 % of the force for a Stribeck peak half the Coulomb level); elsewhere the
    inverse model's immateriality stands."""
    found = [Step(STRIBECK, 0.01)]
    step = proposal(monkeypatch, True, [], immaterial=found)
    assert step is not None and step.effect is STRIBECK and step.level == (1.0,)
    assert proposal(monkeypatch, False, [], ("stribeck",), immaterial=found) is None
