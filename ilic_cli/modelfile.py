"""Model parameter files (``--model PARAMS.json``) shared by identify, simulate, replay and diagnose.

Format written by ``ilic identify --out DIR`` (``DIR/model.json``) and
``ilic diagnose``::

    {"ilic_model": 1, "model": "rigid-offset", "method": "IDIM-LS",
     "parameters": {"M": 95.1089, "Fv": 203.50, "Fc": 20.39, "offset": -3.16},
     "effects": {"stribeck": {"Fs": 5.0, "vs": 0.01}}, "source": "run.mat"}

Also accepted: the JSON printed by ``ilic identify --format json`` (the IDIM-LS
parameters are used) and a flat ``{"M": 95, "Fv": 200, ...}``.

An arm's model file (``ilic identify LOG --urdf ARM.urdf --out DIR``) is the
same document with ``"model": "robot"``, the base parameters as its
``parameters``, and a ``robot`` section: the URDF's path and sha256, the joints,
each base parameter's regrouping of standard parameters, and the friction
(:func:`robot_model_document`; read back by :func:`robot_parameters`, which
refuses a model made for another URDF)::

    {"ilic_model": 1, "model": "robot", "method": "DIDIM",
     "parameters": {"mx_shoulderR": 2.87, ..., "Fv_elbow": 1.25},
     "robot": {"urdf": "fixtures/arm2.urdf", "sha256": "6f1c...", "joints": ["shoulder", "elbow"],
               "base_parameters": [{"name": "mx_shoulderR", "combines": {"mx_shoulder": 1.0, "m_elbow": 0.5}}, ...],
               "friction": {"Fv_shoulder": 2.0, "Fc_shoulder": 3.0, "offset_shoulder": 0.2, ...}},
     "effects": {}, "source": "arm2.csv"}
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ilic_cli.errors import IlicError

MODEL_FILE_VERSION = 1
ROBOT_MODEL = "robot"
"""The ``model`` of an arm's model file."""


def parse_model(doc: Any, where: str | None = None) -> dict[str, Any]:
    """Return ``{"model": str|None, "parameters": {name: float}, "effects": {...}}`` from any accepted layout."""
    if not isinstance(doc, dict):
        raise IlicError(where, "model file must hold a JSON object")
    section = doc
    if "parameters" not in doc:
        for key in ("ls", "idim_ls"):
            if isinstance(doc.get(key), dict) and "parameters" in doc[key]:
                section = doc[key]
                break
    flat = {k: v for k, v in doc.items() if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "ilic_model"}
    params_raw = section.get("parameters", flat if section is doc else None)
    if not isinstance(params_raw, dict) or not params_raw:
        raise IlicError(where, "no 'parameters' in the model file (expected ilic identify output or {\"M\": ..., ...})")
    params: dict[str, float] = {}
    for name, value in params_raw.items():
        if isinstance(value, dict):
            value = value.get("value")
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise IlicError(where, f"parameter '{name}' has no numeric value")
        params[str(name)] = float(value)
    effects = doc.get("effects", {}) or {}
    if not isinstance(effects, dict):
        raise IlicError(where, "'effects' must be an object of effect id -> parameters")
    robot = doc.get("robot")
    if robot is not None and not isinstance(robot, dict):
        raise IlicError(where, "'robot' must be an object (urdf, sha256, joints, base_parameters, friction)")
    parsed = {"model": section.get("model", doc.get("model")), "parameters": params, "effects": effects}
    return parsed | ({"robot": robot} if robot is not None else {})


def load_model_file(path: str | Path) -> dict[str, Any]:
    """Read a model file; :class:`IlicError` (exit 2) for a missing or malformed one."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise IlicError(p, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise IlicError(p, f"cannot read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise IlicError(p, f"not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return parse_model(doc, str(p))


def model_document(
    model: str,
    parameters: dict[str, float],
    *,
    method: str,
    effects: dict[str, Any] | None = None,
    source: str | None = None,
    std: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Build the JSON document of a model file.

    ``std``: standard deviations of the estimates, ``{"parameters": {...}, "effects": {id: {...}}}``
    (written as ``"std"``, which readers other than people ignore).
    """
    doc = {
        "ilic_model": MODEL_FILE_VERSION,
        "model": model,
        "method": method,
        "parameters": {k: float(v) for k, v in parameters.items()},
        "effects": effects or {},
        "source": source,
    }
    if std is not None:
        doc["std"] = std
    return doc


def robot_model_document(
    parameters: dict[str, float],
    *,
    method: str,
    urdf: str,
    sha256: str,
    joints: list[str],
    base_parameters: list[dict[str, Any]],
    friction: dict[str, float | None],
    source: str | None = None,
    std: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """An arm's model file: :func:`model_document` of the base parameters with the ``robot`` section (see the module)."""
    doc = model_document(ROBOT_MODEL, parameters, method=method, source=source, std=std)
    doc["robot"] = {"urdf": urdf, "sha256": sha256, "joints": joints, "base_parameters": base_parameters, "friction": friction}
    return doc


def robot_parameters(model: dict[str, Any], sha256: str, names: tuple[str, ...], where: str | Path) -> list[float]:
    """The base parameters (in ``names``' order) of a parsed arm's model file, if it was made for the URDF of hash ``sha256``."""
    robot = model.get("robot")
    if not robot:
        raise IlicError(where, "not an arm's model file (no 'robot' section; the identification of an arm writes one)")
    if robot.get("sha256") != sha256:
        made = f"{robot.get('urdf')} (sha256 {str(robot.get('sha256'))[:12]})"
        raise IlicError(where, f"made for the URDF {made}, not this one (sha256 {sha256[:12]}): identify again with this URDF")
    missing = [n for n in names if n not in model["parameters"]]
    if missing:
        raise IlicError(where, f"no value for the base parameters {', '.join(missing)}")
    return [model["parameters"][n] for n in names]
