"""The inverse model's baseline: what the rigid model must already account for before an effect is sought.

Two things a rigid fit leaves in the residual without any missing physics:

* **The sample hold.** When the logged force is the held drive command
  (``u[k]`` applied over ``[kT, (k+1)T)``: the EMPS recordings' ``gtau*vir``,
  our plant with ``tau_sensor = "command"``), it equals the mean over that
  interval of the inverse model, i.e. the model half a sample later. The
  regressor is therefore evaluated at ``t_k + T/2`` (:func:`ilic_cli.idim_ls.held`). For the
  filtered kinematics (100 Hz position filter at 1 kHz), the value at the
  midpoint and the mean over the interval differ by ``O((2 pi f T)^2 / 24)``,
  below 1e-3. ``delay`` is then only a lag beyond the hold.
* **The Coulomb switch at velocity reversals.** The force steps by ``2 Fc``
  when the velocity changes sign, or sticks in between, but the instant is
  known only through the low-passed velocity, whose zero crossing is biased
  when the deceleration differs on the two sides of the reversal (it does: the
  friction step itself). That bias reads as timing (a spurious delay of
  0.1-0.2 ms on clean PD logs of the EMPS reference, after the hold). The
  rows whose decimation span touches a reversal are left out
  (:func:`reversal_samples`, applied by :func:`ilic_cli.diagnosis.select.moving_rows`),
  as standstill rows are.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.idim_ls import held, rebuilt
from ilic_cli.prepare import hold_of

__all__ = ["held", "hold_s", "rebuilt", "reversal_samples"]


hold_s = hold_of
"""Half a sample period when the logged force is the held command (:func:`ilic_cli.prepare.hold_of`, the one definition)."""


def reversal_samples(qd: np.ndarray) -> np.ndarray:
    """Full-rate samples on either side of a change of sign of ``qd`` (boolean mask).

    A sample that is exactly zero between two of opposite sign is marked too.
    """
    s = np.sign(qd)
    change = s[1:] != s[:-1]
    out = np.zeros(len(qd), dtype=bool)
    out[:-1] |= change
    out[1:] |= change
    return out
