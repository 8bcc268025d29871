"""One diagnosis per corpus case for the whole test session (several test modules, in either xdist worker, assert on the same log)."""

from __future__ import annotations

import pickle
from functools import cache
from typing import Any

from ilic_cli.diagnosis.core import Diagnosis, diagnose
from ilic_cli.effects.definition import Effect
from ilic_cli.effects.registry import EFFECTS
from tests.corpus import build_case, case_of
from tests.shared_cache import shared


def _registered(effect_id: str) -> Effect:
    return EFFECTS[effect_id]


class DiagnosisPickler(pickle.Pickler):
    """A pickler of :class:`Diagnosis`: an :class:`Effect` (its columns are lambdas) is stored by its id, loaded as the registry's object."""

    def reducer_override(self, obj: Any) -> Any:
        if isinstance(obj, Effect):
            if EFFECTS.get(obj.id) is not obj:
                raise pickle.PicklingError(f"effect {obj.id!r} is not the registry's")
            return _registered, (obj.id,)
        return NotImplemented


@cache
def diagnosed(name: str) -> Diagnosis:
    """``diagnose`` of corpus case ``name`` (or ``name@sSEED``, reseeded) with the default settings, computed once per session (read it, do not change it)."""
    return shared(f"diagnosed:{name}", lambda: diagnose(build_case(case_of(name))), DiagnosisPickler)
