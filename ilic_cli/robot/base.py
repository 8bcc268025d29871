"""Base parameters by numerical QR on random states (Gautier 1990; paper refs [15][17]).

The regressor of the standard parameters is stacked over random states and
factored by QR with column pivoting, ``Y P = Q R``. Its rank ``b`` (the one rank
rule of :func:`ilic_cli.lsq.rank_tolerance` on ``|R_ii|``) is the number of base
parameters; the first ``b`` pivoted columns are the standard parameters kept,
and every other column is a combination of them, ``Y_other = Y_kept K`` with
``K = R11^-1 R12``. So ``Y pi = Y_kept (pi_kept + K pi_other)``: each base
parameter is the standard parameter it keeps plus its coefficients times the
others (the regrouping), and a standard parameter with a zero column (the mass
of the first link) belongs to no base parameter.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.lsq import rank_tolerance
from ilic_cli.robot.model import RobotModel, regressor

ZERO_COEFFICIENT = 1e-10
"""A regrouping coefficient below this (relative to the largest) is rounding, shown and applied as 0."""


@dataclass(frozen=True)
class BaseParameters:
    """The base parameters of an arm and their regrouping of the standard ones.

    Attributes
    ----------
    standard_names : tuple of str
        Standard parameter names (:attr:`RobotModel.names`).
    kept : ndarray of int (b,)
        Column of the standard parameter each base parameter keeps, ascending.
    regrouping : ndarray (b, p)
        ``beta = regrouping @ pi``: 1 at the kept parameter, the coefficients of the others.
    rank_tolerance : float
        ``|R_ii|`` at or below which a pivoted column counts as dependent.
    rows : int
        Rows of the stacked random regressor.
    seed : int
        Seed of the random states.
    """

    standard_names: tuple[str, ...]
    kept: np.ndarray
    regrouping: np.ndarray
    rank_tolerance: float
    rows: int
    seed: int

    @property
    def b(self) -> int:
        return len(self.kept)

    @property
    def names(self) -> tuple[str, ...]:
        """Base parameter names: the kept standard name, with ``R`` appended when others are regrouped into it (``Izz_elbowR``)."""
        return tuple(self.standard_names[k] + ("R" if np.count_nonzero(row) > 1 else "") for k, row in zip(self.kept, self.regrouping))

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """Standard parameters that belong to no base parameter (their regressor column is zero)."""
        return tuple(n for n, col in zip(self.standard_names, self.regrouping.T) if not col.any())

    def values(self, pi: np.ndarray) -> np.ndarray:
        """The base parameters ``beta`` of a standard parameter vector."""
        return self.regrouping @ np.asarray(pi, dtype=np.float64)

    def columns(self, Y: np.ndarray) -> np.ndarray:
        """The base regressor ``Y_b`` (the kept columns of the standard ``Y``, last axis)."""
        return np.asarray(Y)[..., self.kept]

    def combination(self, i: int) -> list[tuple[str, float]]:
        """``(standard name, coefficient)`` of base parameter ``i``, the kept one first."""
        row = self.regrouping[i]
        k = int(self.kept[i])
        return [(self.standard_names[k], float(row[k]))] + [(self.standard_names[j], float(row[j])) for j in np.flatnonzero(row) if j != k]

    def table(self) -> str:
        """One line per base parameter: ``base 3  Izz_elbowR = Izz_elbow + 0.5 mx_tool ...``."""
        lines = []
        width = max((len(n) for n in self.names), default=0)
        for i, name in enumerate(self.names):
            terms = self.combination(i)
            text = terms[0][0] + "".join(f" {'-' if c < 0 else '+'} {abs(c):.6g} {n}" for n, c in terms[1:])
            lines.append(f"base {i + 1:>2}  {name:<{width}} = {text}")
        if self.unidentifiable:
            lines.append(f"no base parameter holds: {', '.join(self.unidentifiable)}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {
            "count": self.b,
            "base": [{"name": n, "combination": {s: c for s, c in self.combination(i)}} for i, n in enumerate(self.names)],
            "unidentifiable": list(self.unidentifiable),
            "rank_tolerance": self.rank_tolerance,
            "rows": self.rows,
            "seed": self.seed,
        }


def random_states(robot: RobotModel, samples: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random ``q`` (uniform over a turn, or +-1 m prismatic), ``qd``, ``qdd`` (standard normal), each (samples, n)."""
    rng = np.random.default_rng(seed)
    span = np.where(np.array(robot.kinds) == "prismatic", 1.0, np.pi)
    q = rng.uniform(-1.0, 1.0, (samples, robot.n)) * span
    return q, rng.standard_normal((samples, robot.n)), rng.standard_normal((samples, robot.n))


