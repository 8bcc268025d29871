"""The n-joint model of an arm from its URDF: standard parameters and the regressor (paper eqs. 1-3).

Per joint ``j`` the standard parameters are 14 (paper eq. 2-3), in this order:
the 10 inertial parameters of the link it moves, in pinocchio's order
(``m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz``: mass, first moments ``m c``
and the inertia about the joint frame's origin, in that frame), then the
rotor inertia ``Ia`` (the joint's own acceleration), the viscous ``Fv``, the
Coulomb ``Fc`` (``sign(qd)``) and the torque ``offset``. Names are
``<parameter>_<joint>`` (``Fv_elbow_joint``).

The regressor ``Y`` (``n*N x 14n``) stacks the joints' rows joint-major: the
rows of joint ``j`` are ``j*N .. (j+1)*N - 1``, so that ``tau.T.ravel() = Y @ pi``.
:func:`regressor` computes it by a compiled Newton-Euler pass in regressor form
(:mod:`ilic_cli.robot.kernel`); :func:`regressor_loop` calls pinocchio's
``computeJointTorqueRegressor`` per sample (the reference the tests and the
speed figures compare against).

pinocchio is imported inside the functions that need it: it is an optional
dependency (``pip install 'ilic[robot]'``) and its import costs ~0.4 s.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.errors import IlicError, ParameterError

INERTIAL = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
"""The 10 inertial standard parameters of a link, in pinocchio's order (``Inertia.toDynamicParameters``)."""

DRIVE = ("Ia", "Fv", "Fc", "offset")
"""The per-joint drive parameters after the link's inertial ones: rotor inertia, viscous, Coulomb, offset."""

PER_JOINT = INERTIAL + DRIVE
"""The 14 standard parameters of one joint, in column order."""


class PinocchioMissing(ParameterError):
    """pinocchio (the ``robot`` extra) is not installed."""

    def __init__(self) -> None:
        self.parameter, self.value, self.rule = "pinocchio", None, "installed"
        IlicError.__init__(self, None, "pinocchio is not installed: pip install 'ilic[robot]'")


def import_pinocchio() -> Any:
    """The ``pinocchio`` module, or :class:`PinocchioMissing` (one line) when the extra is not installed."""
    try:
        import pinocchio  # optional dependency, ~0.4 s: only the robot functions need it
    except ImportError:
        raise PinocchioMissing() from None
    return pinocchio


@dataclass(frozen=True)
class RobotModel:
    """An arm read from a URDF: its moving joints, kinematic tree and standard parameters.

    Attributes
    ----------
    path, sha256 : str
        The URDF file and the SHA-256 of its bytes.
    joints, kinds : tuple of str
        Moving joints in pinocchio's (topological) order; ``revolute`` or ``prismatic``.
    parents : tuple of int
        Index of each joint's parent joint in ``joints`` (-1: the base).
    axes : ndarray (n, 3)
        Unit axis of each joint in its own frame.
    rotations, translations : ndarray (n, 3, 3), (n, 3)
        Placement of each joint in its parent's frame (pinocchio ``jointPlacements``).
    unbounded : tuple of bool
        Continuous joints (pinocchio stores ``cos q, sin q``).
    gravity : ndarray (3,)
        Gravity in the base frame (m/s²).
    standard : ndarray (14 n,)
        The URDF's standard parameters: inertial ones of each link, ``Ia`` from the
        armature (0 in a URDF), ``Fv`` from ``<dynamics damping>``, ``Fc`` from
        ``<dynamics friction>``, offset 0.
    """

    path: str
    sha256: str
    joints: tuple[str, ...]
    kinds: tuple[str, ...]
    parents: tuple[int, ...]
    axes: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    unbounded: tuple[bool, ...]
    gravity: np.ndarray
    standard: np.ndarray
    pin: Any = field(repr=False, compare=False)

    @property
    def n(self) -> int:
        return len(self.joints)

    @property
    def names(self) -> tuple[str, ...]:
        """Standard parameter names, ``<parameter>_<joint>``, in column order."""
        return tuple(f"{p}_{j}" for j in self.joints for p in PER_JOINT)

    def index(self, parameter: str, joint: int) -> int:
        """Column of ``parameter`` (one of :data:`PER_JOINT`) of joint number ``joint``."""
        return len(PER_JOINT) * joint + PER_JOINT.index(parameter)

    def parameters(self, values: Mapping[str, float] | None = None, base: np.ndarray | None = None) -> np.ndarray:
        """A standard parameter vector: ``base`` (default: the URDF's) with ``values`` (name -> value) replaced.

        An unknown name is a :class:`ParameterError`.
        """
        pi = np.array(self.standard if base is None else base, dtype=np.float64)
        names = self.names
        for name, value in (values or {}).items():
            if name not in names:
                raise ParameterError(name, float(value), f"a standard parameter of {Path(self.path).name} (<parameter>_<joint>)")
            pi[names.index(name)] = float(value)
        return pi

    def drive(self, pi: np.ndarray, parameter: str) -> np.ndarray:
        """Per-joint values of a drive parameter (``Ia``, ``Fv``, ``Fc``, ``offset``) in ``pi``."""
        return np.asarray(pi)[len(INERTIAL) + DRIVE.index(parameter) :: len(PER_JOINT)]

    def to_dict(self) -> dict[str, Any]:
        return {
            "urdf": self.path,
            "sha256": self.sha256,
            "joints": [{"name": j, "type": k, "parent": None if p < 0 else self.joints[p]} for j, k, p in zip(self.joints, self.kinds, self.parents)],
            "gravity": self.gravity.tolist(),
            "standard": dict(zip(self.names, self.standard.tolist())),
        }


