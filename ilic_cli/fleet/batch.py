"""A batch: which logs, each log's key, the per-log store that makes a batch resumable.

Each log's key is a hash of its bytes (every file of a ROS 2 bag folder), the
:class:`~ilic_cli.fleet.execute.TaskSettings` and the package version: the same
log under another name is computed once, and an edited log or other settings
are computed again. Each finished log's document is written to
``OUT/logs/KEY.json`` atomically as it arrives, so a batch stopped at any point
resumes with the logs not yet stored; the table is then rebuilt from the store
(:mod:`ilic_cli.fleet.table`), the same whether the documents are new or old.
"""

from __future__ import annotations

import glob
import hashlib
import json
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ilic_cli import __version__
from ilic_cli.errors import IlicError
from ilic_cli.fleet.execute import Runner, Task, TaskSettings, in_process
from ilic_cli.io import EXTENSIONS
from ilic_cli.io.atomic import atomic_write_text

GLOB_CHARACTERS = frozenset("*?[")
GROUPS = ("machine", "joint", "start")
"""Named groups a ``--group-by`` pattern may have: the machine id, the joint id and the log's start (ISO 8601, UTC)."""

STORE = "logs"
"""The folder under a batch's output that holds one document per finished log."""


def is_log(path: Path) -> bool:
    """A file with a log's extension, or a ROS 2 bag folder (``metadata.yaml`` inside)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in EXTENSIONS


def find_logs(arguments: Sequence[str]) -> list[Path]:
    """The logs the arguments name: paths, globs (``**`` too) and folders searched for logs; sorted, each once.

    Raises
    ------
    IlicError
        An argument names nothing, or a glob or folder holds no log.
    """
    found: dict[str, Path] = {}
    for arg in arguments:
        if GLOB_CHARACTERS.intersection(arg):
            paths = [Path(p) for p in glob.glob(arg, recursive=True)]
            paths = [p for p in paths if is_log(p)]
        elif Path(arg).is_dir() and not is_log(Path(arg)):
            paths = [p for p in Path(arg).rglob("*") if is_log(p) and not any(is_log(a) and a.is_dir() for a in p.parents)]
        elif Path(arg).exists():
            paths = [Path(arg)]
        else:
            raise IlicError(arg, "no such log")
        if not paths:
            raise IlicError(arg, "matches no log (.mat, .csv, .mcap, .bag or a ROS 2 bag folder)")
        for p in paths:
            found.setdefault(p.as_posix(), p)
    return [found[k] for k in sorted(found)]


def content_hash(path: Path) -> str:
    """SHA-256 of a log's bytes; of a folder's files, names and bytes in sorted order."""
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        if path.is_dir():
            h.update(f.relative_to(path).as_posix().encode() + b"\0")
        with open(f, "rb") as fh:
            h.update(hashlib.file_digest(fh, "sha256").digest())
    return h.hexdigest()


def task_key(digest: str, settings: TaskSettings) -> str:
    """The key of a log's document: its content hash, the settings and the package version."""
    text = json.dumps({"content": digest, "settings": settings.to_dict(), "version": __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def group_pattern(pattern: str | None) -> re.Pattern[str] | None:
    """Compile a ``--group-by`` pattern: a regular expression with named groups among :data:`GROUPS`.

    Raises
    ------
    IlicError
        Not a regular expression, no named group, or a group of another name.
    """
    if pattern is None:
        return None
    try:
        rx = re.compile(pattern)
    except re.error as exc:
        raise IlicError("group pattern", f"not a regular expression: {exc}") from None
    names = set(rx.groupindex)
    if not names:
        raise IlicError("group pattern", f"no named group: name them (?P<machine>...), (?P<joint>...) or (?P<start>...) [{', '.join(GROUPS)}]")
    unknown = sorted(names - set(GROUPS))
    if unknown:
        raise IlicError("group pattern", f"unknown group '{unknown[0]}' (known: {', '.join(GROUPS)})")
    return rx


def path_groups(rx: re.Pattern[str] | None, path: Path) -> tuple[dict[str, Any], str | None]:
    """The machine, joint and start (``start_time_ns``) the pattern reads from ``path``; else why not."""
    if rx is None:
        return {}, None
    m = rx.search(path.as_posix())
    if m is None:
        return {}, f"{path}: the path does not match --group-by {rx.pattern!r}"
    out: dict[str, Any] = {k: v for k, v in m.groupdict().items() if v is not None and k != "start"}
    start = m.groupdict().get("start")
    if start is not None:
        ns = parse_start(start)
        if ns is None:
            return out, f"{path}: --group-by start '{start}' is not an ISO 8601 date or time"
        out["start_time_ns"] = ns
    return out, None


def parse_start(text: str) -> int | None:
    """Nanoseconds since 1970 UTC of an ISO 8601 date or date and time (UTC unless it says otherwise); ``None`` if not one."""
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        return None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    delta = when - datetime(1970, 1, 1, tzinfo=UTC)
    return (delta.days * 86400 + delta.seconds) * 10**9 + delta.microseconds * 1000


@dataclass
class BatchResult:
    """What a batch did: the logs, their documents (by key) and how many were computed now."""

    logs: list[Path]
    keys: list[str]
    documents: dict[str, dict[str, Any]]
    computed: int
    resumed: int
    out_dir: Path
    written: list[Path] = field(default_factory=list)

    @property
    def errors(self) -> int:
        return sum(1 for k in self.keys if self.documents[k]["error"] is not None)

    def to_dict(self) -> dict[str, Any]:
        return {
            "logs": len(self.logs),
            "computed": self.computed,
            "resumed": self.resumed,
            "errors": self.errors,
            "out": str(self.out_dir),
            "written": [str(p) for p in self.written],
        }


def stored(out_dir: Path, key: str) -> dict[str, Any] | None:
    """The stored document of ``key``, or ``None`` (absent or unreadable: computed again)."""
    path = out_dir / STORE / f"{key}.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) and doc.get("key") == key else None


def plain(x: Any) -> Any:
    """``x`` as plain JSON values: numpy scalars as Python numbers, a non-finite float as ``None``."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if hasattr(x, "item") and not isinstance(x, (str, bytes)):  # a numpy scalar
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def store(out_dir: Path, doc: dict[str, Any]) -> None:
    """Write a finished log's document atomically (``OUT/logs/KEY.json``)."""
    atomic_write_text(out_dir / STORE / f"{doc['key']}.json", json.dumps(plain(doc), sort_keys=True, allow_nan=False) + "\n")


def run_batch(
    logs: Sequence[Path],
    out_dir: Path,
    settings: TaskSettings,
    runner: Runner = in_process,
    progress: Callable[[int, int], None] | None = None,
    stop_after: int | None = None,
) -> BatchResult:
    """Compute every log not yet in ``out_dir``'s store with ``runner``, storing each as it finishes.

    Parameters
    ----------
    logs : sequence of Path
        The logs (:func:`find_logs`).
    out_dir : Path
        The batch's folder (created); its store is ``out_dir/logs``.
    settings : TaskSettings
        What to compute on each log.
    runner : callable
        Where the tasks run (:mod:`ilic_cli.fleet.execute`).
    progress : callable, optional
        ``progress(done, total)`` after each log (the resumed ones count as done at the start).
    stop_after : int, optional
        Stop (``KeyboardInterrupt``) once this many logs were computed and stored: a batch stopped half way.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / STORE).mkdir(exist_ok=True)
    keys = [task_key(content_hash(p), settings) for p in logs]
    documents: dict[str, dict[str, Any]] = {}
    tasks: dict[str, Task] = {}
    for path, key in zip(logs, keys):
        doc = stored(out_dir, key)
        if doc is not None:
            documents[key] = doc
        elif key not in tasks:
            tasks[key] = Task(path.as_posix(), key, settings)
    resumed = len({k for k in keys if k in documents})
    total = len(set(keys))
    if progress is not None:
        progress(resumed, total)
    computed = 0
    for doc in runner(list(tasks.values())) if tasks else ():
        doc = plain(doc)  # the table reads a new document as it would read it back from the store
        store(out_dir, doc)
        documents[doc["key"]] = doc
        computed += 1
        if progress is not None:
            progress(resumed + computed, total)
        if stop_after is not None and computed >= stop_after and computed < len(tasks):
            raise KeyboardInterrupt
    return BatchResult(list(logs), keys, documents, computed, resumed, out_dir)
