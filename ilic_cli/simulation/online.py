"""IDIM-ILIC as the closed loop's online update: the function :func:`plant.closed_loop.simulate_loop` is handed.

The plant knows no estimator (:class:`plant.closed_loop.OnlineUpdate`); a caller that runs the CTC with
``CTCSettings.ilic`` passes :func:`ilic_update`, which estimates each full window with
:func:`ilic_cli.idim_ilic.estimate_window` (paper eqs. 17-24) and keeps the essential parameters only
(:func:`ilic_cli.idim_ilic.update_parameters`).
"""

from __future__ import annotations

import numpy as np

from ilic_cli.idim_ilic import ILICSettings, WindowEstimate, estimate_window, update_parameters
from plant.closed_loop import LoopWindow


def ilic_update(chi: np.ndarray, window: LoopWindow) -> tuple[np.ndarray, WindowEstimate]:
    """The parameters after ``window`` (its essential estimates replace ``chi``'s) and the window's estimate.

    The IDIM-ILIC settings are the controller's (``window_s``, ``cutoff_hz``, ``sigma_max_pct``).
    """
    ctl = window.controller
    settings = ILICSettings(window_s=ctl.window_s, cutoff_hz=ctl.cutoff_hz, sigma_max_pct=ctl.sigma_max_pct)
    est = estimate_window(
        window.model,
        window.qd_ref,
        window.qdd_ref,
        window.tau,
        window.fs_hz,
        settings,
        q_ref=window.q_ref,
        q=window.q,
        t=window.t,
        k=window.k,
    )
    return update_parameters(chi, est), est
