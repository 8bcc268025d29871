"""The compiled loop for effects that have no compiled form of their own.

The built-in effects are compiled into :mod:`plant.kernel` (cached on disk).
An effect defined only in :mod:`ilic_cli.effects` is linear in its own columns:
its plant force is ``sum_i theta_i * of_i(q, qd, 0, t, value)``, the columns'
pointwise forms (:attr:`ilic_cli.effects.EffectColumn.of`) times the
coefficients of its linear form (:meth:`ilic_cli.effects.Effect.linear_form`).
It gets a copy of the kernel compiled with that force added to the net force
on the axis (and the stick/slip decision), at first use in a process (a few
seconds, not cached on disk). Its value and coefficients follow the built-in
slots in the plant vector (:func:`plant.dynamics.plant_vector`).
"""

from __future__ import annotations

import functools
import importlib.util
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import Any

from ilic_cli.effects import EFFECTS, EffectParams
from ilic_cli.jit import njit
from plant import kernel
from plant.dynamics import generic_effects


def kernel_for(effects: Mapping[str, EffectParams]) -> ModuleType:
    """The kernel module that simulates ``effects``: :mod:`plant.kernel` unless one has no compiled form."""
    ids = tuple(e.id for e in generic_effects(effects))
    return _compiled(ids) if ids else kernel


def _summed_force(ids: tuple[str, ...]) -> Callable[..., float]:
    """One compiled ``(g, q, qd, t) -> force``: each effect's columns times their coefficients, read from ``g`` in turn.

    Per effect ``g`` holds its nonlinear value (NaN without one) and then one coefficient per column (:func:`plant.dynamics.plant_vector`).
    """
    total: Callable[..., float] = _zero
    start = 0
    for eid in ids:
        effect = EFFECTS[eid]
        for i, column in enumerate(effect.columns):
            assert column.of is not None, f"effect '{eid}': column '{column.name}' has no pointwise form"  # plant_vector refused it
            total = _plus(total, njit(column.of), start, start + 1 + i)
        start += 1 + len(effect.columns)
    return total


@njit
def _zero(g: Any, q: float, qd: float, t: float) -> float:
    return 0.0


def _plus(rest: Callable[..., float], column: Callable[..., float], at_value: int, at_coef: int) -> Callable[..., float]:
    """``rest`` plus one column times its coefficient ``g[at_coef]``, at the value ``g[at_value]`` (compiled; the indices are constants)."""

    @njit
    def total(g: Any, q: float, qd: float, t: float) -> float:
        return rest(g, q, qd, t) + g[at_coef] * column(q, qd, 0.0, t, g[at_value])

    return total


@functools.lru_cache(maxsize=8)
def _compiled(ids: tuple[str, ...]) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"plant._kernel_{'_'.join(ids)}", kernel.__file__)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    module.__dict__["_GENERIC_FORCE"] = _summed_force(ids)  # the kernel module reads this global when it is executed
    spec.loader.exec_module(module)
    return module
