"""Whether an inverse model's rigid estimate can be the axis's: its mass (inertia) is positive (``identify`` and ``diagnose``).

The rigid model ``tau = M qdd + Fv qd + Fc sign(qd) + offset`` fitted to a force logged with the sign opposite to the
position's gives every coefficient with its sign turned: the 0.5 kg·m² joint's trapezoid with its force negated came out
M = -0.4999 kg·m², Fv = -0.798, Fc = -1.50, the same relative error (1.41 %), and ``identify`` printed them with exit 0.
No axis has a negative mass, so such a fit is refused (:func:`opposed_force`), saying what it shows. A mass the log does not
determine (its 95 % interval holding 0: a log without acceleration) is not refused here: its σ says so in the report.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ilic_cli.effects.definition import Z95
from ilic_cli.parameters import unit


def opposed_force(names: Sequence[str], theta: Sequence[float] | np.ndarray, std: Sequence[float] | np.ndarray, joint: str = "prismatic") -> str | None:
    """Why a rigid estimate (``names``, ``theta`` and its standard deviations ``std``) is no axis's: its mass negative beyond its 95 %
    interval; ``None`` when it is positive or not determined (or the model has no ``M``)."""
    if "M" not in names:
        return None
    i = list(names).index("M")
    m, s = float(theta[i]), float(std[i])
    if not (math.isfinite(m) and math.isfinite(s)) or m + Z95 * s >= 0.0:
        return None
    turned = [n for n in ("Fv", "Fc") if n in names and float(theta[list(names).index(n)]) < 0.0]
    also = f" ({' and '.join(turned)} negative too)" if turned else ""
    mass = "inertia" if joint == "revolute" else "mass"
    return (
        f"the force opposes the acceleration: the rigid fit's {mass} is negative, M = {m:.4g} ± {Z95 * s:.2g} {unit('M', joint)} (95 %){also}; "
        "the force is logged with the sign opposite to the position's (negate one of them), or is not this axis's"
    )
