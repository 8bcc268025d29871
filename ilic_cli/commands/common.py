"""Options and helpers shared by the subcommands."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

if TYPE_CHECKING:
    from ilic_cli.io import Selection
    from ilic_cli.runlog import RunLog

F = TypeVar("F", bound=Callable[..., Any])

LOG_FORMATS = ["mat", "csv", "mcap", "rosbag1", "rosbag2"]


def input_options(func: F) -> F:
    """Add ``--input-format``, ``--topic``, ``--ref-topic`` and ``--joint``."""
    func = click.option("--joint", default=None, help="Joint name to read (default: the only joint).")(func)
    func = click.option("--ref-topic", default=None, help="Topic with the reference (default: /joint_reference).")(func)
    func = click.option("--topic", default=None, help="Topic with the measured JointState (default: the only one, or /joint_states).")(func)
    func = click.option("--input-format", "input_format", type=click.Choice(LOG_FORMATS), default=None, help="Format of the input log (default: from the path).")(func)
    return func


def selection(topic: str | None, ref_topic: str | None, joint: str | None) -> Selection:
    """Build the reader's :class:`~ilic_cli.io.Selection` from the shared options."""
    from ilic_cli.io import Selection

    return Selection(topic=topic, ref_topic=ref_topic, joint=joint)


PROGRESS_MIN_BYTES = 20 * 2**20
"""Files (or bag folders) at least this large show a progress bar while they are read."""


def load(path: str | Path, input_format: str | None, topic: str | None, ref_topic: str | None, joint: str | None) -> RunLog:
    """Read a log with the shared input options (with a progress bar for large files on a terminal)."""
    from ilic_cli.io import read_log

    progress = ReadProgress if progress_enabled() and _size(Path(path)) >= PROGRESS_MIN_BYTES else None
    return read_log(path, input_format, selection(topic, ref_topic, joint), progress=progress)


def _size(path: Path) -> int:
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


class ReadProgress:
    """A one-line progress bar on stderr: ``reading NAME [#####     ]  50 %``; erased when done."""

    WIDTH = 30

    def __init__(self, path: Path) -> None:
        self.label = Path(path).name
        self.last = -1

    def update(self, done: int, total: int) -> None:
        """Redraw the bar when the percentage changes."""
        pct = max(0, min(100, int(100 * done / total))) if total > 0 else 0
        if pct == self.last:
            return
        self.last = pct
        filled = self.WIDTH * pct // 100
        click.echo(f"\r  reading {self.label} [{'#' * filled}{' ' * (self.WIDTH - filled)}] {pct:3d} %", err=True, nl=False)

    def close(self) -> None:
        """Erase the bar."""
        if self.last >= 0:
            click.echo("\r" + " " * (len(self.label) + self.WIDTH + 20) + "\r", err=True, nl=False)


def progress_enabled() -> bool:
    """Progress bars only on a terminal and never in CI."""
    import os
    import sys

    return sys.stderr.isatty() and not os.environ.get("CI")


def note(message: str) -> None:
    """Print a message for the user on stderr (stdout carries only results)."""
    click.echo(message, err=True)
