"""The replay judges a rejected proposal again once an effect proposed after it is kept (issue 29: Stribeck friction beside a flexibility)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from ilic_cli.diagnosis import heldout_replay
from ilic_cli.diagnosis.system import Step
from ilic_cli.diagnosis.verdicts import ReplayVerdict, Verdict
from ilic_cli.effects import EFFECTS


class _Replays:
    """Held-out replays of a log with two effects: the flexibility lowers the error significantly only once the Stribeck friction is in
    the model (the corpus's lin12 s721: 1.58 % -> 1.53 %, p = 0.022, judged first; 1.01 % -> 0.395 % with the friction kept)."""

    def __init__(self, *args: Any) -> None:
        self.models: list[tuple[str, ...]] = []

    def heldout(self, steps: list[Step], search: bool = False) -> tuple[np.ndarray, np.ndarray, list[Any]]:
        ids = tuple(s.effect.id for s in steps)
        self.models.append(ids)
        return np.zeros(3), np.zeros(3), list(ids)

    def judge(self, st: Step, kept: list[Step], current: Any, after: Any, *rest: Any) -> tuple[ReplayVerdict, Step]:
        ok = st.effect.id == "stribeck" or any(s.effect.id == "stribeck" for s in kept)
        verdict = Verdict.AGREES if ok else Verdict.NOT_SIGNIFICANT
        return ReplayVerdict(st.effect.id, 1.0, 0.5, 1.0, 1.0, 1e-6 if ok else 0.02, None, None, ok, verdict.value, verdict=verdict), st


def test_a_proposal_rejected_before_a_later_kept_one_is_judged_again_with_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heldout_replay, "HeldoutReplays", _Replays)
    flex, stribeck = Step(EFFECTS["flexibility"], (30.0, 0.1)), Step(EFFECTS["stribeck"], 0.02)
    no_plant: Any = None
    kept, verdicts = heldout_replay.replay_decide(no_plant, no_plant, no_plant, [], [flex, stribeck], np.ones(3, bool), no_plant, sensor_noise=False)
    assert [s.effect.id for s in kept] == ["flexibility", "stribeck"]  # the proposals' order
    assert [v.accepted for v in verdicts] == [True, True]
    assert verdicts[0].reason == "not significant; judged again with stribeck in the model: the replay agrees"


def test_nothing_is_judged_again_without_a_later_effect_kept(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(heldout_replay, "HeldoutReplays", _Replays)
    flex, stribeck = Step(EFFECTS["flexibility"], (30.0, 0.1)), Step(EFFECTS["stribeck"], 0.02)
    no_plant: Any = None
    kept, verdicts = heldout_replay.replay_decide(no_plant, no_plant, no_plant, [], [stribeck, flex], np.ones(3, bool), no_plant, sensor_noise=False)
    assert [s.effect.id for s in kept] == ["stribeck", "flexibility"]
    assert [v.reason for v in verdicts] == ["the replay agrees", "the replay agrees"]
    kept, verdicts = heldout_replay.replay_decide(no_plant, no_plant, no_plant, [], [flex], np.ones(3, bool), no_plant, sensor_noise=False)
    assert kept == [] and verdicts[0].reason == "not significant"
