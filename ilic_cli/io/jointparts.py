"""What every n-joint log format shares (:mod:`ilic_cli.io.jointlogs`, :mod:`ilic_cli.io.jointros`, :mod:`ilic_cli.io.jointmat`).

The ROS topics, the metadata stored beside the samples, each joint's type (the
file's, the caller's or an assumed ``revolute``) and the log built from what a reader found.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.jointlog import TYPES_ASSUMED, JointLog

STATES, REFERENCE, METADATA = "/joint_states", "/joint_reference", "/ilic/metadata"


def stored_metadata(log: JointLog) -> dict[str, Any]:
    """What every writer stores beside the samples: the joints with their types, and the log's metadata (the types now declared)."""
    return {"joints": [list(p) for p in zip(log.joints, log.kinds)], "meta": {k: v for k, v in log.meta.items() if k != TYPES_ASSUMED}}


def joint_types(
    joints: Sequence[str], declared: Mapping[str, Any], kinds: Mapping[str, str] | None, meta: Mapping[str, Any]
) -> tuple[tuple[str, ...], dict[str, Any]]:
    """Each joint's type (the file's, else the caller's, else ``revolute``), and ``meta`` naming the joints so assumed."""
    given = dict(kinds or {})
    assumed = [j for j in joints if not (declared.get(j) or given.get(j))]
    types = tuple(str(declared.get(j) or given.get(j) or "revolute") for j in joints)
    return types, dict(meta) | ({TYPES_ASSUMED: assumed} if assumed else {})


def is_joints_metadata(payload: Mapping[str, Any]) -> bool:
    """True when ``/ilic/metadata``'s JSON is an n-joint log's (:func:`stored_metadata`: a ``joints`` list, no one-joint ``format``)."""
    return "format" not in payload and isinstance(payload.get("joints"), list)


def joint_log(path: Path, t: np.ndarray, joints: Sequence[str], types: tuple[str, ...], found: Any, refs: Any, meta: Mapping[str, Any]) -> JointLog:
    """The :class:`JointLog` of samples read from ``path`` (``found``: ``{"q": {joint: row}, "tau": ...}``); its errors name ``path``."""
    try:
        return JointLog(
            t=t,
            joints=tuple(joints),
            kinds=types,
            q=np.array([found["q"][j] for j in joints]),
            tau=np.array([found["tau"][j] for j in joints]),
            meta=dict(meta) | {"source": str(path)},
            **refs,
        )
    except LogError as exc:
        raise LogError(path, exc.problem) from None
