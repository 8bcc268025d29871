"""A log of n joints (issue 30): time, joint names and types, positions and torques of shape (n, N).

Units follow REP 103: a ``revolute`` joint's position is in rad and its torque
in N·m, a ``prismatic`` joint's in m and N. The reference (``q_ref``,
``qd_ref``, ``qdd_ref``) is optional. Metadata is the serialised form the 1-joint
:class:`ilic_cli.runlog.RunLog` uses too, read through the same typed views
(:class:`ilic_cli.runlog.Controller`, :class:`ilic_cli.runlog.Provenance`).

The 1-joint ``RunLog`` is left as it is: the one design in which a drive axis is
the n = 1 case of this log is not done (docs/robots.md).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.runlog import Controller, Provenance
from ilic_cli.timebase import gap_starts, nominal_rate_hz, sampling_kind, segments

JOINT_TYPES = ("revolute", "prismatic")
UNITS = {"revolute": ("rad", "N·m"), "prismatic": ("m", "N")}
"""Position and force units of a joint by its type (ROS REP 103: a JointState is in these units and says nothing of which)."""


def position_unit(joint: str, prefix: str = "") -> str:
    """The position unit of a ``joint`` type with a decimal ``prefix`` (``"u"``, ``"µ"``, ``"m"``): um or urad, mm or mrad."""
    return prefix + UNITS[joint][0]


MOTION_CHANNELS = {"q": "", "q_ref": "", "qd": "/s", "qd_ref": "/s", "qdd_ref": "/s^2"}
"""A one-joint log's channels in the joint's position unit (or its derivatives: the unit's suffix)."""


def channel_units(kind: str) -> dict[str, str]:
    """The unit of each channel of a one-joint log of a ``kind`` joint (:data:`UNITS`, :data:`MOTION_CHANNELS`)."""
    position, force = UNITS[kind]
    return {"tau": force} | {name: position + suffix for name, suffix in MOTION_CHANNELS.items()}


TYPES_ASSUMED = "types_assumed"
"""Metadata key: the joints a reader took as ``revolute`` because neither the file nor the caller gave their type."""
"""REP 103 units of a joint type: (position, effort)."""

REFERENCES = ("q_ref", "qd_ref", "qdd_ref")

Parts = tuple[tuple[int, int], ...]
"""``(start, stop)`` sample ranges of a log between its gaps (:meth:`JointLog.parts`)."""


CONTIGUOUS_RULE = (
    "an arm's log is replayed, and identified by IDIM-ILIC, IDIM-IV and DIDIM, as one run at a fixed rate (stamp jitter of "
    "a fixed-rate loop is kept; a step above 1.5 periods is a gap; IDIM-LS takes the parts between gaps): cut it at its gaps and give each part"
)
"""The rule :meth:`JointLog.contiguous` states when it refuses a log."""


@dataclass(frozen=True)
class JointLog:
    """Samples of n joints over one run.

    Attributes
    ----------
    t : ndarray (N,)
        Time (s), increasing.
    joints, kinds : tuple of str
        Joint names and types (``revolute`` or ``prismatic``).
    q, tau : ndarray (n, N)
        Measured positions and efforts.
    q_ref, qd_ref, qdd_ref : ndarray (n, N) or None
        The reference, when the log has one.
    meta : dict
        Serialised metadata (``controller``, ``source``, ``scenario``, ...).
    """

    t: np.ndarray
    joints: tuple[str, ...]
    kinds: tuple[str, ...]
    q: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray | None = None
    qd_ref: np.ndarray | None = None
    qdd_ref: np.ndarray | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n, N = len(self.joints), len(self.t)
        if len(self.kinds) != n or any(k not in JOINT_TYPES for k in self.kinds):
            raise LogError(None, f"joint types {self.kinds!r}: expected one of {', '.join(JOINT_TYPES)} per joint")
        if len(set(self.joints)) != n or n == 0:
            raise LogError(None, f"joint names {self.joints!r} must be distinct and at least one")
        for name in ("q", "tau", *REFERENCES):
            a = getattr(self, name)
            if a is not None and np.shape(a) != (n, N):
                raise LogError(None, f"{name} has shape {np.shape(a)}; expected ({n}, {N})")
        if N < 2 or not np.all(np.diff(self.t) > 0):
            raise LogError(None, "time must increase, over at least 2 samples")

    @property
    def n(self) -> int:
        return len(self.joints)

    def contiguous(self, where: Any = None) -> JointLog:
        """This log, if it is one run at a fixed rate (:data:`CONTIGUOUS_RULE`); else a :class:`LogError` that says where it is not.

        An arm's identification and replay filter and difference every joint over the whole record: across a gap or on
        irregular stamps that would be a wrong result, so such a log is refused (the one-joint chain splits it instead).
        """
        t = np.asarray(self.t, dtype=np.float64)
        rate = nominal_rate_hz(t)
        if rate is None or sampling_kind(t) == "irregular":
            raise LogError(where, f"irregular time stamps: {CONTIGUOUS_RULE}")
        gaps = gap_starts(t, rate)
        if len(gaps):
            i = int(gaps[0])
            raise LogError(where, f"{len(gaps)} gap(s), the first of {t[i + 1] - t[i]:.4g} s at t = {t[i]:.6g} s: {CONTIGUOUS_RULE}")
        return self

    def parts(self, where: Any = None) -> Parts:
        """The ``(start, stop)`` sample ranges between the log's gaps (the one-joint chain's :func:`ilic_cli.timebase.segments`).

        IDIM-LS filters and decimates each part on its own (:func:`ilic_cli.robot.idim.prepare_parts`). Irregular
        stamps are a :class:`LogError`, as for :meth:`contiguous`.
        """
        t = np.asarray(self.t, dtype=np.float64)
        rate = nominal_rate_hz(t)
        if rate is None or sampling_kind(t) == "irregular":
            raise LogError(where, f"irregular time stamps: {CONTIGUOUS_RULE}")
        return segments(t, rate)

    @property
    def fs_hz(self) -> float:
        """The log's nominal sample rate (Hz): the time base's one definition (:func:`ilic_cli.timebase.nominal_rate_hz`), as for a one-joint log."""
        rate = nominal_rate_hz(np.asarray(self.t, dtype=np.float64))
        assert rate is not None, "the constructor requires two or more increasing stamps"
        return rate

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def controller(self) -> Controller | None:
        return Controller.from_meta(self.meta)

    @property
    def provenance(self) -> Provenance:
        return Provenance.from_meta(self.meta)

    @property
    def has_reference(self) -> bool:
        return all(getattr(self, r) is not None for r in REFERENCES)

    def units(self, joint: int) -> tuple[str, str]:
        """(position, effort) units of joint number ``joint``."""
        return UNITS[self.kinds[joint]]

    def select(self, names: Sequence[str], where: Any = None) -> JointLog:
        """The log of joints ``names`` in that order; a joint the log lacks is a :class:`LogError` naming what it has."""
        missing = [j for j in names if j not in self.joints]
        if missing:
            raise LogError(where, f"no joint {', '.join(missing)} in the log (it has {', '.join(self.joints)})")
        idx = [self.joints.index(j) for j in names]

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[idx]

        return replace(
            self,
            joints=tuple(names),
            kinds=tuple(self.kinds[i] for i in idx),
            q=self.q[idx],
            tau=self.tau[idx],
            q_ref=pick(self.q_ref),
            qd_ref=pick(self.qd_ref),
            qdd_ref=pick(self.qdd_ref),
        )

    def to_dict(self) -> dict[str, Any]:
        """A summary: joints with type, units and ranges (not the samples)."""
        joints = []
        for i, (j, k) in enumerate(zip(self.joints, self.kinds)):
            qu, tu = self.units(i)
            joints.append(
                {
                    "name": j,
                    "type": k,
                    "type_assumed": j in self.meta.get(TYPES_ASSUMED, ()),
                    "position_unit": qu,
                    "effort_unit": tu,
                    "q_min": float(self.q[i].min()),
                    "q_max": float(self.q[i].max()),
                    "tau_min": float(self.tau[i].min()),
                    "tau_max": float(self.tau[i].max()),
                }
            )
        return {
            "samples": len(self.t),
            "duration_s": self.duration_s,
            "sample_rate_hz": self.fs_hz,
            "reference": self.has_reference,
            "joints": joints,
            "meta": dict(self.meta),
        }
