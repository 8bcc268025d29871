"""CSV run logs: one header row of channel names, one row per sample.

Layout::

    # units: t=s, q=m, tau=N
    # meta: {"sample_rate_hz": 1000.0, "drive_gain": 35.15}
    t,q,tau
    0.0,7.45e-06,89.2
    ...

Both comment lines are optional when reading (units then default, and the
nominal sample rate is derived from ``t``). Values are written as Python's
``repr`` writes them (the shortest text that reads back to the same float64;
the compiled formatter :mod:`ilic_cli.io.floattext` writes the same bytes), so
a write/read round trip is exact. Any text that is not a number is refused with
its row (file line) and column.

Reading parses the rows with pandas' C parser when the file below its header
holds nothing but plain numbers (:func:`_read_fast`, about 2x the file size in
memory); every other file, and every bad one, is read row by row with the
``csv`` module (``fast=False`` always is), which words the errors.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io.rosjson import dump_json, meta_for_writing, parse_json_object
from ilic_cli.runlog import RunLog
from ilic_cli.timebase import TIME_UNITS, nominal_rate_hz, time_unit

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions

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


def read(path: Path, selection: Selection, *, fast: bool = True) -> RunLog:
    """Read a CSV log.

    Parameters
    ----------
    path : Path
        The CSV file.
    selection : Selection
        ``selection.columns`` names the columns of the standard channels (a
        CSV file holds one axis; its topics and joints do not apply).
    fast : bool
        Parse the rows with pandas' C parser (:func:`_read_fast`); a file it
        does not take is read row by row, which also words every error.
        False: row by row only.

    Returns
    -------
    RunLog
    """
    if fast:
        log = _read_fast(path, dict(selection.columns))
        if log is not None:
            return log
    return _read_rows(path, dict(selection.columns))


DATA_BYTES = b"0123456789.+-eE\r\n"
"""The only bytes the fast reader accepts below the header row besides the delimiter (anything else: row by row)."""

DELIMITERS = (",", ";", "\t")
"""Field delimiters a CSV may use; the header row's most frequent one is taken."""

ALIASES: dict[str, tuple[str, ...]] = {
    "t": (
        "t",
        "time",
        "timestamp",
        "stamp",
        "t_s",
        "time_s",
        "t_ms",
        "time_ms",
        "t_us",
        "time_us",
        "t_ns",
        "time_ns",
        "timestamp_ns",
        "timestamp_us",
        "timestamp_ms",
    ),
    "q": ("q", "position", "pos", "q_meas", "position_measured", "actual_position"),
    "qd": ("qd", "velocity", "vel", "velocity_measured", "actual_velocity"),
    "tau": ("tau", "effort", "torque", "force", "current", "effort_measured", "actual_effort"),
    "q_ref": ("q_ref", "reference", "ref", "position_ref", "reference_position", "setpoint", "desired_position", "position_desired", "qg"),
}
"""Column names (any case) recognised for each standard channel of a CSV not written by ilic; ``--columns`` names any other."""


def _delimiter(header: str) -> str:
    """The header row's most frequent delimiter (``,`` when it has none)."""
    return max(DELIMITERS, key=lambda d: (header.count(d), d == ","))


_BLOCK = 1 << 24


def _top_lines(stream: Any) -> tuple[list[str], int] | None:
    """Comment and blank lines, then the header row: their text, and the offset after the header.

    None when a line is not plain UTF-8 text ending in ``\n`` (the row-by-row
    reader words the problem).
    """
    lines: list[str] = []
    while True:
        raw = stream.readline()
        if not raw:
            return None  # no header row
        if not lines and raw.startswith(b"\xef\xbb\xbf"):
            raw = raw[3:]
        body = raw[:-1] if raw.endswith(b"\n") else raw
        if body.endswith(b"\r"):
            body = body[:-1]
        try:
            line = body.decode("utf-8")
        except UnicodeDecodeError:
            return None
        if line and line.splitlines() != [line]:
            return None  # other line breaks (\r, \v, U+2028...) inside
        lines.append(line)
        if not (line.startswith("#") or not line.strip()):
            return lines, stream.tell()


