"""Artefacts computed once per test session for every pytest-xdist worker: a pickle under the session's shared tmp dir.

Under ``pytest -n N`` each worker is its own process: a ``functools.cache`` there is
per worker, and two workers that need the same expensive artefact (a corpus log's
diagnosis, some 10 s) each computed it. :func:`shared` keeps the first one's result
as a file beside the workers' tmp dirs (``<basetemp>/shared-artefacts``, set by the
session fixture of ``tests/conftest.py``), under a lock: the other worker waits for
it or reads it. Without xdist (``-n 0``) it only computes: the caller's in-process
cache is enough there.
"""

from __future__ import annotations

import atexit
import fcntl
import hashlib
import io
import os
import pickle
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")

_folder: list[Path] = []
"""The session's shared folder, when one is set (:func:`use_folder`)."""

_own: list[Path] = []
"""This process's temporary folder for :func:`folder_for` when no shared folder is set."""


def use_folder(folder: Path | None) -> None:
    """Keep artefacts in ``folder`` from now on (``None``: keep none)."""
    _folder.clear()
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
        _folder.append(folder)


def _stem(key: str) -> str:
    """The file name of artefact ``key`` (the whole key: ``name@sSEED`` is another artefact than ``name``)."""
    return hashlib.sha256(key.encode()).hexdigest()[:32]


def folder_for(key: str) -> Path:
    """A folder for the files of artefact ``key`` (made by its :func:`shared` ``compute``): in the session's shared folder, so the
    other workers read what the first wrote; without one (``-n 0``), in a temporary folder of this process."""
    stem = _stem(key)
    if _folder:
        return _folder[0] / f"{stem}.files"
    if not _own:
        _own.append(Path(tempfile.mkdtemp(prefix="ilic-tests-")))
        atexit.register(shutil.rmtree, _own[0], True)
    return _own[0] / f"{stem}.files"


def shared(key: str, compute: Callable[[], T], pickler: type[pickle.Pickler] = pickle.Pickler) -> T:
    """``compute()`` once per session and ``key`` across the workers: the first caller computes and stores it, the others load it.

    Parameters
    ----------
    key : str
        What the artefact is (one key, one artefact: the caller's arguments in full).
    compute : Callable[[], T]
        Makes the artefact (deterministic: any worker's result is the same).
    pickler : type[pickle.Pickler]
        The pickler that stores it (one with a ``reducer_override`` for objects that pickle by name).

    Returns
    -------
    T
        The artefact, computed here or loaded from the first worker's file.
    """
    if not _folder:
        return compute()
    stem = _stem(key)
    path = _folder[0] / f"{stem}.pickle"
    with open(_folder[0] / f"{stem}.lock", "a+b") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes: the other workers wait for this one's result
        if path.exists():
            with open(path, "rb") as stream:
                return pickle.load(stream)  # type: ignore[no-any-return]
        value = compute()
        buffer = io.BytesIO()
        pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(value)
        partial = path.with_suffix(".partial")
        partial.write_bytes(buffer.getvalue())
        os.replace(partial, path)  # whole or absent
        return value
