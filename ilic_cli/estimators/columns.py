"""Regressor columns at the full rate built one at a time (issue 33: IDIM-LS on a 1-hour log in twice its columns).

:func:`ilic_cli.idim_ls.lsq_rows` decimates each column as soon as it is built; :class:`Derived` gives each column the
kinematics it reads, differentiated from the filtered position when first read and let go with the column, so the
velocity, the acceleration and the column never all live at once beside the log.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.derivatives import derivative
from ilic_cli.regressor import Kinematics, evaluated_later


class Derived(Kinematics):
    """The kinematics one column is built from: ``q``, ``qd``, ``qdd`` trimmed from the filtered position ``qf`` when
    the column first reads them (``shift_s``: interpolated that much later, as :func:`ilic_cli.idim_ls.held`), let go with the column;
    ``points``: the derivatives' stencil (:func:`ilic_cli.derivatives.derivative`); ``speed_noise``: as :class:`Kinematics`'."""

    def __init__(
        self, qf: np.ndarray, dt_s: float, trim: int, t: np.ndarray, shift_s: float, extra: dict[str, np.ndarray], points: int = 3, speed_noise: float = 0.0
    ) -> None:
        later = shift_s != 0.0
        fields = {
            "t": t,
            "sign_qd": None,
            "speed_noise": speed_noise,
            "extra": {k: evaluated_later(t, v, shift_s) for k, v in extra.items()} if later else extra,
        }
        for name, value in {**fields, "_source": (qf, dt_s, trim, t, shift_s, points), "_memo": {}}.items():
            object.__setattr__(self, name, value)

    def _signal(self, order: int) -> np.ndarray:
        memo: dict[int, np.ndarray] = self.__dict__["_memo"]
        if order not in memo:
            x, dt_s, trim, t, shift_s, points = self.__dict__["_source"]
            for _ in range(order):
                x = derivative(x, dt_s, points)
            x = x[trim:]
            memo[order] = x if shift_s == 0.0 else evaluated_later(t, x, shift_s)
        return memo[order]

    @property
    def q(self) -> np.ndarray:
        return self._signal(0)

    @property
    def qd(self) -> np.ndarray:
        return self._signal(1)

    @property
    def qdd(self) -> np.ndarray:
        return self._signal(2)
