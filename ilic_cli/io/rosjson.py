"""JSON helpers for metadata and units, shared by every format module."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import LogError


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, (set, frozenset, tuple)):
        return list(obj)
    raise TypeError(f"value of type {type(obj).__name__} cannot be stored as JSON")


def dump_json(obj: Any) -> str:
    """Serialise ``obj`` (metadata, units) to one line of JSON.

    NumPy scalars and arrays become numbers and lists. Raises
    :class:`~ilic_cli.errors.LogError` for values JSON cannot hold.
    """
    try:
        return json.dumps(obj, default=_json_default, ensure_ascii=True)
    except (TypeError, ValueError) as exc:
        raise LogError(None, f"metadata cannot be written: {exc}") from None


def meta_for_writing(meta: Mapping[str, Any]) -> dict[str, Any]:
    """Return the metadata to store in a file: all keys but ``source``.

    ``source`` names the file a log was read from; it is set again on reading.
    """
    return {k: v for k, v in meta.items() if k != "source"}


def parse_json_object(text: str, path: str | Path, what: str) -> dict[str, Any]:
    """Parse ``text`` as a JSON object or raise a one-line :class:`LogError`.

    Parameters
    ----------
    text : str
        The JSON text.
    path : str or Path
        File named in the error.
    what : str
        What the text is (``"metadata"``), for the error message.
    """
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise LogError(path, f"{what} is not valid JSON ({exc})") from None
    if not isinstance(value, dict):
        raise LogError(path, f"{what} is not a JSON object")
    return value


def parse_units(value: Any, path: str | Path) -> dict[str, str]:
    """Check that ``value`` maps channel names to unit strings."""
    if not isinstance(value, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        raise LogError(path, "units must map channel names to strings")
    return dict(value)
