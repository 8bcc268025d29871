"""A proposal the closed-loop replay rejected, judged again once an effect proposed after it is kept (:func:`judged_again`).

The replay (:func:`ilic_cli.diagnosis.heldout_replay.replay_decide`) judges the proposals in order, each against the model of
those kept before it; this module is its second look, on the model the first one should have had.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from ilic_cli.diagnosis.search import SEARCH_STEPS
from ilic_cli.diagnosis.system import Step
from ilic_cli.diagnosis.verdicts import PROPOSED_BY_INVERSE, ReplayNull, ReplayVerdict, Verdict
from ilic_cli.idim_ls import LSSettings
from ilic_cli.runlog import RunLog

Heldout = tuple[np.ndarray, np.ndarray, list[Any]]
"""Held-out simulated force (decimated) and position errors (blocks concatenated), and the value each fold used."""


class Replays(Protocol):
    """The held-out replays of one recording (:class:`ilic_cli.diagnosis.heldout_replay.HeldoutReplays`): what :func:`judged_again` asks of them."""

    def heldout(self, steps: list[Step], search: bool = False) -> Heldout | None: ...

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
    ) -> tuple[ReplayVerdict, Step | None]: ...


AGAIN_AFTER = (Verdict.NO_FALL, Verdict.NOT_SIGNIFICANT, Verdict.POSITION_RISES)
"""The replay's rejections judged again when an effect proposed after the rejected one was kept (:func:`judged_again`)."""


def judged_again(
    replays: Replays,
    proposed: list[Step],
    kept: list[Step],
    verdicts: list[ReplayVerdict],
    alpha: float,
    null: ReplayNull | None,
    validate: tuple[tuple[RunLog, LSSettings], dict[str, Any]] | None,
) -> tuple[list[Step], list[ReplayVerdict]]:
    """The inverse model's proposals the replay rejected (:data:`AGAIN_AFTER`) judged again, once each, against the model with the
    effects kept after them, and kept where the replay then agrees; ``kept`` stays in the order of the proposals.

    Judged in order, an effect is tested against a model without the effects proposed after it: their force, left in
    every fold's residual, is in both replays (corpus, a flexibility beside Stribeck friction, lin12 s721: the flexibility
    judged first fell 1.58 % -> 1.53 %, p = 0.022, with the Stribeck peak still in the error; the Stribeck friction then kept,
    1.58 % -> 0.995 %). Its second judgement is the same test with the same level, on the model the first one should have had.
    """
    n_known = len(kept) - sum(v.accepted for v in verdicts)
    by_index = dict(zip([i for i, v in enumerate(verdicts) if v.accepted], kept[n_known:], strict=True))
    for i, st in enumerate(proposed):
        v = verdicts[i]
        later = [proposed[k].effect.id for k in by_index if k > i]
        if v.accepted or v.verdict not in AGAIN_AFTER or st.level is not None or not later:
            continue
        search = st.effect.id in SEARCH_STEPS and st.effect.scan is not None and not isinstance(st.value, tuple)
        model = kept[:n_known] + [by_index[k] for k in sorted(by_index)]
        current, after = replays.heldout(model), replays.heldout([*model, st], search)
        if current is None or after is None:
            continue
        verdict, judged = replays.judge(st, model, current, after, search, PROPOSED_BY_INVERSE, alpha, null, validate)
        verdicts[i] = replace(verdict, reason=f"{v.reason}; judged again with {', '.join(later)} in the model: {verdict.reason}")
        if verdict.accepted:
            assert judged is not None
            by_index[i] = judged
    return kept[:n_known] + [by_index[k] for k in sorted(by_index)], verdicts
