"""The mutation configuration (``[tool.ilic-mutation]`` in pyproject.toml) still applies to the tree.

A planted bug whose module was renamed or whose text was edited away would stop
``make mutation`` at its last step; this catches it in ``make test``.
"""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["ilic-mutation"]


def test_every_planted_bug_applies_once_and_names_existing_tests():
    assert CONFIG["planted"], "no planted bugs configured"
    for bug in CONFIG["planted"]:
        source = ROOT / bug["path"]
        assert source.is_file(), f"{bug['why']}: {bug['path']} does not exist"
        assert source.read_text().count(bug["old"]) == 1, f"{bug['why']}: its original text does not occur exactly once in {bug['path']}"
        assert bug["old"] != bug["new"], bug["why"]
        for test in bug["tests"]:
            assert (ROOT / test).is_file(), f"{bug['why']}: test file {test} does not exist"


def test_every_mutated_module_and_its_tests_exist():
    assert CONFIG["modules"]
    for path, entry in CONFIG["modules"].items():
        assert (ROOT / path).is_file(), path
        for test in entry["tests"]:
            assert (ROOT / test).is_file(), f"{path}: test file {test} does not exist"
