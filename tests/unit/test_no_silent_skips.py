"""Nothing skips under CI: every skip goes through ``tests.conftest.skip_outside_ci``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests import conftest

TESTS = Path(__file__).parents[1]
SKIPPING = re.compile(r"importorskip\(|pytest\.skip\(|mark\.skip|skipif|pytest\.xfail\(|mark\.xfail")


def test_no_test_file_skips_by_itself() -> None:
    """Only the conftest helper may call ``pytest.skip``; test files use it (or ``import_or_skip``)."""
    offenders = []
    for path in sorted(TESTS.rglob("*.py")):
        if path.name == "conftest.py" and path.parent == TESTS or path == Path(__file__):
            continue
        for i, line in enumerate(path.read_text().splitlines(), start=1):
            if SKIPPING.search(line):
                offenders.append(f"{path.relative_to(TESTS)}:{i}: {line.strip()}")
    assert not offenders, "skip through tests.conftest.skip_outside_ci / import_or_skip:\n" + "\n".join(offenders)


def test_helper_skips_outside_ci_and_fails_in_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="gone"):
        conftest.skip_outside_ci("gone")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="gone.*nothing may skip"):
        conftest.skip_outside_ci("gone")
    with pytest.raises(pytest.fail.Exception, match="cannot import no_such_module_xyz"):
        conftest.import_or_skip("no_such_module_xyz")
    assert conftest.import_or_skip("math").sqrt(4.0) == 2.0


def test_missing_recordings_fail_in_ci(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(conftest, "SHARED_EMPS", tmp_path)
    monkeypatch.setenv("CI", "1")
    with pytest.raises(pytest.fail.Exception, match="DATA_EMPS.mat"):
        conftest.require_shared()
    monkeypatch.setenv("CI", "")
    with pytest.raises(pytest.skip.Exception, match="DATA_EMPS.mat"):
        conftest.require_shared()
