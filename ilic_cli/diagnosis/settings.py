"""The settings of a diagnosis (:class:`DiagnoseSettings`), passed down the stages: propose, decide, refit, report."""

from __future__ import annotations

from dataclasses import dataclass, field

from ilic_cli.diagnosis.null import NullSettings
from ilic_cli.diagnosis.select import SelectSettings
from ilic_cli.idim_ls import LSSettings


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of a diagnosis.

    Attributes
    ----------
    model : str
        Rigid model structure identified first (``rigid-offset``).
    ls : LSSettings
        IDIM-LS filtering and decimation (benchmark defaults).
    select : SelectSettings
        Statistics of the forward selection.
    simulate : bool
        Replay the recorded reference through the plant (before/after).
    null : NullSettings
        The test that decides the replay (default: Diebold-Mariano; or a Monte-Carlo null).
    pd_timing : {"recorded", "documented"}
        When a PD log's command acts in every replay (:data:`ilic_cli.parameters.PD_TIMINGS`).
    replay_noise : bool
        The replays that decide carry the recording's position noise (:mod:`ilic_cli.diagnosis.sensor`); ``False``: noise-free.
    """

    model: str = "rigid-offset"
    ls: LSSettings = LSSettings()
    select: SelectSettings = field(default_factory=SelectSettings)
    simulate: bool = True
    null: NullSettings = NullSettings()
    pd_timing: str = "recorded"
    replay_noise: bool = True


def replay_alpha(settings: DiagnoseSettings) -> float:
    """Level of the replay's test: ``settings.null.alpha``, else the selection's held-out level."""
    return settings.null.alpha if settings.null.alpha is not None else settings.select.alpha_heldout
