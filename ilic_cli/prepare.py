"""One preparation of a log for the numerics: its rate, its quality and the samples that may be used.

``identify``, ``diagnose`` and ``replay`` all start here, so the rate, the
data-quality warnings and the saturation masking are worked out once and
the same way for each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ilic_cli.quality import assess_log, saturation_mask
from ilic_cli.runlog import RunLog


@dataclass(frozen=True)
class PreparedLog:
    """A log with what the numerics need to know about it.

    Attributes
    ----------
    log : RunLog
        The log itself.
    fs_hz : float
        Its nominal sample rate (:attr:`RunLog.fs_hz`).
    valid : ndarray of bool or None
        Samples that may be used; False on the plateaus of a saturated drive
        (:func:`ilic_cli.quality.saturation_mask`); ``None`` when every one may.
    warnings : tuple of str
        The data-quality warnings, prefixed.
    """

    log: RunLog
    fs_hz: float
    valid: np.ndarray | None
    warnings: tuple[str, ...]

    @property
    def source(self) -> str:
        return str(self.log.meta.get("source", ""))

    def saturation_note(self) -> str | None:
        """``saturated drive: X % of the samples masked``, or ``None`` without masking."""
        if self.valid is None:
            return None
        return f"saturated drive: {100.0 * (1.0 - float(np.mean(self.valid))):.3g} % of the samples masked"


def prepare_log(log: RunLog, prefix: str = "data quality") -> PreparedLog:
    """Assess ``log`` once: rate, quality warnings (``prefix: ...``) and the usable samples.

    A saturated drive command is never used silently: the samples on its
    plateau are masked, and the note says so.
    """
    quality = assess_log(log)
    warnings = tuple(f"{prefix}: {message}" for message in quality.warnings())
    valid = None
    if quality.saturation_limit is not None and "vir" in log.channels:
        saturated = saturation_mask(log["vir"], quality.saturation_limit)
        valid = ~saturated if saturated.any() else None
    return PreparedLog(log=log, fs_hz=log.fs_hz, valid=valid, warnings=warnings)
