"""The compiled loop for effects that have no compiled form of their own.

The built-in effects are compiled into :mod:`plant.kernel` (cached on disk).
An effect defined only in :mod:`ilic_cli.effects` -- a force of position and
velocity, ``force(q, qd, prm)`` -- gets a copy of the kernel compiled with
that force added to the net force on the axis (and the stick/slip decision),
at first use in a process (a few seconds, not cached on disk). Its
parameters follow the built-in slots in the plant vector
(:func:`plant.dynamics.plant_vector`).
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

from numba import njit

from ilic_cli.effects import EFFECTS, EffectParams
from plant import kernel
from plant.dynamics import generic_effects


def kernel_for(effects: Mapping[str, EffectParams]) -> ModuleType:
    """The kernel module that simulates ``effects``: :mod:`plant.kernel` unless one has no compiled form."""
    ids = tuple(e.id for e in generic_effects(effects))
    return _compiled(ids) if ids else kernel


def _summed_force(ids: tuple[str, ...]) -> Callable[..., float]:
    """One compiled ``(g, q, qd) -> force``: the effects' forces, each reading its parameters from ``g`` in turn."""
    total: Callable[..., float] = _zero
    start = 0
    for eid in ids:
        effect = EFFECTS[eid]
        assert effect.force is not None, f"effect '{eid}' has neither a compiled form nor a force term"
        total = _plus(total, njit(effect.force), start, start + len(effect.params))
        start += len(effect.params)
    return total


@njit
def _zero(g: Any, q: float, qd: float) -> float:
    return 0.0


def _plus(rest: Callable[..., float], force: Callable[..., float], a: int, b: int) -> Callable[..., float]:
    """``rest`` plus one effect's force on parameters ``g[a:b]`` (compiled; the closure's values are constants)."""

    @njit
    def total(g: Any, q: float, qd: float) -> float:
        return rest(g, q, qd) + force(q, qd, g[a:b])

    return total


@functools.lru_cache(maxsize=8)
def _compiled(ids: tuple[str, ...]) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"plant._kernel_{'_'.join(ids)}", kernel.__file__)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    module.__dict__["_GENERIC_FORCE"] = _summed_force(ids)  # the kernel module reads this global when it is executed
    spec.loader.exec_module(module)
    return module
