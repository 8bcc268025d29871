"""CSV run logs: one header row of channel names, one row per sample.

Layout::

    # units: t=s, q=m, tau=N
    # meta: {"sample_rate_hz": 1000.0, "drive_gain": 35.15}
    t,q,tau
    0.0,7.45e-06,89.2
    ...

Both comment lines are optional when reading (units then default, and the
nominal sample rate is derived from ``t``). Values are written with Python's
``repr`` (the shortest text that reads back to the same float64), so a
write/read round trip is exact. Any text that is not a number is refused with
its row (file line) and column.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io.rosjson import dump_json, meta_for_writing, parse_json_object

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions
    from ilic_cli.runlog import RunLog

UNITS_PREFIX = "# units:"
META_PREFIX = "# meta:"


def _parse_units(text: str, path: Path, line: int) -> dict[str, str]:
    units: dict[str, str] = {}
    body = text.strip()
    if not body:
        return units
    for item in body.split(","):
        name, sep, unit = item.partition("=")
        if not sep or not name.strip():
            raise LogError(path, f"line {line}: units entry '{item.strip()}' is not NAME=UNIT")
        units[name.strip()] = unit.strip()
    return units


def read(path: Path, selection: Selection) -> RunLog:
    """Read a CSV log.

    Parameters
    ----------
    path : Path
        The CSV file.
    selection : Selection
        Ignored (a CSV file holds one axis).

    Returns
    -------
    RunLog
    """
    from ilic_cli.quality import nominal_rate_hz
    from ilic_cli.runlog import RunLog

    try:
        text = path.read_text(encoding="utf-8-sig")  # tolerate a byte-order mark (Excel)
    except UnicodeDecodeError as exc:
        raise LogError(path, f"not a UTF-8 text file (byte {exc.start})") from None
    lines = text.splitlines()
    units: dict[str, str] = {}
    meta: dict[str, Any] | None = None
    index = 0
    while index < len(lines) and (lines[index].startswith("#") or not lines[index].strip()):
        line = lines[index]
        if line.startswith(UNITS_PREFIX):
            units = _parse_units(line[len(UNITS_PREFIX) :], path, index + 1)
        elif line.startswith(META_PREFIX):
            meta = parse_json_object(line[len(META_PREFIX) :], path, f"line {index + 1}: metadata")
        index += 1
    if index >= len(lines):
        raise LogError(path, "no header row with channel names")
    header_line = index + 1
    try:
        rows = list(csv.reader(io.StringIO("\n".join(lines[index:]))))
    except csv.Error as exc:
        raise LogError(path, f"not valid CSV ({exc})") from None
    header = [name.strip() for name in rows[0]]
    if any(not name for name in header):
        raise LogError(path, f"line {header_line}: empty column name in the header")
    dupes = sorted({name for name in header if header.count(name) > 1})
    if dupes:
        raise LogError(path, f"line {header_line}: duplicated column(s) {', '.join(dupes)}")
    width = len(header)
    columns: list[list[float]] = [[] for _ in header]
    for offset, row in enumerate(rows[1:], start=1):
        line_no = header_line + offset
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        if len(row) != width:
            raise LogError(path, f"row at line {line_no} has {len(row)} fields, the header has {width}")
        for j, cell in enumerate(row):
            try:
                columns[j].append(float(cell))
            except ValueError:
                shown = cell.strip()[:40] or "(empty)"
                raise LogError(path, f"row at line {line_no}, column '{header[j]}': '{shown}' is not a number") from None
    channels = {name: np.asarray(values, dtype=np.float64) for name, values in zip(header, columns)}
    if meta is None:
        meta = {}
        if "t" in channels:
            rate = nominal_rate_hz(channels["t"])
            if rate:
                meta["sample_rate_hz"] = rate
    return RunLog(channels, {k: v for k, v in units.items() if k in channels}, meta)


def _check_unit(name: str, unit: str) -> None:
    if any(ch in unit for ch in ",=\n\r") or any(ch in name for ch in ",=\n\r\""):
        raise LogError(None, f"channel '{name}' with unit '{unit}' cannot be written to CSV (',', '=' or line breaks)")


def write(log: RunLog, path: Path, options: WriteOptions) -> None:
    """Write ``log`` as CSV with a units line and a metadata line.

    Parameters
    ----------
    log : RunLog
        The log to write.
    path : Path
        Destination file (a temporary path chosen by ``write_log``).
    options : WriteOptions
        Unused.
    """
    names = list(log.channels)
    for name in names:
        _check_unit(name, log.units.get(name, ""))
    out = io.StringIO()
    out.write(UNITS_PREFIX + " " + ", ".join(f"{n}={log.units.get(n, '')}" for n in names) + "\n")
    out.write(META_PREFIX + " " + dump_json(meta_for_writing(log.meta)) + "\n")
    out.write(",".join(names) + "\n")
    columns = [list(map(repr, log.channels[n].tolist())) for n in names]
    for row in zip(*columns):
        out.write(",".join(row))
        out.write("\n")
    path.write_text(out.getvalue(), encoding="utf-8", newline="\n")
