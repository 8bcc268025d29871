"""IDIM-LS of an arm of n joints: the 1-DOF chain's processing per joint, stacked, and Gautier's weighted LS.

Each joint's measured position is filtered, differentiated and trimmed exactly
as the 1-DOF chain does (:mod:`ilic_cli.idim_ls` with its :class:`LSSettings`):
zero-phase Butterworth low-pass, central differences, edge trim. The base
regressor of every joint's rows and that joint's torque are decimated in
parallel by the same decimation (MATLAB ``decimate``: :func:`decimate_columns`,
compiled, within 1e-11 of ``idim_ls._decimate``; ``_decimate`` itself when
``matlab`` is off), then the joints' systems are stacked (joint-major rows).

Weighted LS (Gautier 1997): a first unweighted fit gives each joint's error
standard deviation ``sigma_j`` (sample std of its rows' residual); every row of
joint ``j`` is divided by ``sigma_j`` and the weighted system is solved by
:func:`ilic_cli.lsq.solve_tall` (:func:`ilic_cli.lsq.solve` by a QR), whose eq. (9) standard deviations are then those of
the weighted estimate. Only the base columns a joint's rows can touch
(:func:`active_columns`) are decimated; memory: those columns at the full rate,
at most ``8 n N b`` bytes.
"""

from __future__ import annotations

import functools
import math
import mmap
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.filter_design import cheby1_ba, cheby1_sos
from ilic_cli.filtering import MATLAB_DECIMATE_MAX, _polished_roots, butter_lowpass_zero_phase, kept_indices
from ilic_cli.idim_ilic import essential_mask
from ilic_cli.idim_ls import LSSettings, _decimate, min_samples, part_valid  # the 1-DOF chain's decimation, gap edges: one definition
from ilic_cli.jointlog import Parts
from ilic_cli.lsq import LSResult, finite_or_none, pinv, relative_error_pct, solve_tall
from ilic_cli.parallel import ordered_map
from ilic_cli.robot.base import BaseParameters
from ilic_cli.robot.model import INERTIAL, PER_JOINT, RobotModel
from ilic_cli.row_spans import valid_rows
from ilic_cli.usable import glitch, nothing_to_fit

ROBOT_BAND_HZ = 20.0
"""The band an arm's decimated rows keep: :func:`ilic_cli.filtering.rows_decimation` with it gives 20 at 1 kHz, 40 at 2 kHz.

``LSSettings(band_hz=ROBOT_BAND_HZ)``: the 1-DOF chain's one rule by the log's rate, with half its band. On the
6-joint and 2-joint test logs at 1 kHz, the 1-DOF band (40 Hz: decimation 10) under the 50 Hz position filter let
the encoders' quantisation through the acceleration: arm2's relative error 1.1 % against 0.17 %, and ur5like's
Fv_wrist_2 4 % off (3 % allowed)."""


@dataclass(frozen=True)
class RobotSystem:
    """The decimated IDIM system of one log: ``y = W beta`` (joint-major rows)."""

    W: np.ndarray
    y: np.ndarray
    joint: np.ndarray
    """Joint number of each row."""
    names: tuple[str, ...]
    joints: tuple[str, ...]
    settings: LSSettings
    sample: np.ndarray
    """The log's sample each row stands for (its time: ``t[sample]``)."""
    kept: tuple[np.ndarray, ...] = ()
    """Per joint, the decimated rows kept by ``min_speed`` (empty: every row)."""


