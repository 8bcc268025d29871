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


def load(path: str | Path, input_format: str | None, topic: str | None, ref_topic: str | None, joint: str | None) -> RunLog:
    """Read a log with the shared input options."""
    from ilic_cli.io import read_log

    return read_log(path, input_format, selection(topic, ref_topic, joint))


def progress_enabled() -> bool:
    """Progress bars only on a terminal and never in CI."""
    import os
    import sys

    return sys.stderr.isatty() and not os.environ.get("CI")


def note(message: str) -> None:
    """Print a message for the user on stderr (stdout carries only results)."""
    click.echo(message, err=True)