def _read_fast(path: Path, columns: dict[str, str]) -> RunLog | None:
    """Read a CSV log with ``pandas.read_csv(engine="c")``; None when the file needs the row-by-row reader.

    The comment lines and the header row are read as :func:`_read_rows` does.
    Below the header only :data:`DATA_BYTES` may occur (no quotes, spaces,
    text, NaN or infinity words), every row must have the header's number of
    fields and every field must be a number: then pandas' values are the
    ones ``float`` gives. Any other file (including every bad one) returns
    None, so that errors keep their wording.
    """
    import pandas as pd  # pandas (some 0.6 s) deferred: only a file the NumPy parser does not take

    with open(path, "rb") as stream:
        top = _top_lines(stream)
        if top is None:
            return None
        lines, data_at = top
        units: dict[str, str] = {}
        meta: dict[str, Any] | None = None
        try:
            for number, line in enumerate(lines[:-1], start=1):
                if line.startswith(UNITS_PREFIX):
                    units = _parse_units(line[len(UNITS_PREFIX) :], path, number)
                elif line.startswith(META_PREFIX):
                    meta = parse_json_object(line[len(META_PREFIX) :], path, f"line {number}: metadata")
        except LogError:
            return None
        header_text = lines[-1]
        if '"' in header_text or "\x00" in header_text:
            return None
        sep = _delimiter(header_text)
        header = [name.strip() for name in header_text.split(sep)]
        if any(not name for name in header[1:]) or len(set(header)) != len(header):
            return None
        allowed = DATA_BYTES + sep.encode()
        while True:
            block = stream.read(_BLOCK)
            if not block:
                break
            if block.translate(None, allowed):
                return None
        stream.seek(data_at)
        try:
            frame = pd.read_csv(
                stream, header=None, sep=sep, dtype=np.float64, engine="c", na_filter=False, keep_default_na=False, skip_blank_lines=True, quoting=3
            )
        except MemoryError:
            raise LogError(path, "CSV content needs more memory than available") from None
        except Exception:  # noqa: BLE001 - any parser complaint: the row-by-row reader words it
            return None
    if frame.shape[1] != len(header) or len(frame) == 0:
        return None
    values = frame.to_numpy(dtype=np.float64, copy=False)
    del frame
    if np.isnan(values).any():
        return None
    channels = {name: np.ascontiguousarray(values[:, j]) for j, name in enumerate(header)}
    del values
    return _log(channels, units, meta, path, columns)


def _read_rows(path: Path, columns: dict[str, str]) -> RunLog:
    """Read a CSV log row by row with the ``csv`` module (every check, every error worded)."""

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
        rows = list(csv.reader(io.StringIO("\n".join(lines[index:])), delimiter=_delimiter(lines[index])))
    except csv.Error as exc:
        raise LogError(path, f"not valid CSV ({exc})") from None
    header = [name.strip() for name in rows[0]]
    if any(not name for name in header[1:]) or (not header[0] and len(header) == 1):
        raise LogError(path, f"line {header_line}: empty column name in the header")
    dupes = sorted({name for name in header if header.count(name) > 1})
    if dupes:
        raise LogError(path, f"line {header_line}: duplicated column(s) {', '.join(dupes)}")
    width = len(header)
    fields: list[list[float]] = [[] for _ in header]
    for offset, row in enumerate(rows[1:], start=1):
        line_no = header_line + offset
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        if len(row) != width:
            raise LogError(path, f"row at line {line_no} has {len(row)} fields, the header has {width}")
        for j, cell in enumerate(row):
            try:
                fields[j].append(float(cell))
            except ValueError:
                shown = cell.strip()[:40] or "(empty)"
                raise LogError(path, f"row at line {line_no}, column '{header[j]}': '{shown}' is not a number") from None
    channels = {name: np.asarray(values, dtype=np.float64) for name, values in zip(header, fields)}
    return _log(channels, units, meta, path, columns)


