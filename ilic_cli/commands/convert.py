"""``ilic convert``: read a log in one format and write it in another."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ilic_cli.commands.common import LOG_FORMATS, input_options, load, note
from ilic_cli.errors import LogError
from ilic_cli.io import WriteOptions, detect_format, write_log
from ilic_cli.io.atomic import same_path

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog


def resample(log: RunLog, rate_hz: float) -> RunLog:
    """Return ``log`` linearly interpolated onto a uniform grid.

    Parameters
    ----------
    log : RunLog
        The log (increasing ``t``).
    rate_hz : float
        New sample rate (Hz), > 0.

    Returns
    -------
    RunLog
        Samples at ``t[0] + k / rate_hz`` for every ``k`` with the time inside
        the original span; every channel interpolated linearly (discrete
        channels such as ``pulses`` too). ``sample_rate_hz`` is set to
        ``rate_hz`` and ``resampled`` records the original sample count and
        the rule. A fixed-rate loop whose stamps only jitter (no gap, every
        step within half a period of the nominal one) at ``rate_hz`` keeps its
        samples and is restamped on the uniform grid instead: interpolating
        between jittered stamps would distort samples taken on time.
    """
    import numpy as np

    from ilic_cli.quality import nominal_rate_hz  # deferred: numpy
    from ilic_cli.runlog import RunLog  # deferred: numpy

    t = log.t
    nominal = nominal_rate_hz(t)
    if nominal and abs(nominal - rate_hz) <= 5e-4 * rate_hz and np.all(np.abs(np.diff(t) * nominal - 1.0) < 0.5):
        meta = dict(log.meta)
        meta["sample_rate_hz"] = float(rate_hz)
        meta["resampled"] = {"method": "restamped (stamp jitter of a fixed-rate loop)", "from_samples": len(log), "rate_hz": float(rate_hz)}
        grid = t[0] + np.arange(len(t), dtype=np.float64) / rate_hz
        return RunLog({**log.channels, "t": grid}, dict(log.units), meta)
    span = float(t[-1] - t[0])
    count = int(np.floor(span * rate_hz * (1 + 1e-12))) + 1
    if count < 2:
        raise LogError(log.meta.get("source"), f"--resample {rate_hz:g} Hz leaves fewer than two samples in {span:.6g} s")
    if count > 100_000_000:
        raise LogError(log.meta.get("source"), f"--resample {rate_hz:g} Hz would make {count} samples; choose a lower rate")
    grid = t[0] + np.arange(count, dtype=np.float64) / rate_hz
    grid[-1] = min(grid[-1], t[-1])
    channels = {name: (grid if name == "t" else np.interp(grid, t, values)) for name, values in log.channels.items()}
    meta = dict(log.meta)
    meta["sample_rate_hz"] = float(rate_hz)
    meta["resampled"] = {"method": "linear", "from_samples": len(log), "rate_hz": float(rate_hz)}
    return RunLog(channels, dict(log.units), meta)


@click.command("convert", help="Convert a log between .mat, CSV, MCAP, ROS 1 .bag and ROS 2 bag folders.")
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
    from ilic_cli.quality import assess_log  # deferred: numpy; `ilic convert --help` stays instant

    if same_path(source, target):
        raise LogError(target, "output would overwrite the input; choose another output path")
    fmt = detect_format(target, out_format, for_writing=True)
    log = load(source, input_format, topic, ref_topic, joint, columns)
    if resample_hz is not None:
        log = resample(log, resample_hz)
    else:
        report = assess_log(log)
        if report.irregular:
            note(
                f"ilic: warning: {source}: irregular sampling kept ({report.gaps} gap(s), jitter {100 * report.jitter:.3g} %); "
                "use --resample HZ for a uniform grid"
            )
    options = WriteOptions(storage=storage, joint=joint or "axis")
    write_log(log, target, fmt, options, inputs=(source,))
    rate = log.meta.get("sample_rate_hz")
    rate_text = f" at {float(rate):g} Hz" if isinstance(rate, (int, float)) else ""
    note(f"ilic: wrote {target} ({fmt}): {len(log)} samples{rate_text}, {log.duration_s:.6g} s, channels {', '.join(log.channels)}")