def stacked_regressor(robot: RobotModel, samples: int | None = None, seed: int = 0) -> np.ndarray:
    """The standard regressor stacked over random states (default: 10 rows per standard parameter)."""
    samples = samples or max(20, (10 * len(robot.names)) // robot.n + 1)
    return regressor(robot, *random_states(robot, samples, seed))


def flapack() -> Any:
    """scipy's LAPACK wrappers (the module behind ``scipy.linalg.lapack``), loaded without importing ``scipy.linalg``.

    ``scipy.linalg``'s package imports some 0.17 s of modules (its array-API layer,
    ``numpy.f2py``, ``numpy.ma``, ``numpy.testing``) before any routine runs; its
    extension ``_flapack`` alone loads in 4-5 ms. When ``scipy.linalg`` is imported
    already, its own module. Not put in ``sys.modules``: a later ``import
    scipy.linalg`` loads the package as usual (CPython hands it the same extension).
    """
    loaded = sys.modules.get("scipy.linalg._flapack")
    if loaded is not None:
        return loaded
    import scipy  # deferred: the top package only (numba's import did already), not scipy.linalg

    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = Path(scipy.__file__ or "").parent / "linalg" / f"_flapack{suffix}"
        extension = importlib.util.spec_from_file_location("scipy.linalg._flapack", path) if path.is_file() else None
        if extension is not None and extension.loader is not None:
            module = importlib.util.module_from_spec(extension)
            extension.loader.exec_module(module)
            return module
    from scipy.linalg import _flapack  # scipy laid out otherwise: through its package

    return _flapack


def pivoted_qr(Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``R, perm`` of ``scipy.linalg.qr(Y, mode="economic", pivoting=True)`` (rows >= columns), bit for bit: the same LAPACK call.

    LAPACK's ``dgeqp3`` with the workspace it asks for, as scipy's ``qr`` calls it (``Q`` is not formed).
    """
    geqp3 = flapack().dgeqp3
    Y = np.asarray_chkfinite(Y, dtype=np.float64)
    lwork = int(geqp3(Y, lwork=-1)[-2][0].real)
    qr, jpvt, _, _, info = geqp3(Y, lwork=lwork)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqp3")
    return np.triu(qr[: Y.shape[1], :]), jpvt - 1


def upper_solve(U: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``scipy.linalg.solve_triangular(U, B)`` (``U`` upper triangular, not Fortran-ordered), bit for bit: LAPACK's ``dtrtrs`` on ``U'`` as scipy calls it."""
    if B.size == 0:
        return np.empty(B.shape)
    U, B = np.asarray_chkfinite(U, dtype=np.float64), np.asarray_chkfinite(B, dtype=np.float64)
    trtrs = flapack().dtrtrs
    x, info = trtrs(U, B, lower=False, trans=0, unitdiag=False) if U.flags.f_contiguous else trtrs(U.T, B, lower=True, trans=True, unitdiag=False)
    if info > 0:
        raise np.linalg.LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    if info < 0:
        raise ValueError(f"illegal value in {-info}-th argument of internal trtrs")
    return np.asarray(x)


def base_parameters(robot: RobotModel, *, samples: int | None = None, seed: int = 0) -> BaseParameters:
    """The base parameters of ``robot`` by QR with column pivoting of :func:`stacked_regressor` (:func:`pivoted_qr`, :func:`upper_solve`)."""
    Y = stacked_regressor(robot, samples, seed)
    R, perm = pivoted_qr(Y)
    d = np.abs(np.diag(R))
    tol = float(rank_tolerance(d[0], *Y.shape))
    b = int(np.sum(d > tol))
    K = upper_solve(R[:b, :b], R[:b, b:])
    K[np.abs(K) < ZERO_COEFFICIENT * max(1.0, float(np.abs(K).max(initial=0.0)))] = 0.0
    p = Y.shape[1]
    G = np.zeros((b, p))
    G[np.arange(b), perm[:b]] = 1.0
    G[:, perm[b:]] = K
    order = np.argsort(perm[:b])
    return BaseParameters(tuple(robot.names), perm[:b][order].astype(np.intp), G[order], tol, Y.shape[0], seed)