def load_urdf(path: str | Path) -> RobotModel:
    """Read an arm from a URDF file (pinocchio's parser; fixed joints merge their links into the parent).

    Only revolute, continuous and prismatic joints are taken; any other moving
    joint (floating, planar, spherical) is refused in one line.
    """
    pin = import_pinocchio()
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise IlicError(path, f"cannot read the URDF: {exc.strerror or exc}") from None
    try:
        model = pin.buildModelFromXML(data.decode("utf-8"))
    except (ValueError, RuntimeError, UnicodeDecodeError) as exc:
        raise IlicError(path, f"not a URDF pinocchio can read: {str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__}") from None
    if model.njoints < 2:
        raise IlicError(path, "the URDF has no moving joint")
    pdata = model.createData()
    q0 = pin.neutral(model)
    pin.computeJointJacobians(model, pdata, q0)
    kinds, axes, unbounded = [], [], []
    for i in range(1, model.njoints):
        joint = model.joints[i]
        if joint.nv != 1 or joint.nq not in (1, 2):
            raise IlicError(path, f"joint {model.names[i]!r} ({joint.shortname()}) is not revolute, continuous or prismatic")
        s = np.asarray(pin.getJointJacobian(model, pdata, i, pin.LOCAL)).reshape(6, model.nv)[:, joint.idx_v]  # (6,) for one joint: eigenpy's vector
        lin, ang = s[:3], s[3:]
        if np.allclose(lin, 0.0) and np.isclose(np.linalg.norm(ang), 1.0):
            kinds.append("revolute")
            axes.append(ang)
        elif np.allclose(ang, 0.0) and np.isclose(np.linalg.norm(lin), 1.0):
            kinds.append("prismatic")
            axes.append(lin)
        else:
            raise IlicError(path, f"joint {model.names[i]!r} ({joint.shortname()}) is not revolute, continuous or prismatic")
        unbounded.append(joint.nq == 2)
    standard = np.zeros(len(PER_JOINT) * (model.njoints - 1))
    for i in range(1, model.njoints):
        j = len(PER_JOINT) * (i - 1)
        standard[j : j + len(INERTIAL)] = model.inertias[i].toDynamicParameters()
        standard[j + 10 : j + 14] = (model.armature[i - 1], model.damping[i - 1], model.friction[i - 1], 0.0)
    return RobotModel(
        path=str(path),
        sha256=hashlib.sha256(data).hexdigest(),
        joints=tuple(model.names[1:]),
        kinds=tuple(kinds),
        parents=tuple(int(model.parents[i]) - 1 for i in range(1, model.njoints)),
        axes=np.array(axes, dtype=np.float64),
        rotations=np.array([model.jointPlacements[i].rotation for i in range(1, model.njoints)]),
        translations=np.array([model.jointPlacements[i].translation for i in range(1, model.njoints)]),
        unbounded=tuple(unbounded),
        gravity=np.array(model.gravity.linear, dtype=np.float64),
        standard=standard,
        pin=model,
    )


