"""The noise the measured position puts in the IDIM system's columns, realised through the same derivation
(:func:`noise_kinematics`), for the least squares corrected for it (:func:`ilic_cli.diagnosis.system.column_noise`,
:func:`ilic_cli.lsq.noise_corrected_lstsq`; a flexibility's columns, issue 29).

The rest of the system's fits are plain least squares: their columns' noise is small beside their signal. A
flexibility's column is the position's fourth derivative, low-passed at its resonance: on the robot corpus's 200 kg
multisine at 500 Hz (s3340) plain least squares fitted the mass behind the spring 34 % low at the truth's resonance and
damping with the sensor's noise, 0.5 % without it; corrected, 10 %.
"""

from __future__ import annotations

import numpy as np

from ilic_cli.idim_ls import IDIMData, differentiated, filtered_position
from ilic_cli.regressor import Kinematics


def noise_kinematics(data: IDIMData, seed: int) -> Kinematics:
    """Kinematics of white position noise of ``data.position_noise_std``, derived as ``data``'s were (the position
    filter, the derivatives, the trim: :func:`ilic_cli.idim_ls.filtered_position`, :func:`~ilic_cli.idim_ls.differentiated`;
    the shift of :func:`~ilic_cli.idim_ls.held`): one realisation of the noise the measured position puts in the
    regressor's columns, drawn from ``seed``."""
    t = data.kin.t
    assert t is not None
    n = np.random.default_rng(seed).standard_normal(len(t) + data.settings.trim) * data.position_noise_std
    kin = Kinematics(*differentiated(filtered_position(n, data.fs_hz, data.settings), data.fs_hz, data.settings), t=t)
    return kin.later(data.shift_s) if data.shift_s else kin