@dataclass(frozen=True)
class Fit:
    """An n-joint IDIM-LS estimate of the base parameters.

    Attributes
    ----------
    method : str
        ``IDIM-WLS`` (rows weighted per joint) or ``IDIM-LS``.
    names, theta, covariance : tuple, ndarray, ndarray
        Base parameter names, estimate and its covariance (of the weighted system).
    residual : ndarray
        ``y - W theta`` on the decimated rows, in torque units (unweighted).
    joint_std : ndarray (n,)
        Each joint's error standard deviation (the weights; 1 for unweighted LS).
    result : LSResult
        The solver's result on the (weighted) system.
    relative_error_pct : float
        ``100 ||y - W theta|| / ||y||`` of the unweighted system.
    """

    method: str
    names: tuple[str, ...]
    theta: np.ndarray
    covariance: np.ndarray
    residual: np.ndarray
    joints: tuple[str, ...]
    joint_std: np.ndarray
    result: LSResult
    relative_error_pct: float

    @property
    def std(self) -> np.ndarray:
        return self.result.std

    @property
    def rel_std_pct(self) -> np.ndarray:
        return self.result.rel_std_pct

    def value(self, name: str) -> float:
        return float(self.theta[self.names.index(name)])

    def to_dict(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "parameters": self.result.parameters(),
            "joint_error_std": {j: finite_or_none(s) for j, s in zip(self.joints, self.joint_std)},
            "relative_error_pct": finite_or_none(self.relative_error_pct),
            "condition_number": finite_or_none(self.result.condition_number),
            "rows": self.result.rows,
            "rank": self.result.rank,
        }