def configuration(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Joint positions ``q`` (..., n) as pinocchio configurations (``cos q, sin q`` for a continuous joint)."""
    q = np.asarray(q, dtype=np.float64)
    if not any(robot.unbounded):
        return q
    parts = [np.stack([np.cos(q[..., j]), np.sin(q[..., j])], axis=-1) if u else q[..., j : j + 1] for j, u in enumerate(robot.unbounded)]
    return np.concatenate(parts, axis=-1)


def pinocchio_model(robot: RobotModel, pi: np.ndarray) -> Any:
    """A copy of the pinocchio model with the links' inertias and the armature (``Ia``) of ``pi``.

    pinocchio's ``rnea`` and ``aba`` then include ``Ia qdd``; friction and offset are not theirs.
    """
    pin = import_pinocchio()
    model = pin.Model(robot.pin)
    pi = np.asarray(pi, dtype=np.float64)
    for j in range(robot.n):
        model.inertias[j + 1] = pin.Inertia.FromDynamicParameters(pi[len(PER_JOINT) * j : len(PER_JOINT) * j + len(INERTIAL)])
    model.armature = robot.drive(pi, "Ia").copy()
    return model


def friction_torque(robot: RobotModel, pi: np.ndarray, qd: np.ndarray, sign_qd: np.ndarray | None = None) -> np.ndarray:
    """``Fv qd + Fc sign(qd) + offset`` per joint (``sign_qd`` replaces ``sign(qd)``: a smooth rule)."""
    qd = np.asarray(qd, dtype=np.float64)
    s = np.sign(qd) if sign_qd is None else sign_qd
    return robot.drive(pi, "Fv") * qd + robot.drive(pi, "Fc") * s + robot.drive(pi, "offset")


def inverse_dynamics(robot: RobotModel, pi: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Joint torques (N, n) by pinocchio's ``rnea`` (inertias and ``Ia`` of ``pi``) plus :func:`friction_torque`."""
    pin = import_pinocchio()
    model = pinocchio_model(robot, pi)
    data = model.createData()
    qc = configuration(robot, q)
    q, qd, qdd = (np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (q, qd, qdd))
    tau = np.array([pin.rnea(model, data, qc_k, v, a) for qc_k, v, a in zip(np.atleast_2d(qc), qd, qdd)])
    return tau + friction_torque(robot, pi, qd)


def _check(robot: RobotModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    arrays = tuple(np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in (q, qd, qdd))
    for name, a in zip(("q", "qd", "qdd"), arrays):
        if a.ndim != 2 or a.shape[1] != robot.n or a.shape != arrays[0].shape:
            raise ValueError(f"{name} has shape {a.shape}; expected (N, {robot.n}) like q")
    return arrays[0], arrays[1], arrays[2]


def _drive_columns(robot: RobotModel, Y: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> None:
    """Fill the ``Ia, Fv, Fc, offset`` columns of the joint-major ``Y`` (n, N, 14 n) in place."""
    for j in range(robot.n):
        c = len(PER_JOINT) * j + len(INERTIAL)
        Y[j, :, c] = qdd[:, j]
        Y[j, :, c + 1] = qd[:, j]
        Y[j, :, c + 2] = np.sign(qd[:, j])
        Y[j, :, c + 3] = 1.0


def regressor_loop(robot: RobotModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """``Y`` (n*N, 14n) from pinocchio's ``computeJointTorqueRegressor``, one call per sample (the reference)."""
    pin = import_pinocchio()
    q, qd, qdd = _check(robot, q, qd, qdd)
    model = robot.pin
    data = model.createData()
    N, n = q.shape
    Y = np.zeros((n, N, len(PER_JOINT) * n))
    inertial = (np.arange(n)[:, None] * len(PER_JOINT) + np.arange(len(INERTIAL))).ravel()
    qc = configuration(robot, q)
    for k in range(N):
        Y[:, k, inertial] = pin.computeJointTorqueRegressor(model, data, qc[k], qd[k], qdd[k])
    _drive_columns(robot, Y, qd, qdd)
    return Y.reshape(n * N, -1)


def regressor(robot: RobotModel, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *, joint_major: bool = True, out: np.ndarray | None = None) -> np.ndarray:
    """The regressor ``Y`` (n*N, 14 n) of the standard parameters at the states ``q, qd, qdd`` (N, n).

    ``tau.T.ravel() = Y @ pi`` (joint-major rows); ``joint_major=False`` returns the
    (n, N, 14 n) array instead. The inertial columns come from the compiled
    kernel (:func:`ilic_cli.robot.kernel.inertial_regressor`); they equal
    :func:`regressor_loop` (pinocchio) to rounding. ``out``: an (n, >= N, 14 n)
    array returned by an earlier call for the same robot, filled again (a block
    loop then touches no new memory: fresh pages cost more than the kernel).
    """
    from ilic_cli.robot.kernel import inertial_regressor  # deferred: numba's import and the cached machine code cost ~0.5 s

    q, qd, qdd = _check(robot, q, qd, qdd)
    N, n = q.shape
    p = len(PER_JOINT) * n
    if out is None:
        Y = np.zeros((n, N, p))
    elif out.ndim != 3 or out.shape[0] != n or out.shape[1] < N or out.shape[2] != p:
        raise ValueError(f"out has shape {out.shape}; expected ({n}, >= {N}, {p})")
    else:
        Y = out[:, :N]
    prismatic = np.array([k == "prismatic" for k in robot.kinds])
    parents = np.array(robot.parents, dtype=np.int64)
    inertial_regressor(prismatic, parents, robot.axes, robot.rotations, robot.translations, robot.gravity, q, qd, qdd, Y, len(PER_JOINT))
    _drive_columns(robot, Y, qd, qdd)
    return Y.reshape(n * N, -1) if joint_major else Y
