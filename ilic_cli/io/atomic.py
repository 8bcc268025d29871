"""Atomic output: write to a temporary sibling, rename on success."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ilic_cli.errors import LogError


def same_path(a: str | Path, b: str | Path) -> bool:
    """Return True when ``a`` and ``b`` name the same existing file or folder."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return Path(a).resolve() == Path(b).resolve()


@contextmanager
def atomic_path(target: str | Path, *, directory: bool = False, inputs: tuple[str | Path, ...] = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; move it onto ``target`` on success.

    On any exception (including KeyboardInterrupt) the temporary file or folder
    is removed and ``target`` is left as it was. ``inputs`` are refused as
    targets so that an input is never overwritten.
    """
    target = Path(target)
    for src in inputs:
        if same_path(src, target):
            raise LogError(target, "output would overwrite the input; choose another output path")
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise LogError(target, f"output folder '{parent}' does not exist")
    prefix = f".{target.name}."
    if directory:
        tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=".tmp", dir=parent))
        shutil.rmtree(tmp)  # writers (rosbag2) insist on creating the folder themselves
    else:
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=parent)
        os.close(fd)
        tmp = Path(name)
    try:
        yield tmp
        if tmp.is_file():
            # mkstemp creates 0600; give the output the usual permissions
            os.chmod(tmp, 0o666 & ~_umask())
        if target.is_dir() and not target.is_symlink():
            shutil.rmtree(target)
        os.replace(tmp, target)
    except BaseException:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            tmp.unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_text(target: str | Path, text: str, *, inputs: tuple[str | Path, ...] = ()) -> None:
    """Write ``text`` to ``target`` atomically."""
    with atomic_path(target, inputs=inputs) as tmp:
        tmp.write_text(text, encoding="utf-8")
