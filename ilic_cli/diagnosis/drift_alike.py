"""A drift whose coefficient the rows cannot tell: the trend of ``Fv`` or of ``Fc`` explains them alike (issue 29, item 5).

On moves at one cruise speed the viscous and the Coulomb column are nearly proportional wherever the axis moves, and so
are their trends: a warm-up of ``Fv`` is as well a warm-up of ``Fc`` there (the independent simulator's 3 kg·m² joint,
S-curves at 250 Hz under the loop a period late, seed 61: each trend alone at p ~ 1e-90, neither significant given the
other, p = 1; its warm-up of Fv was reported as one of Fc, -0.485 +- 0.015 N·m for the truth's -0.5 N·m·s/rad at 1 rad/s,
with nothing said of the other). The forward selection keeps the first and tests the second given it; :func:`alike` tests
the first given the second too. Both not significant: the finding states the other coefficient beside its own
(:data:`ALIKE_RULE`), its values those of the one kept.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ilic_cli.diagnosis.stats import nested_f_test

ALIKE_RULE = (
    "a drift's coefficient is stated with another whose trend alone is significant and material too, when neither trend is "
    "significant given the other (each nested F-test on the prewhitened rows, at the drift's level after its Bonferroni)"
)
"""The rule of :func:`alike`, in words."""


class Alike(NamedTuple):
    """The coefficient whose trend explains the rows as well as the finding's, and the two tests that say so."""

    parameter: str
    p_given_it: float
    """The finding's trend tested given this one's (adjusted p)."""
    p_given_finding: float
    """This trend tested given the finding's (adjusted p)."""

    def cannot_tell(self, found: str) -> str:
        """The conclusion, in words: which two coefficients the rows cannot tell (``found``: the finding's)."""
        return f"the rows cannot tell which of {found} and {self.parameter} drifts"

    def words(self, found: str) -> str:
        return (
            f"a trend of {self.parameter} explains the rows as well (that of {found} given it: p = {self.p_given_it:.2g}; "
            f"it given that of {found}: p = {self.p_given_finding:.2g}): {self.cannot_tell(found)}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {"parameter": self.parameter, "p_given_it": self.p_given_it, "p_given_finding": self.p_given_finding, "rule": ALIKE_RULE}


def alike(W: np.ndarray, y: np.ndarray, found: tuple[np.ndarray, int], others: list[tuple[str, np.ndarray, int]], trials: int, alpha: float) -> Alike | None:
    """The first of ``others`` (``(coefficient, trend column, degrees of freedom)``, each trend alone significant and material) whose
    trend and the finding's (``found``: its column and degrees of freedom) are each not significant given the other in ``W``'s
    model at ``alpha`` (Bonferroni over ``trials``); ``None``: the rows tell the finding's coefficient."""
    column, q = found
    for name, other, q_other in others:
        given_it = nested_f_test(np.c_[W, other], y, np.c_[W, other, column], y, q, trials)
        given_found = nested_f_test(np.c_[W, column], y, np.c_[W, column, other], y, q_other, trials)
        if given_it.p_adjusted >= alpha and given_found.p_adjusted >= alpha:
            return Alike(name, float(given_it.p_adjusted), float(given_found.p_adjusted))
    return None
