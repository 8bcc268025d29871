"""Physical consistency of identified base parameters (issue 30, item 4; Wensing, Kim, Slotine 2018).

A link's standard parameters are physically consistent when its pseudo-inertia
``J = [[Sigma, h], [h', m]]`` (``Sigma = tr(I)/2 1 - I``, ``h = m c``, ``I`` about
the frame origin) is positive definite; a drive's when ``Ia, Fv, Fc >= 0``.

:func:`consistent_fit` looks for such a standard set whose base parameters are
the identified ones: the log-Cholesky parametrisation ``J = U U'`` (``U`` upper
triangular with ``exp`` on its diagonal: every value is consistent), the drive
parameters bounded below by 0, and ``scipy.optimize.least_squares`` on the
base parameters' errors weighted by the estimate's covariance, plus a light pull
(:data:`PRIOR_WEIGHT`) of the standard set towards the URDF's, which fixes the
standard parameters the base ones leave free. The identified set *admits* a
consistent standard set when that fit reproduces it (a Mahalanobis distance below
:data:`ADMIT_SIGMA`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.robot.base import BaseParameters
from ilic_cli.robot.model import DRIVE, INERTIAL, PER_JOINT, RobotModel

PRIOR_WEIGHT = 1e-4
"""Weight of the pull towards the URDF's inertial parameters (a relative change of 1 costs 1e-4 of a standard deviation of the estimate)."""

ADMIT_SIGMA = 0.01
"""The consistent fit reproduces the identified base parameters when its Mahalanobis distance from them is below this."""


def pseudo_inertia(p: np.ndarray) -> np.ndarray:
    """The 4 x 4 pseudo-inertia of a link's 10 inertial parameters (pinocchio's order)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = p
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    J[:3, 3] = J[3, :3] = (hx, hy, hz)
    J[3, 3] = m
    return J


def inertial_of(J: np.ndarray) -> np.ndarray:
    """The 10 inertial parameters of a pseudo-inertia (inverse of :func:`pseudo_inertia`)."""
    sigma = J[:3, :3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    h = J[:3, 3]
    return np.array([J[3, 3], h[0], h[1], h[2], inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]])


_UPPER = np.triu_indices(4, 1)


def _cholesky_upper(J: np.ndarray) -> np.ndarray:
    """``U`` upper triangular with ``J = U U'`` (Cholesky of the reversed matrix)."""
    P = np.eye(4)[::-1]
    return P @ np.linalg.cholesky(P @ J @ P) @ P


def _link_theta(p: np.ndarray) -> np.ndarray:
    """Log-Cholesky coordinates (4 log-diagonal, 6 upper) of a consistent link."""
    U = _cholesky_upper(pseudo_inertia(p))
    return np.concatenate([np.log(np.diag(U)), U[_UPPER]])


def _link_params(theta: np.ndarray) -> np.ndarray:
    U = np.diag(np.exp(theta[:4]))
    U[_UPPER] = theta[4:]
    return inertial_of(U @ U.T)


@dataclass(frozen=True)
class Consistency:
    """A physically consistent standard set fitted to identified base parameters.

    Attributes
    ----------
    standard : ndarray (14 n,)
        The consistent standard parameters.
    base : ndarray (b,)
        Their base parameters.
    z : ndarray (b,)
        ``(base - identified) / std``: what consistency moves each base parameter by.
    distance : float
        Mahalanobis distance of ``base`` from the identified set (its covariance).
    admits : bool
        ``distance`` below :data:`ADMIT_SIGMA`: the identified set has a consistent standard set.
    within_noise : bool
        ``distance**2`` within the 99 % quantile of chi-square with ``b`` degrees of
        freedom: the consistent set is as likely as the estimate's own noise allows.
    names : tuple of str
        Base parameter names.
    identified_violations : tuple of str
        The identified base parameters that break a rule by themselves (a negative
        ``Ia``, ``Fv`` or ``Fc`` kept alone, a negative mass kept alone).
    """

    standard: np.ndarray
    base: np.ndarray
    z: np.ndarray
    distance: float
    admits: bool
    within_noise: bool
    names: tuple[str, ...]
    identified_violations: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "admits_consistent_standard_set": self.admits,
            "within_noise": self.within_noise,
            "mahalanobis_distance": self.distance,
            "max_abs_z": float(np.max(np.abs(self.z))) if len(self.z) else 0.0,
            "violations": list(self.identified_violations),
            "base": dict(zip(self.names, self.base.tolist())),
        }


