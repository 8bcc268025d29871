"""The built-in effects registered in :data:`~ilic_cli.effects.registry.EFFECTS`, in the order diagnosis tries them."""

from __future__ import annotations

from ilic_cli.effects.drive import CURRENT_LOOP, DELAY, DISTURBANCE, FLEXIBILITY, NOISE, QUANTIZATION, SATURATION
from ilic_cli.effects.mechanics import (
    ASYMMETRIC_FRICTION,
    COULOMB_SMOOTHING,
    FRICTION_DRIFT,
    GRAVITY,
    OFFSET,
    PAYLOAD_CHANGE,
    POSITION_RIPPLE,
    SPRING,
    STRIBECK,
)
from ilic_cli.effects.registry import register

BUILT_IN = (
    ASYMMETRIC_FRICTION,
    STRIBECK,
    POSITION_RIPPLE,
    SPRING,
    GRAVITY,
    PAYLOAD_CHANGE,
    FRICTION_DRIFT,
    COULOMB_SMOOTHING,
    OFFSET,
    DELAY,
    FLEXIBILITY,
    SATURATION,
    QUANTIZATION,
    NOISE,
    DISTURBANCE,
    CURRENT_LOOP,
)
"""The built-in definitions (:mod:`.mechanics`, :mod:`.drive`), in the order of the catalogue."""

for _effect in BUILT_IN:
    register(_effect)
