"""n-joint logs (:class:`ilic_cli.jointlog.JointLog`) as MATLAB ``.mat`` files (level 5, zlib-compressed), by ``scipy.io``.

Layout (N samples, n joints; every number float64, so the round trip is lossless)
------------------------------------------------------------------------------------
===============================  ===========  ===========================================
variable                         size         content
===============================  ===========  ===========================================
``t``                            N x 1        time (s)
``q``, ``tau``                   N x n        positions and efforts, one column per joint
``q_ref``, ``qd_ref``,           N x n        the reference, when the log has one
``qdd_ref``
``joint_names``, ``joint_types``  1 x n cell   the joints' names and types (``revolute``, ``prismatic``)
``metadata``                     text         the log's metadata as JSON
===============================  ===========  ===========================================

In MATLAB: ``load('arm.mat'); plot(t, q(:, 2)); joint_names{2}``. ``joint_names``
tells an n-joint file apart from a one-joint EMPS file (``t``, ``qm``, ...: :mod:`ilic_cli.io.mat`),
which the one-joint chain reads as before. Writing stamps no creation time in the
file's header text, so the same log gives the same bytes.
"""

from __future__ import annotations

import io
import json
import struct
import zlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.io import matfast
from ilic_cli.io.jointparts import joint_log, joint_types, stored_metadata
from ilic_cli.io.mat import HEADER_TEXT, JOINT_NAMES_VAR, _load_scipy
from ilic_cli.io.rosjson import parse_json_object
from ilic_cli.jointlog import REFERENCES, JointLog

NAMES, TYPES, META = JOINT_NAMES_VAR, "joint_types", "metadata"


def is_joint_mat(path: Path) -> bool:
    """True for a ``.mat`` file of an n-joint log (it has :data:`NAMES`); False for any other, readable or not.

    Reads each variable's name only (the head of its element, inflated up to its name): no ``scipy.io`` and no samples,
    so that telling a one-joint ``.mat`` apart costs the one-joint chain nothing to speak of.
    """
    if path.suffix.lower() != ".mat" or not path.is_file():
        return False
    try:
        return NAMES in _names(path)
    except (OSError, ValueError, struct.error, zlib.error, matfast._Unusual):
        return False


def _names(path: Path) -> list[str]:
    """The variable names of a level-5 MAT file (:mod:`ilic_cli.io.matfast`'s elements; a compressed one is not padded)."""
    names = []
    with path.open("rb") as f:
        header = f.read(128)
        if header[124:128] != b"\x00\x01IM":
            raise ValueError("not a little-endian level-5 MAT file")
        while tag := f.read(8):
            start = f.tell()
            kind, size = struct.unpack("<II", tag)
            head = f.read(min(size, 256))
            if kind == matfast.MI_COMPRESSED:
                head = zlib.decompressobj().decompress(head, 256)
                f.seek(start + size)
            else:
                f.seek(start + size + (-size % 8))
                head = tag + head
            if struct.unpack_from("<I", head)[0] != matfast.MI_MATRIX:
                raise ValueError("not a matrix")
            buf = memoryview(head)  # the matrix's head: its tag, then its elements
            pos = matfast._element(buf, 8, len(buf))[3]  # array flags
            pos = matfast._element(buf, pos, len(buf))[3]  # dimensions
            _, a, b, _ = matfast._element(buf, pos, len(buf))
            names.append(bytes(buf[a:b]).decode("latin1"))
    return names


def _cell(texts: tuple[str, ...]) -> np.ndarray:
    cell = np.empty((1, len(texts)), dtype=object)
    cell[0, :] = list(texts)
    return cell


def write(log: JointLog, path: Path) -> None:
    """Write ``log`` to ``path`` (see the module's docstring)."""
    import scipy.io  # deferred: 0.13 s of imports; only to write a .mat

    mdict: dict[str, Any] = {"t": log.t.reshape(-1, 1), "q": log.q.T, "tau": log.tau.T}
    if log.has_reference:
        mdict |= {r: getattr(log, r).T for r in REFERENCES}
    header = stored_metadata(log)
    mdict |= {NAMES: _cell(log.joints), TYPES: _cell(log.kinds), META: np.array(json.dumps(header["meta"], sort_keys=True, default=str))}
    buffer = io.BytesIO()
    scipy.io.savemat(buffer, mdict, do_compression=True, oned_as="column")
    raw = bytearray(buffer.getvalue())
    raw[:116] = HEADER_TEXT.ljust(116, b" ")  # MAT level 5: free header text, where scipy puts the creation time
    path.write_bytes(bytes(raw))


def _texts(value: Any, name: str, path: Path) -> list[str]:
    """The strings of a cell array of text (``joint_names``, ``joint_types``)."""
    if not isinstance(value, np.ndarray) or value.dtype != object or value.ndim != 2 or value.shape[0] != 1:
        raise LogError(path, f"{name} is not a 1 x n cell array of text")
    out = []
    for item in value[0]:
        if not isinstance(item, np.ndarray) or item.dtype.kind != "U" or item.size != 1:
            raise LogError(path, f"{name} holds something else than text")
        out.append(str(item.reshape(-1)[0]))
    return out


def _matrix(variables: Mapping[str, Any], name: str, shape: tuple[int, int], path: Path) -> np.ndarray:
    value = variables[name]
    if not isinstance(value, np.ndarray) or value.dtype != np.float64 or value.shape != shape:
        got = f"{value.dtype} {value.shape}" if isinstance(value, np.ndarray) else type(value).__name__
        raise LogError(path, f"{name} is {got}; expected float64 of size {shape[0]} x {shape[1]}")
    return np.ascontiguousarray(value.T)


def read(path: Path, kinds: Mapping[str, str] | None = None) -> JointLog:
    """An n-joint ``.mat`` (see the module's docstring); ``kinds``: joint types where the file gives none."""
    variables = _load_scipy(path)
    if NAMES not in variables:
        raise LogError(path, f"not an n-joint .mat: no {NAMES} (a one-joint EMPS file is read by the one-joint chain)")
    joints = _texts(variables[NAMES], NAMES, path)
    declared = dict(zip(joints, _texts(variables[TYPES], TYPES, path))) if TYPES in variables else {}
    missing = [v for v in ("t", "q", "tau") if v not in variables]
    if missing:
        raise LogError(path, f"no variable {', '.join(missing)}" + (" (a log without effort)" if missing == ["tau"] else ""))
    t = variables["t"]
    if not isinstance(t, np.ndarray) or t.dtype != np.float64 or t.ndim != 2 or t.shape[1] != 1:
        raise LogError(path, "t is not a float64 column (N x 1)")
    shape = (len(t), len(joints))
    found = {v: dict(zip(joints, _matrix(variables, v, shape, path))) for v in ("q", "tau")}
    refs = {r: _matrix(variables, r, shape, path) if all(x in variables for x in REFERENCES) else None for r in REFERENCES}
    text = variables.get(META)
    meta = parse_json_object(str(text.reshape(-1)[0]), path, META) if isinstance(text, np.ndarray) and text.size == 1 else {}
    types, kept = joint_types(joints, declared, kinds, meta)
    return joint_log(path, np.ascontiguousarray(t[:, 0]), joints, types, found, refs, kept)
