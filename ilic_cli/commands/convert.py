"""``ilic convert``: read a log in one format and write it in another."""

from __future__ import annotations

from pathlib import Path

import click

from ilic_cli.commands.common import LOG_FORMATS, input_options, load, note, options_named
from ilic_cli.commands.robot import convert_options
from ilic_cli.errors import LogError
from ilic_cli.io import WriteOptions, detect_format, write_log
from ilic_cli.io.atomic import same_path


@click.command(
    "convert",
    help="Convert a log between .mat, CSV, MCAP, ROS 1 .bag and ROS 2 bag folders. An arm's log (--urdf, --joints, or a log that declares its joints) "
    "is converted whole: every joint, its reference, types and metadata.",
)
@click.argument("source", metavar="IN", type=click.Path(path_type=Path))
@click.argument("target", metavar="OUT", type=click.Path(path_type=Path))
@click.option(
    "--format", "out_format", type=click.Choice(LOG_FORMATS), default=None, help="Format of OUT (default: from its extension; no extension: ROS 2 bag folder)."
)
@click.option("--storage", type=click.Choice(["sqlite3", "mcap"]), default="sqlite3", show_default=True, help="Storage plugin of a ROS 2 bag.")
@click.option(
    "--resample",
    "resample_hz",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    metavar="HZ",
    help="Put the log on a uniform grid at HZ: restamped when the stamps only jitter at that rate, else interpolated linearly.",
)
@input_options
@convert_options
def command(
    source: Path,
    target: Path,
    out_format: str | None,
    storage: str,
    resample_hz: float | None,
    input_format: str | None,
    topic: str | None,
    ref_topic: str | None,
    joint: str | None,
    columns: str | None,
) -> None:
    """Read IN, optionally resample, write OUT atomically (never over IN)."""
    from ilic_cli.timebase import sampling_kind  # deferred: numpy; `ilic convert --help` stays instant

    if same_path(source, target):
        raise LogError(target, "output would overwrite the input; choose another output path")
    fmt = detect_format(target, out_format, for_writing=True)
    log = load(source, input_format, topic, ref_topic, joint, columns)
    if resample_hz is not None:
        from ilic_cli.prepare import resample  # deferred: numpy; `ilic convert --help` stays instant

        with options_named():
            log = resample(log, resample_hz)
    elif sampling_kind(log.t) == "irregular":
        note(f"ilic: warning: {source}: irregular sampling kept (identify interpolates it onto a uniform grid); use --resample HZ for a uniform grid here")
    options = WriteOptions(storage=storage, joint=joint or "axis")
    write_log(log, target, fmt, options, inputs=(source,))
    rate = log.sensor.sample_rate_hz
    rate_text = f" at {rate:g} Hz" if rate is not None else ""
    note(f"ilic: wrote {target} ({fmt}): {len(log)} samples{rate_text}, {log.duration_s:.6g} s, channels {', '.join(log.channels)}")
