"""Whether an inverse model's rigid estimate can be the axis's: its mass (inertia) is positive (``identify`` and ``diagnose``), and
an arm's joint's friction takes energy out, not in (``identify --urdf``).

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


def driving_friction(names: Sequence[str], theta: Sequence[float] | np.ndarray, std: Sequence[float] | np.ndarray, joints: Sequence[str]) -> str | None:
    """Why an arm's estimate is no arm's: a joint whose viscous and Coulomb friction (``Fv_<joint>``, ``Fc_<joint>``) are both negative
    beyond their 95 % intervals, a friction that would drive the joint; ``None`` else. An arm2 log with its torques negated gave
    every base parameter turned (``Ia_shoulderR`` -1.385, ``Fv_shoulder`` -2.001, ``Fc_shoulder`` -2.999) with exit 0; its inertial
    base parameters are combinations whose sign no one rule fixes, the friction's is."""
    index = {n: i for i, n in enumerate(names)}
    turned = []
    for joint in joints:
        iv, ic = index.get(f"Fv_{joint}"), index.get(f"Fc_{joint}")
        if iv is None or ic is None:
            continue
        if all(math.isfinite(float(theta[i])) and float(theta[i]) + Z95 * float(std[i]) < 0.0 for i in (iv, ic)):
            turned.append(f"{joint} (Fv = {float(theta[iv]):.4g}, Fc = {float(theta[ic]):.4g})")
    if not turned:
        return None
    return (
        f"the torque opposes the motion at joint(s) {', '.join(turned)}: viscous and Coulomb friction both negative beyond their 95 % "
        "intervals, a friction that would drive the joint; its torque is logged with the sign opposite to its position's (negate one of them)"
    )