def prepare(
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    robot: RobotModel,
    base: BaseParameters,
    settings: LSSettings = LSSettings(),
    *,
    min_speed: float = 0.0,
    torque_held: bool = False,
    keep: tuple[np.ndarray, ...] = (),
    rows_needed: int | None = None,
    valid: np.ndarray | None = None,
) -> RobotSystem:
    """Filter, differentiate, trim and decimate each joint as the 1-DOF chain; stack the joints' base systems.

    Parameters
    ----------
    q, tau : ndarray (N, n)
        Measured joint positions and torques, sampled at ``fs_hz``, joints in ``robot.joints`` order.
    min_speed : float
        A joint's decimated row is left out when its span (:func:`ilic_cli.row_spans.valid_rows`)
        holds a sample with that joint's filtered ``|qd| <= min_speed``: near rest the
        joint sticks and its friction is not ``Fc sign(qd)`` (0: every row is kept).
    torque_held : bool
        The logged torque is a command held over the period that follows its
        sample (:mod:`ilic_cli.robot.simulate`, a drive's command log). The
        central-difference acceleration at ``t_k`` spans both neighbouring
        periods, so the torque is moved half a period later,
        ``(tau[k-1] + tau[k]) / 2``; without this the 6-joint test log's shoulder
        ``Fv`` comes out 2.8 % (5 sigma) low.
    keep : tuple of ndarray
        Per joint, the decimated rows to keep, in place of ``min_speed``'s (another
        system's :attr:`RobotSystem.kept`: the closed-loop methods pair the rows of
        the measured and the simulated logs).
    rows_needed : int, optional
        ``min_speed`` leaving this many rows or fewer is an error (default: the base parameters' number;
        -1: never, :func:`prepare_parts`, which leaves out a part with none and checks the stack).
    valid : ndarray of bool (N,), optional
        Samples that may be used (``None``: every one): every joint's rows whose span touches another are left out, beside
        ``min_speed``'s (:func:`prepare_parts`: a part's edges at a gap, :func:`ilic_cli.idim_ls.part_valid`).
    """
    settings = settings.at_rate(fs_hz)  # the decimation by the log's rate, the 1-DOF chain's one rule (unless given: band_hz None)
    q, tau = np.asarray(q, dtype=np.float64), np.asarray(tau, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != robot.n or tau.shape != q.shape:
        raise ValueError(f"q {q.shape} and tau {tau.shape} must both be (N, {robot.n})")
    if len(q) < min_samples(settings):
        raise ValueError(f"too few samples ({len(q)}) for IDIM-LS with trim {settings.trim} and decimation {settings.decimation}")
    dt = 1.0 / fs_hz
    if torque_held:
        tau = np.vstack([tau[:1], 0.5 * (tau[1:] + tau[:-1])])
    qf = butter_lowpass_zero_phase(q, settings.cutoff_hz, fs_hz, settings.order, matlab=settings.matlab, axis=0)
    qd = derivative(qf, dt, settings.stencil)
    qdd = derivative(qd, dt, settings.stencil)
    s = slice(settings.trim, None)
    qf, qd, qdd, tau = qf[s], qd[s], qdd[s], tau[s]
    active = active_columns(robot, base)
    columns, rows = base_columns(robot, base, active, qf, qd, qdd, tau, parts=2)
    # every joint's columns through the one parallel decimation (the same filter for every column, each filtered on its own)
    if settings.matlab:
        d = decimate_columns(columns, settings.decimation)
    else:
        d = _decimate(np.concatenate(list(columns), axis=1), settings, fs_hz)
    del columns
    parts = []
    for j in range(robot.n):
        part = np.zeros((len(d), base.b + 1))
        part[:, np.flatnonzero(np.append(active[j], True))] = d[:, rows[j] : rows[j + 1]]
        parts.append(part)
    kept: tuple[np.ndarray, ...] = ()
    usable = np.ones(len(qd), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)[s]
    if keep:
        kept = tuple(np.asarray(k, dtype=bool) for k in keep)
    elif min_speed > 0 or valid is not None:
        kept = tuple(valid_rows(usable & (np.abs(qd[:, j]) > min_speed) if min_speed > 0 else usable, settings.decimation) for j in range(robot.n))
    if kept:
        parts = [p[k] for p, k in zip(parts, kept)]
        if sum(len(p) for p in parts) <= (base.b if rows_needed is None else rows_needed):
            raise ValueError(f"only {sum(len(p) for p in parts)} rows move faster than {min_speed:g}: too few for {base.b} base parameters")
    W = np.concatenate([p[:, :-1] for p in parts])
    y = np.concatenate([p[:, -1] for p in parts])
    joint = np.concatenate([np.full(len(p), j) for j, p in enumerate(parts)])
    at = settings.trim + kept_indices(len(q) - settings.trim, settings.decimation)
    sample = np.concatenate([at[k] for k in kept]) if kept else np.tile(at, robot.n)
    return RobotSystem(W=W, y=y, joint=joint, names=base.names, joints=robot.joints, settings=settings, kept=kept, sample=sample)


def joint_glitch(q: np.ndarray, tau: np.ndarray, t: np.ndarray, joints: Sequence[str]) -> str | None:
    """Why an arm's log is refused for a glitch: the first joint whose position or torque (arrays of ``(samples, joints)``) holds
    one (:func:`ilic_cli.usable.glitch`), else ``None``. The arm's fits (:func:`prepare_parts`) and its replay check it, as a
    one-joint log is checked by :func:`ilic_cli.usable.glitches`."""
    for j, name in enumerate(joints):  # t: the samples' stamps (s), for the message
        if (why := glitch("the position", q[:, j], t) or glitch("the torque", tau[:, j], t)) is not None:
            return f"joint {name}: {why}"
    return None


def prepare_parts(
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    robot: RobotModel,
    base: BaseParameters,
    parts: Parts,
    settings: LSSettings = LSSettings(),
    *,
    min_speed: float = 0.0,
    torque_held: bool = False,
    t: np.ndarray | None = None,
) -> RobotSystem:
    """:func:`prepare` of each contiguous part ``(start, stop)`` of a log cut at its gaps (:func:`ilic_cli.timebase.segments`), stacked.

    A joint whose position or torque never changes, or holds a glitch, is refused as the one-joint chain refuses it
    (:func:`ilic_cli.usable.nothing_to_fit`, :func:`ilic_cli.usable.glitch`): a frozen elbow had been refused with NumPy's
    warnings on stderr and a message of ``np.float64(nan)``, a torque of zeros fitted with exit 0.

    The one-joint chain's rule (``idim_ls.decimated_systems``): each part is filtered, differentiated and decimated on its own,
    and leaves out its edges at a gap (:func:`ilic_cli.idim_ls.part_valid`: the filters' transients, mid-motion there);
    a part shorter than :func:`ilic_cli.idim_ls.min_samples` is left out, and none left is an error. Rows are
    joint-major within each part; :attr:`RobotSystem.sample` says which sample each stands for. ``t``: the samples' stamps (s),
    the time a glitch's message gives (default: the sample's index over the rate, which a gap does not move).
    """
    for j, name in enumerate(robot.joints):  # the one-joint chain's refusals (usable.with_rest), joint by joint
        if (why := nothing_to_fit(q[:, j], tau[:, j])) is not None:
            raise ValueError(f"joint {name}: {why}")
    if (why := joint_glitch(q, tau, np.arange(len(q)) / fs_hz if t is None else t, robot.joints)) is not None:
        raise ValueError(why)
    if len(parts) == 1:
        return prepare(q, tau, fs_hz, robot, base, settings, min_speed=min_speed, torque_held=torque_held)
    at_rate = settings.at_rate(fs_hz)
    shortest = min_samples(at_rate)
    systems = []
    for i, (a, b) in enumerate(parts):
        if b - a < shortest:
            continue
        valid = part_valid(None, b - a, i > 0, i < len(parts) - 1, at_rate)
        one = prepare(q[a:b], tau[a:b], fs_hz, robot, base, settings, min_speed=min_speed, torque_held=torque_held, rows_needed=-1, valid=valid)
        if len(one.y):  # a part with no row fast enough (min_speed) adds nothing
            systems.append(replace(one, sample=one.sample + a, kept=()))
    if not systems:
        raise ValueError(f"no contiguous part of the log has the {shortest} samples IDIM-LS needs")
    joined = replace(
        systems[0],
        W=np.concatenate([s.W for s in systems]),
        y=np.concatenate([s.y for s in systems]),
        joint=np.concatenate([s.joint for s in systems]),
        sample=np.concatenate([s.sample for s in systems]),
    )
    if len(joined.y) <= base.b:
        raise ValueError(f"only {len(joined.y)} rows in the log's contiguous parts: too few for {base.b} base parameters")
    return joined


def base_columns(
    robot: RobotModel,
    base: BaseParameters,
    active: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    tau: np.ndarray,
    *,
    parts: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's nonzero base columns then its torque, at the full rate: ``(columns (C, N), rows (n + 1,))``.

    Joint ``j``'s columns are ``columns[rows[j] : rows[j + 1]]``: its ``active``
    base columns in the order of ``base.kept``, then ``tau[:, j]``. They are
    those of :func:`ilic_cli.robot.model.regressor` (compiled, written straight
    into place: the full regressor of every standard column is never held).

    ``parts > 0``: the columns by sample in that many parts, ``(parts, N, w)``, column ``d`` at ``[d // w, :, d % w]``
    (``w = ceil(C / parts)``, the last part's spare columns zero): what :func:`decimate_columns` filters, a part per thread.
    """
    from ilic_cli.robot.kernel import base_columns as fill  # deferred: numba's import and the cached machine code cost ~0.5 s

    n, p = robot.n, len(PER_JOINT) * robot.n
    counts = active.sum(axis=1) + 1
    rows = np.concatenate([[0], np.cumsum(counts)])
    destination = np.full((n, p), -1, dtype=np.int64)
    for j in range(n):
        destination[j, base.kept[active[j]]] = rows[j] + np.arange(counts[j] - 1)
    width = -(-int(rows[-1]) // parts) if parts else int(rows[-1])
    columns = plain_pages((parts, len(q), width)) if parts else plain_pages((int(rows[-1]), len(q)))
    out = columns.transpose(0, 2, 1) if parts else columns[None]  # (parts, width, N)
    out[-1, int(rows[-1]) - width * (len(out) - 1) :] = 0.0  # the spare columns of the last part (none: an empty slice)
    prismatic = np.array([k == "prismatic" for k in robot.kinds])
    parents = np.array(robot.parents, dtype=np.int64)
    q, qd, qdd = (np.ascontiguousarray(a) for a in (q, qd, qdd))
    arguments = (prismatic, parents, robot.axes, robot.rotations, robot.translations, robot.gravity, q, qd, qdd, destination, len(PER_JOINT), out, width)
    # two halves of the samples in two threads (the kernel holds no GIL; each sample's columns are its own: the same bits)
    cut = [0, len(q) // 2, len(q)]
    ordered_map(lambda k: fill(*arguments, cut[k], cut[k + 1]), [0, 1])
    for j, d in enumerate(rows[1:] - 1):
        out[d // width, d % width] = tau[:, j]
    return columns, rows


@functools.lru_cache(maxsize=8)
def chebyshev_sections(r: int) -> tuple[np.ndarray, float, float]:
    """MATLAB ``decimate``'s Chebyshev filter for factor ``r`` as :func:`ilic_cli.robot.kernel.filtfilt_kept` runs it: ``(a (4, 2), k, gain)``.

    The transfer function ``b/a`` of :func:`ilic_cli.filtering.decimate_matlab` (``b = k (1 + z^-1)^8``), its
    poles those :func:`ilic_cli.filtering.filtfilt_matlab` runs (the roots of ``a``, polished), one section per
    conjugate pair or pair of real poles; ``gain`` its DC gain. Above :data:`ilic_cli.filtering.MATLAB_DECIMATE_MAX` the
    design's own poles (its second-order sections), as there.
    """
    if r > MATLAB_DECIMATE_MAX:  # the poles of the design itself, as decimate_matlab's sections there
        sos = cheby1_sos(8, 0.05, 0.8 / r)
        gain = math.prod(math.fsum(row[:3]) / math.fsum(row[3:]) for row in sos)
        return np.ascontiguousarray(sos[:, 4:6]), float(np.prod(sos[:, 0])), gain
    b, a = cheby1_ba(8, 0.05, 0.8 / r)
    b, a = b / a[0], a / a[0]
    poles = _polished_roots(a)
    real = np.sort(poles[poles.imag == 0].real)
    pairs = [[-2.0 * float(p.real), float(p.real**2 + p.imag**2)] for p in poles[poles.imag > 0]]
    pairs += [[-float(real[i] + real[i + 1]), float(real[i] * real[i + 1])] for i in range(0, len(real), 2)]
    return np.array(pairs), float(b[0]), math.fsum(b) / math.fsum(a)


def decimate_columns(columns: np.ndarray, r: int) -> np.ndarray:
    """MATLAB ``decimate(x, r)`` of each column of ``columns``, compiled; ``columns`` is overwritten.

    ``columns``: (N, C), or (parts, N, w) as :func:`base_columns` lays them out, a part per thread (each thread's
    memory contiguous), the result then (kept samples, parts w). :func:`ilic_cli.filtering.decimate_matlab`'s
    filter, padding and kept samples; its rounding differs (1e-13 relative on the regressor's columns:
    ``tests/robot/test_identify.py``).
    """
    from ilic_cli.robot.kernel import filtfilt_kept  # deferred: numba's import and the cached machine code

    if r == 1:
        return columns
    split = columns if columns.ndim == 3 else columns[None]
    parts, n, c = split.shape
    keep = kept_indices(n, r)
    sections, k, gain = chebyshev_sections(r)
    pad = 3 * 8
    if n <= pad:
        raise ValueError(f"The length of the input vector x must be greater than padlen, which is {pad}.")
    # each part's output a contiguous page of its own (a column slice of one array would compile the kernel a second
    # time, for a strided output: 1.9 s of CPU), laid side by side at the end (a copy of the kept samples only)
    out = np.empty((parts, len(keep), c))
    ordered_map(lambda i: filtfilt_kept(split[i], sections, k, gain, pad, int(keep[0]), r, out[i], 0, c), range(parts))
    return out[0] if parts == 1 else np.ascontiguousarray(out.transpose(1, 0, 2)).reshape(len(keep), parts * c)


def plain_pages(shape: tuple[int, ...]) -> np.ndarray:
    """An uninitialised float64 array in anonymous memory of ordinary pages, populated when mapped (freed with the array).

    NumPy asks for transparent huge pages on large arrays; where the kernel
    must compact memory to find them (``defrag=madvise``), the first touch of
    the 835 MB of full-rate columns of a 10-minute 6-joint log measured
    0.5-3.5 s, against 0.5-0.7 s with ordinary pages touched one by one and
    0.4-0.5 s populated by the mapping (``MAP_POPULATE``, where there is one).
    """
    if not hasattr(mmap, "MAP_PRIVATE"):  # Windows: no anonymous private mappings by flags
        return np.empty(shape)
    size = max(8, 8 * math.prod(shape))
    buffer = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS | getattr(mmap, "MAP_POPULATE", 0))
    return np.frombuffer(buffer, dtype=np.float64, count=math.prod(shape)).reshape(shape)


def active_columns(robot: RobotModel, base: BaseParameters) -> np.ndarray:
    """``(n, b)``: True where base column ``c`` can be nonzero on joint ``j``'s rows.

    A joint's torque depends on the inertial parameters of the links below it
    (itself included) and on its own ``Ia, Fv, Fc, offset`` only; the regressor
    is exactly zero elsewhere.
    """
    k = len(PER_JOINT)
    below = np.zeros((robot.n, robot.n), dtype=bool)  # below[j, i]: link i is moved by joint j
    for i in range(robot.n):
        j = i
        while j >= 0:
            below[j, i] = True
            j = robot.parents[j]
    link = base.kept // k
    drive = base.kept % k >= len(INERTIAL)
    own = link[None, :] == np.arange(robot.n)[:, None]
    return np.where(drive[None, :], own, below[:, link])


def _joint_std(system: RobotSystem, e: np.ndarray) -> np.ndarray:
    return np.array([np.std(e[system.joint == j], ddof=1) for j in range(len(system.joints))])


def solve_system(system: RobotSystem, *, weighted: bool = True) -> Fit:
    """The (weighted) least-squares estimate of a stacked system (see the module's docstring)."""
    W, y = system.W, system.y
    if weighted:
        first = solve_tall(W, y, system.names, sigma=system.settings.sigma)
        sig = _joint_std(system, y - W @ first.theta)
        if not np.all(sig > 0):
            raise ValueError(f"a joint's error has zero spread ({dict(zip(system.joints, sig))}): rows cannot be weighted")
    else:
        sig = np.ones(len(system.joints))
    w = 1.0 / sig[system.joint]
    Ww, yw = W * w[:, None], y * w
    result = solve_tall(Ww, yw, system.names, sigma=system.settings.sigma)
    cov = result.cov if result.cov is not None and result.full_rank else result.sigma_rho**2 * pinv(Ww.T @ Ww)
    e = y - W @ result.theta
    return Fit(
        method="IDIM-WLS" if weighted else "IDIM-LS",
        names=system.names,
        theta=result.theta,
        covariance=cov,
        residual=e,
        joints=system.joints,
        joint_std=sig,
        result=result,
        relative_error_pct=relative_error_pct(y, W @ result.theta),
    )


def idim_ls(
    q: np.ndarray,
    tau: np.ndarray,
    fs_hz: float,
    robot: RobotModel,
    base: BaseParameters,
    settings: LSSettings = LSSettings(),
    *,
    weighted: bool = True,
    min_speed: float = 0.0,
    torque_held: bool = False,
) -> Fit:
    """n-joint IDIM-LS of the base parameters from measured ``q`` and ``tau`` (N, n); Gautier's weighted LS by default.

    ``min_speed`` and ``torque_held``: see :func:`prepare`.
    """
    return solve_system(prepare(q, tau, fs_hz, robot, base, settings, min_speed=min_speed, torque_held=torque_held), weighted=weighted)


def validation_error_pct(theta: np.ndarray, system: RobotSystem) -> float:
    """Relative error (%) of base parameters ``theta`` on another log's system (cross validation)."""
    return relative_error_pct(system.y, system.W @ np.asarray(theta, dtype=np.float64))


def essential_fit(system: RobotSystem, fit: Fit, sigma_max_pct: float) -> tuple[np.ndarray, Fit]:
    """The essential base parameters of ``fit`` and the fit of ``system`` with only them (the others removed, i.e. 0).

    Essential: ``%sigma <= sigma_max_pct`` (:func:`ilic_cli.idim_ilic.essential_mask`, the parameters IDIM-ILIC
    updates). The reduced fit's relative error against ``fit``'s says whether removing the others degrades the fit.
    """
    mask = essential_mask(fit.result, sigma_max_pct)
    if not mask.any():
        raise ValueError(f"no base parameter has %sigma <= {sigma_max_pct:g}: none is essential")
    names = tuple(n for n, e in zip(system.names, mask, strict=True) if e)
    return mask, solve_system(replace(system, W=system.W[:, mask], names=names), weighted=fit.method == "IDIM-WLS")