def _log(channels: dict[str, np.ndarray], units: dict[str, str], meta: dict[str, Any] | None, path: Path, columns: dict[str, str]) -> RunLog:
    """The log of parsed columns; a CSV without ilic's metadata line is read by the stated rules.

    * an index column (an empty first column name, pandas' ``to_csv``
      default, or ``Unnamed: 0``) counting 0, 1, 2, ... is dropped;
    * the standard channels come from the columns ``columns`` names
      (``--columns``), else from the first name of :data:`ALIASES` present
      (any case); the choice is recorded in ``meta["columns"]``;
    * the time is in seconds: the declared unit (``# units: t=ns`` or a name
      such as ``time_ns``) or :func:`ilic_cli.timebase.time_unit`'s (the rule is
      recorded in ``meta["time_unit"]``).

    ilic's own CSV files keep their names, and are in seconds.
    """
    first = next(iter(channels), None)
    if first is not None and (first == "" or first.startswith("Unnamed:")):
        index = channels.pop(first)
        if not np.array_equal(index, np.arange(len(index), dtype=np.float64)):
            raise LogError(path, "the first column has no name and does not count 0, 1, 2, ...: name it")
    if meta is not None:
        return RunLog(channels, {k: v for k, v in units.items() if k in channels}, meta)
    meta = {}
    unknown = sorted(set(columns) - set(ALIASES))
    if unknown:
        raise LogError(path, f"no standard channel '{unknown[0]}' to map a column to (channels: {', '.join(ALIASES)})")
    lower = {name.lower(): name for name in channels}
    chosen: dict[str, str] = {}
    for channel, aliases in ALIASES.items():
        if channel in columns:
            if columns[channel] not in channels:
                raise LogError(path, f"no column '{columns[channel]}' for {channel} (columns: {', '.join(channels)})")
            chosen[channel] = columns[channel]
        elif channel not in channels:
            found = next((lower[a] for a in aliases if a in lower), None)
            if found is not None and found not in chosen.values():
                chosen[channel] = found
    renamed = {channel: channels.pop(name) for channel, name in chosen.items()}
    for channel, name in chosen.items():
        if name in units:
            units[channel] = units.pop(name)
    channels = {**renamed, **channels}
    if chosen:
        meta["columns"] = {channel: name for channel, name in chosen.items() if channel != name}
    if "t" in channels:
        declared = units.get("t") or _unit_in_name(chosen.get("t", ""))
        try:
            unit, rule = time_unit(channels["t"], declared)
        except ValueError as exc:
            raise LogError(path, str(exc)) from None
        if unit != "s":
            channels["t"] = channels["t"] * TIME_UNITS[unit]
        units = {**units, "t": "s"}
        meta["time_unit"] = {"unit": unit, "rule": rule}
        rate = nominal_rate_hz(channels["t"])
        if rate:
            meta["sample_rate_hz"] = rate
    return RunLog(channels, {k: v for k, v in units.items() if k in channels}, meta)


def _unit_in_name(name: str) -> str | None:
    """``ns`` for a column named ``time_ns`` (and ``us``, ``ms``, ``s``)."""
    suffix = name.lower().rsplit("_", 1)[-1] if "_" in name else ""
    return suffix if suffix in TIME_UNITS else None


def _check_unit(name: str, unit: str) -> None:
    if any(ch in unit for ch in ",=\n\r") or any(ch in name for ch in ',=\n\r"'):
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
        ``options.fast`` (default True) lays out blocks of rows with the
        compiled formatter (:mod:`ilic_cli.io.floattext`); False joins
        Python's ``repr`` of the values row by row. Both write the same bytes
        (tested).
    """
    names = list(log.channels)
    for name in names:
        _check_unit(name, log.units.get(name, ""))
    head = UNITS_PREFIX + " " + ", ".join(f"{n}={log.units.get(n, '')}" for n in names) + "\n"
    head += META_PREFIX + " " + dump_json(meta_for_writing(log.meta)) + "\n"
    head += ",".join(names) + "\n"
    if getattr(options, "fast", True):
        _write_rows(path, head, [np.asarray(log.channels[n], dtype=np.float64) for n in names], len(log))
        return
    out = io.StringIO()
    out.write(head)
    columns_text = [list(map(repr, log.channels[n].tolist())) for n in names]
    for row in zip(*columns_text):
        out.write(",".join(row))
        out.write("\n")
    path.write_text(out.getvalue(), encoding="utf-8", newline="\n")


ROWS_PER_BLOCK = 32768
"""Rows laid out at once by the fast writer (a buffer of some 25 bytes a value)."""


def _write_rows(path: Path, head: str, columns: list[np.ndarray], n: int) -> None:
    """``head``, then the rows of ``columns`` laid out by :func:`ilic_cli.io.floattext.csv_rows`, a block of rows at a time in one reused buffer."""
    from ilic_cli.io.floattext import csv_rows  # deferred: numba, only when a CSV file is written

    buffer = None
    with open(path, "wb") as stream:
        stream.write(head.encode("utf-8"))
        for start in range(0, n, ROWS_PER_BLOCK):
            buffer, length = csv_rows(columns, start, min(n, start + ROWS_PER_BLOCK), buffer)
            stream.write(buffer[:length].data)