def link_consistent(pi: np.ndarray, robot: RobotModel) -> np.ndarray:
    """Per link: pseudo-inertia positive definite (mass > 0 follows) and ``Ia, Fv, Fc >= 0``."""
    out = []
    for j in range(robot.n):
        p = np.asarray(pi)[len(PER_JOINT) * j : len(PER_JOINT) * (j + 1)]
        pd = bool(np.all(np.linalg.eigvalsh(pseudo_inertia(p[: len(INERTIAL)])) > 0))
        out.append(pd and bool(np.all(p[len(INERTIAL) : len(INERTIAL) + 3] >= 0)))
    return np.array(out)


def _violations(base: BaseParameters, beta: np.ndarray) -> tuple[str, ...]:
    bad = []
    for i, name in enumerate(base.names):
        terms = base.combination(i)
        kind = base.standard_names[int(base.kept[i])].split("_", 1)[0]
        if len(terms) == 1 and kind in ("m", "Ia", "Fv", "Fc") and beta[i] < 0:
            bad.append(name)
    return tuple(bad)


def consistent_fit(robot: RobotModel, base: BaseParameters, theta: np.ndarray, covariance: np.ndarray, prior: np.ndarray | None = None) -> Consistency:
    """The physically consistent standard set closest to identified base parameters ``theta`` (see the module's docstring).

    Parameters
    ----------
    robot, base : RobotModel, BaseParameters
        The arm and its base parameters.
    theta, covariance : ndarray
        The identified base parameters and their covariance (:class:`ilic_cli.robot.idim.Fit`).
    prior : ndarray, optional
        The standard set to pull towards (default: the URDF's, with ``Ia = 0``); its links must be consistent.
    """
    from scipy.optimize import least_squares  # deferred: scipy.optimize and scipy.stats cost ~0.5 s of import
    from scipy.stats import chi2  # deferred with scipy.optimize, the same reason

    theta = np.asarray(theta, dtype=np.float64)
    std = np.sqrt(np.clip(np.diag(covariance), 1e-300, None))
    prior = np.array(robot.standard if prior is None else prior, dtype=np.float64)
    n, k = robot.n, len(PER_JOINT)
    # the pull concerns the links' inertial parameters only (a drive's parameters are base parameters by themselves),
    # each relative to its own size or a hundredth of the link's largest
    inertial = np.array([PER_JOINT[c % k] in INERTIAL for c in range(k * n)])
    link_max = np.repeat([np.abs(prior[k * j : k * j + len(INERTIAL)]).max() for j in range(n)], k)
    scale = np.maximum(np.abs(prior), 1e-2 * link_max + 1e-12)
    # x: per joint 10 log-Cholesky coordinates, then Ia, Fv, Fc (>= 0), offset
    x0_list: list[Any] = []
    lo_list: list[float] = []
    for j in range(n):
        p = prior[k * j : k * (j + 1)]
        x0_list += [*_link_theta(p[: len(INERTIAL)]), *np.maximum(p[len(INERTIAL) : len(INERTIAL) + 3], 0.0), p[-1]]
        lo_list += [-np.inf] * len(INERTIAL) + [0.0] * 3 + [-np.inf]
    x0, lo = np.array(x0_list), np.array(lo_list)

    def standard(x: np.ndarray) -> np.ndarray:
        pi = np.empty(k * n)
        for j in range(n):
            xj = x[k * j : k * (j + 1)]
            pi[k * j : k * j + len(INERTIAL)] = _link_params(xj[: len(INERTIAL)])
            pi[k * j + len(INERTIAL) : k * (j + 1)] = xj[len(INERTIAL) :]
        return pi

    # whitened by the full covariance: an error along a well-determined combination costs what it costs in torque
    white = np.linalg.inv(np.linalg.cholesky(np.asarray(covariance, dtype=np.float64) + np.diag(std**2) * 1e-12))

    def residual(x: np.ndarray) -> np.ndarray:
        pi = standard(x)
        return np.concatenate([white @ (base.values(pi) - theta), PRIOR_WEIGHT * ((pi - prior) / scale)[inertial]])

    # the friction of the identified set as the start where it is already >= 0 (it is a base parameter alone)
    start = x0.copy()
    for i in range(base.b):
        kept = int(base.kept[i])
        if len(base.combination(i)) == 1 and PER_JOINT[kept % k] in DRIVE:
            start[kept] = max(theta[i], 0.0) if PER_JOINT[kept % k] != "offset" else theta[i]
    sol = least_squares(residual, np.maximum(start, lo), bounds=(lo, np.full_like(lo, np.inf)), method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
    pi = standard(sol.x)
    beta = base.values(pi)
    z = (beta - theta) / std
    distance = float(np.linalg.norm(white @ (beta - theta)))
    return Consistency(
        standard=pi,
        base=beta,
        z=z,
        distance=distance,
        admits=distance < ADMIT_SIGMA,
        within_noise=bool(distance**2 <= chi2.ppf(0.99, len(theta))),
        names=base.names,
        identified_violations=_violations(base, theta),
    )
