"""``benchmarks/diagnose_corpus.py --reseed``: a case again with another seed, its effects and sizes as they are."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from tests.corpus import CASES, build_case, case_of, reseeded

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "diagnose_corpus.py"


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    spec = importlib.util.spec_from_file_location("diagnose_corpus", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def test_a_reseeded_case_keeps_its_effects_and_changes_its_noise(bench: ModuleType) -> None:
    name = "spring-trapezoid-combined-s233"
    case = bench.case_of(f"{name}@s1233")
    assert (case.name, case.seed, case.effects, case.trajectory, case.noise) == (f"{name}@s1233", 1233, CASES[name].effects, "trapezoid", "combined")
    assert bench.case_of(name) is CASES[name]
    assert reseeded(name, 1) == f"{name}@s1233" and reseeded(name, 0) == name and case_of(reseeded(name, 3)).seed == 3233
    a, b = build_case(CASES[name]), build_case(case)
    assert a.meta["corpus"]["truth"]["effects"]["spring"] == b.meta["corpus"]["truth"]["effects"]["spring"]
    assert not np.array_equal(np.asarray(a["tau"]), np.asarray(b["tau"]))


def test_the_table_over_seeds_counts_each_case_once(bench: ModuleType) -> None:
    def row(case: str, missed: list[str], err: dict[str, float]) -> dict[str, object]:
        return {"case": case, "clean": False, "truth": {"stribeck": {}}, "missed": missed, "false_alarms": 0, "parameter_error": err}

    rows = [row("stribeck-x", [], {"stribeck": 0.23}), row("stribeck-x@s1000", ["stribeck"], {}), row("stribeck-x@s2000", [], {"stribeck": 0.1})]
    table = bench.over_seeds([*rows, {**row("clean-x", [], {}), "clean": True}]).splitlines()
    assert len(table) == 3 and table[2] == "| stribeck-x | 3 | 2/3 | 2/3 | 1/2 | 23%, 10% |"
