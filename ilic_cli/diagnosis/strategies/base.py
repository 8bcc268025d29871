"""The protocol of an effect's identification strategy: how the diagnosis identifies an effect the inverse model cannot on its own.

An effect names its strategy by a typed field (:attr:`ilic_cli.effects.Effect.strategy`); the diagnosis looks it
up (:func:`ilic_cli.diagnosis.strategies.strategy_of`), never by the effect's id. A strategy says which rows (the
logs it applies to), which scan (its proposal, and its search on each fold's training blocks), and which refit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ilic_cli.diagnosis.fits import Refit
from ilic_cli.diagnosis.system import Step, SystemFit
from ilic_cli.effects import Effect
from ilic_cli.idim_ls import IDIMData, LSSettings
from ilic_cli.regressor import Model
from ilic_cli.runlog import RunLog


class IdentificationStrategy(Protocol):
    """How the diagnosis identifies one effect beyond the inverse model's forward selection."""

    name: str
    """The value of :attr:`ilic_cli.effects.Effect.strategy` that names it."""
    method: str
    """How a finding it proposes is estimated (``Finding.method``, ``ReplayVerdict.proposed_by``)."""
    spread: str
    """Where the standard deviations of its estimates come from, as the report says it."""
    not_refitted: str
    """Why its finding keeps the closed-loop search's estimate when its own refit is not used."""

    def applies(self, log: RunLog, min_s: float, min_count: int) -> bool:
        """Which rows: whether ``log`` has the rows the strategy needs (a reference that dwells at least ``min_count`` times ``min_s``)."""
        ...

    def propose(self, effect: Effect, data: IDIMData, base: Model, rows: np.ndarray) -> Step | None:
        """Which scan, first: the candidate the replay searches (its level held), or ``None`` when the model cannot carry it."""
        ...

    def scan(self, step: Step, rigid: SystemFit, grid: np.ndarray, training_error: Callable[[Step | None], float]) -> Step | None:
        """Which scan, per fold: the candidate's values searched on one fold's training error (``None``: the model without it),
        from the fold's rigid fit ``rigid`` and the effect's ``grid``."""
        ...

    def judged(self, found: list[Step | None], joint: str) -> tuple[Step | None, str]:
        """The step the folds' estimates give, and a sentence (in the units of a ``joint``); ``None`` when too few folds found one."""
        ...

    def fold_values(self, found: list[Step | None]) -> list[Any]:
        """Each fold's values, for the verdict's record."""
        ...

    def refit(
        self,
        log: RunLog,
        data: IDIMData,
        base: Model,
        rows: np.ndarray,
        ls: LSSettings,
        known: list[Step],
        kept: list[Step],
        hold: float,
        *,
        segment_s: float,
        level_z: float,
    ) -> tuple[Refit, str | None]:
        """Which refit: the finding (the last of ``kept``) estimated again, and why the recording refutes it (else ``None``)."""
        ...
