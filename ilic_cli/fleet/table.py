"""The batch table: one row per log x joint x method x window, as Parquet (pyarrow) and CSV.

Columns, in this order and of these types whatever the batch held:

==========================  =========  =============================================================
``log``                     string     the log's path as the batch was given it
``content_hash``            string     the key of its document (content, settings, version)
``machine``, ``joint``      string     from ``--group-by`` on the path, else the log's metadata
``start_time``              timestamp  UTC, ns (the log's ``start_time_ns`` or ``--group-by`` start)
``joint_type``              string     ``prismatic`` or ``revolute``: the parameters' units
``method``                  string     ``IDIM-LS``, ``IDIM-ILIC``, ``DIDIM``, ``IDIM-IV``
``window``                  int64      the IDIM-ILIC window k; 0 for a whole-log estimate
``t_start_s``, ``t_end_s``  float64    the window's span (NaN for a whole-log estimate)
P, ``P_std``, ``P_rel_std_pct``  float64    each parameter P of the structure, σ and %σ
``relative_error_pct``      float64    ‖Y − Wθ̂‖/‖Y‖ of the estimate
``findings``                string     the diagnosis's effect ids, comma-separated; ``none``; ``undecided`` when nothing is
                                       found and a proposal could not be judged; null without ``--diagnose``
``not_judged``              string     the effect ids proposed that no replay could judge (their fit is no plant),
                                       comma-separated; ``none``; null without ``--diagnose``
``status``                  string     ``ok`` or ``error``
``error``                   string     why the log gave no estimate (or why the diagnosis failed)
==========================  =========  =============================================================

A failed log is one row with ``status = error``. Rows are sorted by (machine,
joint, start time, log, method, window): the table is the same bytes wherever
and in whatever order its logs were computed. A whole-log estimate's window is
0, not null, so every column's type is the same in every table.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ilic_cli import parameters
from ilic_cli.errors import IlicError
from ilic_cli.fleet.batch import BatchResult, path_groups
from ilic_cli.io.atomic import atomic_path, atomic_write_text

METHOD_ORDER = ("IDIM-LS", "IDIM-ILIC", "DIDIM", "IDIM-IV")
STRING_COLUMNS = ("log", "content_hash", "machine", "joint")
TABLE_NAME = "table"
"""``OUT/table.parquet`` and ``OUT/table.csv``."""


def columns(structure: str) -> list[tuple[str, str]]:
    """``(name, type)`` of every column for ``structure`` (types: string, timestamp, int64, float64)."""
    cols = [(c, "string") for c in STRING_COLUMNS]
    cols += [("start_time", "timestamp"), ("joint_type", "string"), ("method", "string"), ("window", "int64"), ("t_start_s", "float64"), ("t_end_s", "float64")]
    for name in parameters.structure_names(structure):
        cols += [(name, "float64"), (f"{name}_std", "float64"), (f"{name}_rel_std_pct", "float64")]
    cols += [("relative_error_pct", "float64"), ("findings", "string"), ("not_judged", "string"), ("status", "string"), ("error", "string")]
    return cols


def _float(x: Any) -> float:
    return float("nan") if x is None else float(x)


def rows(result: BatchResult, structure: str, group_by: Any = None) -> list[dict[str, Any]]:
    """The table's rows, sorted: every log's estimates, or its error (``group_by``: a compiled ``--group-by``)."""
    names = parameters.structure_names(structure)
    out: list[dict[str, Any]] = []
    for path, key in zip(result.logs, result.keys):
        doc = result.documents[key]
        groups, group_error = path_groups(group_by, path)
        meta = {**doc["meta"], **groups}
        base = {
            "log": path.as_posix(),
            "content_hash": key,
            "machine": meta.get("machine"),
            "joint": meta.get("joint"),
            "start_time": meta.get("start_time_ns"),
            "joint_type": meta.get("joint_type"),
        }
        error = group_error or doc["error"]
        findings, not_judged = _diagnosed(doc)
        diag_error = next((w for w in doc["warnings"] if w.startswith("diagnose: ")), None)
        if error is not None or not doc["estimates"]:
            out.append(_row(base, names, None, None, None, "error", error or f"{path}: no estimate"))
            continue
        for est in doc["estimates"]:
            out.append(_row(base, names, est, findings, not_judged, "ok", diag_error))
    out.sort(key=_sort_key)
    return out


def _diagnosed(doc: dict[str, Any]) -> tuple[str | None, str | None]:
    """The ``findings`` and ``not_judged`` cells of a log's document (``None``: not diagnosed).

    A log whose diagnosis found nothing but could not judge a proposal is ``undecided``, not ``none``: its conclusion is
    "undecided" (:attr:`ilic_cli.diagnosis.Diagnosis.conclusion`), and a fleet filtered on ``none`` takes it for a clean log.
    A document a batch stored before ``not_judged`` was kept does not say: its ``not_judged`` is null."""
    if doc["findings"] is None:
        return None, None
    pending = doc.get("not_judged")
    found = ",".join(doc["findings"])
    if pending is None:
        return found or "none", None
    return found or ("undecided" if pending else "none"), ",".join(pending) or "none"


def _row(
    base: dict[str, Any], names: tuple[str, ...], est: dict[str, Any] | None, findings: str | None, not_judged: str | None, status: str, error: str | None
) -> dict[str, Any]:
    row = dict(base)
    row["method"] = None if est is None else est["method"]
    row["window"] = 0 if est is None else int(est["window"])
    row["t_start_s"] = _float(None if est is None else est["t_start"])
    row["t_end_s"] = _float(None if est is None else est["t_end"])
    for n in names:
        v, s, p = est["parameters"].get(n, (None, None, None)) if est is not None else (None, None, None)
        row[n], row[f"{n}_std"], row[f"{n}_rel_std_pct"] = _float(v), _float(s), _float(p)
    row["relative_error_pct"] = _float(None if est is None else est["relative_error_pct"])
    row["findings"], row["not_judged"], row["status"], row["error"] = findings, not_judged, status, error
    return row


def _sort_key(row: dict[str, Any]) -> tuple[Any, ...]:
    def text(x: str | None) -> tuple[int, str]:
        return (x is None, x or "")

    method = row["method"]
    rank = METHOD_ORDER.index(method) if method in METHOD_ORDER else len(METHOD_ORDER)
    start = row["start_time"]
    return (text(row["machine"]), text(row["joint"]), (start is None, start or 0), row["log"], rank, text(method), row["window"])


def format_time(ns: int | None) -> str:
    """``2026-01-05T08:00:00Z`` (fractional seconds when there are any, to the ns); empty for none."""
    if ns is None:
        return ""
    seconds, frac = divmod(int(ns), 10**9)
    text = datetime.fromtimestamp(seconds, tz=UTC).strftime("%Y-%m-%dT%H:%M:%S")
    return text + (f".{frac:09d}".rstrip("0") if frac else "") + "Z"


def to_csv(table: Sequence[dict[str, Any]], structure: str) -> str:
    """CSV text: floats in their shortest exact form (``repr``), NaN and null as empty fields, times in ISO 8601 UTC."""
    cols = columns(structure)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([c for c, _ in cols])
    for row in table:
        out = []
        for c, kind in cols:
            v = row[c]
            if kind == "timestamp":
                out.append(format_time(v))
            elif kind == "float64":
                out.append("" if math.isnan(v) else repr(v))
            else:
                out.append("" if v is None else str(v))
        w.writerow(out)
    return buf.getvalue()


def write_parquet(table: Sequence[dict[str, Any]], structure: str, target: Path) -> None:
    """Write the table as Parquet with fixed column types (pyarrow), atomically."""
    # deferred: pyarrow takes ~0.2 s to import, and only writing or reading a table needs it
    import pyarrow as pa
    import pyarrow.parquet as pq

    types = {"string": pa.string(), "timestamp": pa.timestamp("ns", tz="UTC"), "int64": pa.int64(), "float64": pa.float64()}
    cols = columns(structure)
    schema = pa.schema([(c, types[k]) for c, k in cols], metadata={"ilic.structure": structure, "ilic.units": _units_json(structure)})
    arrays = [pa.array([row[c] for row in table], type=types[k]) for c, k in cols]
    with atomic_path(target) as tmp:
        pq.write_table(pa.Table.from_arrays(arrays, schema=schema), tmp)


def _units_json(structure: str) -> str:
    return json.dumps({jt: {n: parameters.unit(n, jt) for n in parameters.structure_names(structure)} for jt in ("prismatic", "revolute")}, sort_keys=True)


def write_table(result: BatchResult, structure: str, group_by: Any = None) -> list[Path]:
    """Write ``OUT/table.parquet`` and ``OUT/table.csv``; return their paths."""
    table = rows(result, structure, group_by)
    pq_path = result.out_dir / f"{TABLE_NAME}.parquet"
    csv_path = result.out_dir / f"{TABLE_NAME}.csv"
    write_parquet(table, structure, pq_path)
    atomic_write_text(csv_path, to_csv(table, structure))
    return [pq_path, csv_path]


def read_table(path: Path) -> Any:
    """A batch table (Parquet, or the CSV) as a pandas DataFrame with the table's column types."""
    # deferred: pandas and pyarrow, only for reading a table
    import pandas as pd

    try:
        if path.suffix.lower() == ".parquet":
            frame = pd.read_parquet(path)
        else:
            # deferred: pyarrow's CSV reader (pyarrow takes ~0.2 s to import), only for a CSV table
            import pyarrow as pa
            import pyarrow.csv as pacsv

            # pyarrow's parser reads every float back exactly (the shortest repr the table was written with)
            types = {c: pa.string() for c in (*STRING_COLUMNS, "joint_type", "method", "findings", "not_judged", "status", "error")}
            types["start_time"] = pa.timestamp("ns", tz="UTC")
            frame = pacsv.read_csv(path, convert_options=pacsv.ConvertOptions(column_types=types, strings_can_be_null=True)).to_pandas()
    except FileNotFoundError:
        raise IlicError(path, "no such table") from None
    except Exception as exc:  # a file that is not a table (pyarrow and pandas raise their own kinds)
        raise IlicError(path, f"not a batch table: {type(exc).__name__}: {exc}") from None
    missing = [c for c in ("machine", "joint", "start_time", "method", "status", "joint_type") if c not in frame.columns]
    if missing:
        raise IlicError(path, f"not a batch table (no column {', '.join(missing)})")
    return frame
