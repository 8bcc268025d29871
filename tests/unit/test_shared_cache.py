"""The session's artefacts shared by the xdist workers (``tests/shared_cache.py``) and the pickler of a cached diagnosis."""

from __future__ import annotations

import fcntl
import pickle
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.effects.registry import EFFECTS
from tests import shared_cache
from tests.diagnose.corpus_cache import DiagnosisPickler


@pytest.fixture()
def folder(tmp_path: Path) -> Iterator[Path]:
    """A shared folder of its own for the test; the session's restored after it."""
    before = list(shared_cache._folder)
    shared_cache.use_folder(tmp_path / "shared")
    yield tmp_path / "shared"
    shared_cache.use_folder(before[0] if before else None)


def test_the_first_result_is_stored_and_every_later_caller_loads_it(folder: Path) -> None:
    calls: list[str] = []

    def make(key: str, value: float) -> np.ndarray:
        calls.append(key)
        return np.array([value, 1.0 / 3.0])

    first = shared_cache.shared("diagnosed:a@s1", lambda: make("a@s1", 1.0))
    again = shared_cache.shared("diagnosed:a@s1", lambda: make("a@s1 again", 2.0))  # as another worker: the stored value, not its own
    other = shared_cache.shared("diagnosed:a@s2", lambda: make("a@s2", 3.0))  # another key, another artefact
    assert calls == ["a@s1", "a@s2"]
    assert again.tobytes() == first.tobytes() and other[0] == 3.0
    assert len(list(folder.glob("*.pickle"))) == 2 and not list(folder.glob("*.partial"))


def test_the_computing_worker_holds_the_key_s_lock(folder: Path) -> None:
    """While one worker computes, another asking for the same key waits (the lock is taken) rather than computing it too."""
    held: list[bool] = []

    def compute() -> int:
        (lock,) = folder.glob("*.lock")
        with open(lock, "a+b") as other:  # another open file: flock's locks are per open file, as another process's
            try:
                fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
                held.append(False)
            except BlockingIOError:
                held.append(True)
        return 7

    assert shared_cache.shared("k", compute) == 7 and held == [True]


def test_without_a_folder_each_call_computes() -> None:
    before = list(shared_cache._folder)
    shared_cache.use_folder(None)
    try:
        values = iter([1, 2])
        assert [shared_cache.shared("k", lambda: next(values)) for _ in range(2)] == [1, 2]
    finally:
        shared_cache.use_folder(before[0] if before else None)


def test_a_diagnosis_s_effects_come_back_as_the_registry_s_objects() -> None:
    """An effect (its columns are lambdas) is pickled by id; one that is not the registry's is refused, not stored as another."""
    import io

    delay = EFFECTS["delay"]
    buffer = io.BytesIO()
    DiagnosisPickler(buffer).dump({"kept": [delay, EFFECTS["stribeck"]], "x": np.arange(3.0)})
    loaded = pickle.loads(buffer.getvalue())
    assert loaded["kept"][0] is delay and loaded["kept"][1] is EFFECTS["stribeck"] and loaded["x"].tolist() == [0.0, 1.0, 2.0]
    with pytest.raises(pickle.PicklingError, match="not the registry's"):
        DiagnosisPickler(io.BytesIO()).dump(replace(delay, title="a copy"))


def test_an_artefact_s_files_are_in_the_shared_folder_under_its_key(folder: Path) -> None:
    """:func:`tests.shared_cache.folder_for`: the files one worker's ``compute`` wrote are where the other looks, one folder per key."""
    a, b = shared_cache.folder_for("cli:diagnose\0x"), shared_cache.folder_for("cli:diagnose\0y")
    assert a.parent == b.parent == folder and a != b and a == shared_cache.folder_for("cli:diagnose\0x")
    shared_cache.use_folder(None)
    alone = shared_cache.folder_for("cli:diagnose\0x")  # -n 0: a temporary folder of this process
    assert folder not in alone.parents and alone.parent == shared_cache.folder_for("k").parent
