"""The files ``ilic identify LOG --urdf ARM.urdf --out DIR`` writes: report.md, report.json, model.json and one torque plot per joint.

``model.json`` is the one model file format (:func:`ilic_cli.modelfile.robot_model_document`):
the estimate of the method the ``--method`` value names for the model file
(:data:`ilic_cli.method_names.COMPOSITES`' ``model_from``: DIDIM for ``all``,
IDIM-WLS for ``both``), with the URDF's path and sha256. ``ilic replay --urdf``
and ``ilic simulate --urdf`` read it back. The plots
(``torque_<joint>.png``, :func:`ilic_cli.plotting.plot_joint_torques`) show each
joint's measured torque against that estimate's, and their difference, on the
decimated rows IDIM-LS fits.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.commands.common import note
from ilic_cli.errors import IlicError
from ilic_cli.io.atomic import atomic_write_text, same_path
from ilic_cli.jointlog import JointLog, Parts
from ilic_cli.method_names import COMPOSITES

REPORTS = ("report.md", "report.json", "model.json")


def _plots(joints: tuple[str, ...] | list[str], plot_format: str) -> list[str]:
    return [] if plot_format == "none" else [f"torque_{j}.{plot_format}" for j in joints]


def refuse_out(out_dir: Path, inputs: tuple[Path, ...], plot_format: str) -> None:
    """Refuse an ``--out`` that is no folder, or where a report file would replace an input (before any work)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise IlicError(out_dir, "--out must be a folder")
    for target in (out_dir / n for n in REPORTS):
        if target.exists() and any(same_path(src, target) for src in inputs):
            raise IlicError(target, "output would overwrite the input; choose another --out folder")
    for target in out_dir.glob(f"torque_*.{plot_format}") if out_dir.is_dir() else ():
        if any(same_path(src, target) for src in inputs):
            raise IlicError(target, "output would overwrite the input; choose another --out folder")


def model_entry(doc: Mapping[str, Any], method: str) -> tuple[str, Mapping[str, Any]]:
    """The method's name and report entry the model file takes (``--method``'s ``model_from``, else the first run)."""
    labels = {"ls": "IDIM-WLS", "ilic": "IDIM-ILIC", "iv": "IDIM-IV", "didim": "DIDIM"}
    chosen = labels.get(COMPOSITES[method].model_from if method in COMPOSITES else method)
    name = chosen if chosen is not None and chosen in doc["methods"] else str(next(iter(doc["methods"])))
    return name, doc["methods"][name]


def write_identify(
    doc: Mapping[str, Any],
    log: JointLog,
    parts: Parts,
    robot: Any,
    base: Any,
    out_dir: Path,
    settings: tuple[Any, str, str],
    inputs: tuple[Path, ...],
) -> None:
    """Write the report, the model file and the per-joint torque plots into ``out_dir``.

    ``settings``: the IDIM-LS settings (the plots' rows), ``--method`` and ``--plots``.
    """
    from ilic_cli.commands.robot_report import identify_markdown  # deferred: with the report
    from ilic_cli.modelfile import robot_model_document  # deferred: with the report

    ls, method, plot_format = settings
    name, entry = model_entry(doc, method)
    values = {n: p["value"] for n, p in entry["parameters"].items()}
    std = {"parameters": {n: p["std"] for n, p in entry["parameters"].items()}}
    friction = {n: (v or {}).get("value") for n, v in entry["friction"].items()}
    model = robot_model_document(
        values, method=name, urdf=robot.path, sha256=robot.sha256, joints=list(robot.joints),
        base_parameters=doc["base_parameters"], friction=friction, source=doc["log"], std=std,
    )  # fmt: skip
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out_dir / "report.md", identify_markdown(doc), inputs=inputs)
    atomic_write_text(out_dir / "report.json", json.dumps(doc, indent=2) + "\n", inputs=inputs)
    atomic_write_text(out_dir / "model.json", json.dumps(model, indent=2) + "\n", inputs=inputs)
    written = [out_dir / n for n in REPORTS]
    if plot_format != "none":
        theta = np.array([np.nan if v is None else v for v in values.values()], dtype=np.float64)
        written += _torque_plots(log, parts, robot, base, ls, theta, name, out_dir, plot_format)
    note(f"ilic: wrote {', '.join(str(p) for p in written)}")


def _torque_plots(log: JointLog, parts: Parts, robot: Any, base: Any, ls: Any, theta: np.ndarray, method: str, out_dir: Path, plot_format: str) -> list[Path]:
    """Each joint's measured torque and the model's on the decimated rows of the fitted parts (every row: no ``min_speed``), against time."""
    from ilic_cli.plotting import plot_joint_torques  # deferred: matplotlib only when a plot is written
    from ilic_cli.robot.idim import prepare_parts  # deferred: numba only for an arm

    held = bool(log.meta.get("torque_held", False))
    system = prepare_parts(log.q.T, log.tau.T, log.fs_hz, robot, base, parts, ls, torque_held=held, t=log.t)
    model = system.W @ theta
    first = system.joint == 0  # every joint has a row at each kept sample (no min_speed): the first joint's times are all joints'
    measured = [system.y[system.joint == j] for j in range(robot.n)]
    fitted = [model[system.joint == j] for j in range(robot.n)]
    units = [log.units(j)[1] for j in range(robot.n)]
    title = f"log {Path(str(log.meta.get('source', 'log'))).name}; model: the {method} estimate"
    return plot_joint_torques(log.t[system.sample[first]], list(robot.joints), units, measured, fitted, title, out_dir, plot_format)
