"""One diagnosis per corpus case for the whole test session (several test modules assert on the same log)."""

from __future__ import annotations

from functools import cache

from ilic_cli.diagnosis.core import Diagnosis, diagnose
from tests.corpus import build_case, case_of


@cache
def diagnosed(name: str) -> Diagnosis:
    """``diagnose`` of corpus case ``name`` (or ``name@sSEED``, reseeded) with the default settings, computed once (read it, do not change it)."""
    return diagnose(build_case(case_of(name)))
