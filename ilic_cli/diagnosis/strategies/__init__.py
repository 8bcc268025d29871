"""Identification strategies attached to effects (:attr:`ilic_cli.effects.Effect.strategy`), looked up by that field.

- ``dwell_segments`` (:mod:`~ilic_cli.diagnosis.strategies.stribeck`): Stribeck friction, proposed by the closed loop
  at a reference's dwells and refitted on open-loop segments driven by the recorded force.
"""

from __future__ import annotations

from ilic_cli.diagnosis.strategies.base import IdentificationStrategy
from ilic_cli.diagnosis.strategies.stribeck import DWELL_SEGMENTS
from ilic_cli.effects import Effect

STRATEGIES: dict[str, IdentificationStrategy] = {DWELL_SEGMENTS.name: DWELL_SEGMENTS}
"""Strategy name -> the strategy."""


def strategy_of(effect: Effect) -> IdentificationStrategy | None:
    """The identification strategy ``effect`` names (:attr:`~ilic_cli.effects.Effect.strategy`), ``None`` when it names none."""
    return None if effect.strategy is None else STRATEGIES[effect.strategy]


__all__ = ["STRATEGIES", "IdentificationStrategy", "strategy_of"]
