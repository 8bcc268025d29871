"""How much IDIM-LS's Fv and Fc rest on the sign in the Coulomb column: the shape of the friction near zero speed (issue 29).

The rigid model's Coulomb column is ``sign(qd)`` (the expected sign where rows at rest are left out: :data:`ilic_cli.usable.SIGN_RULE`),
as a drive with stiction has it. A simulator often writes ``Fc tanh(qd/vc)`` instead, and a real drive's friction rises over a
speed too; the least squares then put the difference into Fv and Fc. On the independent simulator's clean trapezoids and
S-curves at 1 kHz (``tests.corpus.independent``, ``vc`` 10 % of the cruise speed) ``identify --method ls`` was 4.7-12.9 % off Fv
and 7.7-8.8 % off Fc, exit 0; with the law's column, within 0.7 %.

Whether the law or the sign is the plant's the inverse model cannot say: on logs with stiction the rows prefer a law too (the
robot corpus's clean dwell-and-move logs: ``vc`` 1-4.5 % of the top speed at F = 30-240), a sampled drive's command and the
filters smoothing the sign. The closed loop decides that (``ilic diagnose``'s friction law). What the rows do say is how much the
estimates depend on it: :func:`friction_shape` fits the model with ``tanh(qd/vc)`` in place of the sign over
:func:`ilic_cli.effects.grids.smoothing_speeds` (every second point) and states the best ``vc`` and how far Fv and Fc move there.
``identify`` warns (:data:`SHAPE_RULE`) when that is more than :data:`SHAPE_MOVE` and beyond 1.96 robust standard deviations;
measured, the robot corpus's clean logs (stiction) move them by at most 1 %, ``DATA_EMPS.mat`` by 0.8 % with its best ``vc`` at the
grid's lower edge (docs/methods.md).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ilic_cli.effects.definition import Z95
from ilic_cli.effects.grids import smoothing_speeds, speed_scale
from ilic_cli.idim_ls import LSSettings, decimated_systems, differentiated, filtered_position, min_samples
from ilic_cli.lsq import finite_or_none, lstsq
from ilic_cli.prepare import PreparedLog
from ilic_cli.regressor import Column, Kinematics, Model
from ilic_cli.usable import identification_speed_noise

SHAPE_MOVE = 0.02
"""A friction shape moves Fv or Fc materially beyond this relative change: the 2 % ``identify --method ls`` is held to (issue 29)."""

SPEEDS = slice(None, None, 2)
"""The points of :func:`~ilic_cli.effects.grids.smoothing_speeds` fitted: every second (16, a factor 1.36 apart; the columns are
built one at a time at the log's rate, 16 more than the model's)."""

SHAPE_RULE = (
    "the model is fitted again with tanh(qd/vc) in place of the sign in its Coulomb column, vc over 16 speeds from 0.2 % to 20 % of "
    f"the top speed; a warning when the rows prefer a vc inside that range and Fv or Fc moves there by more than {100 * SHAPE_MOVE:g} % "
    "and beyond 1.96 robust standard deviations: the estimates then rest on the friction's shape near zero speed, which only the "
    "closed loop tells (ilic diagnose)"
)
"""The friction-shape check in words (the reports state it)."""

MOVED = ("Fv", "Fc")
"""The estimates whose move the check states."""


@dataclass(frozen=True)
class FrictionShape:
    """The rows' best smoothed Coulomb law and how far it moves the estimates (:func:`friction_shape`).

    Attributes
    ----------
    vc : float
        The smoothing speed whose fit leaves the least residual (m/s or rad/s).
    top_speed : float
        The log's top speed (:func:`~ilic_cli.effects.grids.speed_scale`), the grid's scale.
    at_edge : bool
        ``vc`` is the grid's lowest (the sign fits as well) or highest point (no shape inside the range).
    preferred : bool
        The law's residual is below the sign's.
    change : dict
        Fv, Fc -> relative change of the estimate with the law.
    z : dict
        Fv, Fc -> the change in the sign's fit's robust standard deviations.
    values : dict
        Fv, Fc -> the estimates with the law.
    """

    vc: float
    top_speed: float
    at_edge: bool
    preferred: bool
    change: dict[str, float]
    z: dict[str, float]
    values: dict[str, float]

    @property
    def material(self) -> bool:
        """Whether ``identify`` warns: a preferred law inside the range moves Fv or Fc by more than :data:`SHAPE_MOVE` and 1.96 σ."""
        return self.preferred and not self.at_edge and any(abs(self.change[n]) > SHAPE_MOVE and abs(self.z[n]) > Z95 for n in MOVED)

    def warning(self, unit: str, units: Mapping[str, str]) -> str:
        """The warning ``identify`` gives when :attr:`material` (``unit``: the speed's; ``units``: Fv's and Fc's)."""
        moves = " and ".join(f"{n} by {100 * self.change[n]:+.1f} % (to {self.values[n]:.4g} {units[n]})" for n in MOVED)
        return (
            f"friction near zero speed: a smoothed Coulomb law, Fc tanh(qd/vc) with vc about {self.vc:.3g} {unit} "
            f"({100 * self.vc / self.top_speed:.2g} % of the top speed), fits the rows better than the sign and moves {moves}: "
            "Fv and Fc rest on the friction's shape there, which the inverse model does not decide; `ilic diagnose` judges it on the closed loop"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "smoothing_speed": finite_or_none(self.vc),
            "top_speed": finite_or_none(self.top_speed),
            "at_edge_of_range": self.at_edge,
            "preferred_to_the_sign": self.preferred,
            "change": {n: finite_or_none(v) for n, v in self.change.items()},
            "change_in_robust_std": {n: finite_or_none(v) for n, v in self.z.items()},
            "with_the_law": {n: finite_or_none(v) for n, v in self.values.items()},
            "material": self.material,
            "rule": SHAPE_RULE,
        }


def friction_shape(W: np.ndarray, y: np.ndarray, laws: np.ndarray, speeds: np.ndarray, names: tuple[str, ...], robust: np.ndarray, top: float) -> FrictionShape:
    """The shape the rows ``(W, y)`` prefer: each column of ``laws`` (``tanh(qd/vc)`` at ``speeds``, decimated on the same rows) in
    place of the ``Fc`` column of ``W`` (``names``), the least residual's; ``robust``: the sign's fit's robust standard deviations."""
    theta0, rss0 = lstsq(W, y)
    fc = names.index("Fc")
    fits = []
    for j in range(laws.shape[1]):
        Wj = W.copy()
        Wj[:, fc] = laws[:, j]
        fits.append(lstsq(Wj, y))
    best = int(np.argmin([rss for _, rss in fits]))
    theta, rss = fits[best]
    idx = {n: names.index(n) for n in MOVED}
    return FrictionShape(
        vc=float(speeds[best]),
        top_speed=top,
        at_edge=best in (0, len(speeds) - 1),
        preferred=rss < rss0,
        change={n: float(theta[i] / theta0[i] - 1.0) if theta0[i] != 0 else float("nan") for n, i in idx.items()},
        z={n: float((theta[i] - theta0[i]) / robust[i]) if robust[i] > 0 else float("nan") for n, i in idx.items()},
        values={n: float(theta[i]) for n, i in idx.items()},
    )


def _law(vc: float) -> Callable[[Kinematics], np.ndarray]:
    """The column ``tanh(qd / vc)``."""
    return lambda k: np.tanh(k.qd / vc)


def shape_of(prepared: PreparedLog, model: Model, settings: LSSettings, hold_s: float, robust: np.ndarray) -> FrictionShape | None:
    """:func:`friction_shape` on the rows IDIM-LS fits of ``prepared`` with ``model`` (``settings`` at the log's rate, its
    regressor ``hold_s`` late, as :func:`ilic_cli.idim_ls.idim_ls` was run); ``None`` when the model's Coulomb friction is not its
    plain ``Fc`` column alone (an asymmetric structure, effect columns: the sign is in those too) or it has no Fv, and when the
    rows are fewer than the model's columns and the laws' (:func:`ilic_cli.idim_ls.lsq_rows`' rule)."""
    if [c.name for c in model.columns if c.name not in ("M", "offset")] != list(MOVED):
        return None
    log, fs = prepared.log, prepared.fs_hz
    spans = prepared.segments or ((0, len(log)),)
    qd = [differentiated(filtered_position(log["q"][a:b], fs, settings), fs, settings)[0] for a, b in spans if b - a >= min_samples(settings)]
    top = speed_scale(np.concatenate(qd))
    speeds = smoothing_speeds(top)[SPEEDS]
    both = model.extend(*(Column(f"tanh{j}", "", _law(float(vc))) for j, vc in enumerate(speeds)))
    try:
        Wall, y, _, _ = decimated_systems(
            log.t, log["q"], log["tau"], fs, both, settings, prepared.valid, prepared.segments, hold_s, identification_speed_noise(prepared)
        )
    except ValueError:  # fewer rows than the model and its laws have columns (a drive saturated most of the log): not asked
        return None
    b = len(model.columns)
    return friction_shape(Wall[:, :b], y, Wall[:, b:], speeds, model.names, robust, top)
