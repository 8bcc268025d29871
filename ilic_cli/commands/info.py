"""``ilic info``: what is in a log, and whether it is fit for identification."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ilic_cli.commands.common import input_options, load
from ilic_cli.commands.robot import info_options
from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io import bag_folder, detect_format
from ilic_cli.io.overview import overview

if TYPE_CHECKING:
    from ilic_cli.runlog import RunLog


def summarize(log: RunLog, path: str | Path, fmt: str) -> dict[str, Any]:
    """Return the facts ``ilic info`` reports, as a JSON-serialisable dict.

    Parameters
    ----------
    log : RunLog
        The log that was read.
    path : str or Path
        The file it came from.
    fmt : str
        Its format name.

    Returns
    -------
    dict
        ``file``, ``format``, ``samples``, ``duration_s``, ``sample_rate_hz``,
        ``channels`` (name, unit, min, max), ``drive_gain``, ``controller``,
        ``scenario``, ``true_parameters``, ``joint``, ``meta`` (the rest) and
        ``quality`` (:meth:`QualityReport.to_dict`).
    """
    from ilic_cli.prepare import drive_command  # deferred: numpy; `ilic info --help` stays instant
    from ilic_cli.quality import assess_log  # deferred: numpy
    from ilic_cli.timebase import nominal_rate_hz  # deferred: numpy; `ilic info --help` stays instant

    meta = log.meta  # shown as recorded (the typed views normalise; a report quotes the file)
    rate = log.sensor.sample_rate_hz
    if rate is None or not rate > 0:
        rate = nominal_rate_hz(log.t)
    channels = [
        {"name": name, "unit": log.units.get(name, ""), "min": float(values.min()), "max": float(values.max())} for name, values in log.channels.items()
    ]
    shown = {"sample_rate_hz", "drive_gain", "controller", "scenario", "true_parameters", "joint", "source"}
    return {
        "file": str(path),
        "format": fmt,
        "samples": len(log),
        "duration_s": log.duration_s,
        "sample_rate_hz": float(rate) if rate else None,
        "channels": channels,
        "drive_gain": meta.get("drive_gain"),
        "controller": meta.get("controller"),
        "scenario": meta.get("scenario"),
        "true_parameters": meta.get("true_parameters"),
        "joint": meta.get("joint"),
        "meta": {k: v for k, v in meta.items() if k not in shown},
        "quality": assess_log(log, drive_command(log)).to_dict(),
    }


def _num(value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return f"{value:.6g}"


def _rate_text(rate: float | None) -> str:
    if not rate:
        return "unknown"
    if rate >= 1000 and rate % 1000 == 0:
        return f"{rate:g} Hz ({rate / 1000:g} kHz, nominal)"
    return f"{rate:.6g} Hz (nominal)"


def _mapping(value: Any) -> str:
    if isinstance(value, dict):
        return ", ".join(f"{k}={_num(v) if not isinstance(v, (dict, list)) else v}" for k, v in value.items())
    return str(value)


def render_markdown(summary: dict[str, Any]) -> str:
    """Render :func:`summarize` output as Markdown text."""
    lines = [f"# {summary['file']}", ""]
    gain = summary["drive_gain"]
    lines += [
        f"- format: {summary['format']}",
        f"- samples: {summary['samples']}",
        f"- duration: {summary['duration_s']:.6g} s",
        f"- sample rate: {_rate_text(summary['sample_rate_hz'])}",
        f"- drive gain: {_num(gain) + ' N/V' if gain is not None else 'unknown'}",
        f"- controller: {_mapping(summary['controller']) if summary['controller'] else 'unknown'}",
    ]
    if summary["joint"]:
        lines.append(f"- joint: {summary['joint']}")
    if summary["scenario"] is not None:
        lines.append(f"- scenario: {_mapping(summary['scenario'])}")
    if summary["true_parameters"] is not None:
        lines.append(f"- true parameters: {_mapping(summary['true_parameters'])}")
    topics = _topics_markdown(summary.get("topics") or [])
    if topics:
        lines += ["", *topics]
    lines += ["", "## Channels", "", "| channel | unit | min | max |", "| --- | --- | --- | --- |"]
    for ch in summary["channels"]:
        lines.append(f"| {ch['name']} | {ch['unit']} | {_num(ch['min'])} | {_num(ch['max'])} |")
    q = summary["quality"]
    lines += ["", "## Data quality", ""]
    lines.append(f"- steps: median {_num(q['median_step_s'])} s, max {_num(q['max_step_s'])} s, jitter {100 * q['jitter']:.3g} %")
    lines.append(f"- gaps: {q['gaps']} (about {q['dropped_samples']} dropped samples)")
    if q["saturation_share"] is not None:
        state = f"saturated at +/-{_num(q['saturation_limit'])}" if q["saturation_limit"] is not None else "not saturated"
        lines.append(f"- drive command: {state} ({100 * q['saturation_share']:.3g} % of samples at max |vir|)")
    lines.append(f"- frozen sensor runs: {len(q['frozen_runs'])}")
    warnings = [f["message"] for f in q["findings"] if f["severity"] == "warning"]
    if warnings:
        lines += ["", "Warnings:"] + [f"- {w}" for w in warnings]
    else:
        lines.append("- no problems found")
    return "\n".join(lines) + "\n"


@click.command("info", help="Summarise a log: duration, rate, channels, ranges, drive gain, data quality.")
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=Path))
@click.option("--format", "out_format", type=click.Choice(["md", "json"]), default="md", show_default=True, help="Markdown text or JSON (JSON only on stdout).")
@input_options
@info_options
def command(
    log_path: Path, out_format: str, input_format: str | None, topic: str | None, ref_topic: str | None, joint: str | None, columns: str | None
) -> None:
    """Print the summary of LOG on stdout."""
    fmt = detect_format(log_path, input_format)
    try:
        log = load(log_path, input_format, topic, ref_topic, joint, columns)
    except ChoiceError as exc:  # the container parsed; which of its topics or joints is for the user to say
        if exc.choice == "joint" and _joints_listed(log_path, input_format, fmt, out_format):
            return
        topics = _overview(log_path, input_format, fmt)
        topic_rows = [t.to_dict() for t in topics]
        summary = {"file": str(log_path), "format": fmt, "topics": topic_rows, "choose": exc.message()}
        if out_format == "json":
            click.echo(json.dumps(summary, indent=2, default=_json_default))
        else:
            click.echo("\n".join([f"# {log_path}", "", *_topics_markdown(topic_rows), "", f"Choose: {exc.message()}", ""]), nl=False)
        return
    summary = summarize(log, log_path, fmt)
    summary["topics"] = [t.to_dict() for t in _overview(log_path, input_format, fmt)]
    if out_format == "json":
        click.echo(json.dumps(summary, indent=2, default=_json_default))
    else:
        click.echo(render_markdown(summary), nl=False)


JOINTS_NOTE = "An arm's log of several joints: `identify` and `replay` read it whole with --urdf ARM.urdf, and any command one joint with --joint NAME"


def _joints_listed(path: Path, input_format: str | None, fmt: str, out_format: str) -> bool:
    """Print a JointState log of several joints as an arm's log: its joints, types and ranges, then its topics.

    False when it cannot be read as one (no effort, several JointState topics, a container it does not take): the caller lists the topics to choose from.
    """
    from ilic_cli.commands.robot import info_markdown, joints_summary  # deferred: the n-joint reader only for such a log

    try:
        summary = joints_summary(path, None, None)
    except LogError:
        return False
    summary["format"] = fmt
    summary["topics"] = [t.to_dict() for t in _overview(path, input_format, fmt)]
    summary["read_as"] = JOINTS_NOTE
    if out_format == "json":
        click.echo(json.dumps(summary, indent=2, default=_json_default))
    else:
        topics = _topics_markdown(summary["topics"])
        click.echo("\n".join([info_markdown(summary).rstrip("\n"), "", f"{JOINTS_NOTE}.", "", *topics]).rstrip("\n") + "\n", nl=False)
    return True


def _overview(path: Path, input_format: str | None, fmt: str) -> list[Any]:
    """The container's topics; none when its summary cannot be listed (the log itself was read: its report stands)."""
    try:
        return overview(bag_folder(Path(path), input_format), fmt)
    except Exception:  # noqa: BLE001 - a damaged summary or index must not hide the report of a readable log
        return []


def _topics_markdown(topics: list[dict[str, Any]]) -> list[str]:
    """The container's topics as a table (none for .mat and CSV)."""
    if not topics:
        return []
    lines = ["## Topics", "", "| topic | type | messages | rate (Hz) | joints |", "| --- | --- | --- | --- | --- |"]
    for t in topics:
        joints = ", ".join(t["joints"]) if t["joints"] else ""
        rate = f"{t['rate_hz']:.4g}" if t["rate_hz"] else ""
        lines.append(f"| {t['topic']} | {t['type']} | {t['count']} | {rate} | {joints} |")
    return lines


def _json_default(obj: Any) -> Any:
    import numpy as np  # numpy (some 0.1 s) deferred: `ilic info --help` imports this module

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return str(obj)
