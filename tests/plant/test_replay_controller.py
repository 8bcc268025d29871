"""The controller a replay takes from a log (``plant.replay.controller_from_log``), read through the typed view ``RunLog.controller``."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.errors import SimulationError
from ilic_cli.runlog import RunLog
from plant.controllers import CTCSettings, PDSettings
from plant.replay import controller_from_log, records_controller


def _log(meta: dict[str, object], vir: bool = False) -> RunLog:
    t = np.arange(5) * 1e-3
    chans = {"t": t, "q": np.zeros(5), **({"vir": np.zeros(5)} if vir else {})}
    return RunLog(chans, {}, {"source": "run.mat", **meta})


def test_a_pd_log_gives_its_gains_and_drive_gain() -> None:
    log = _log({"controller": {"kind": "PD", "kp": 160.0, "kv": 243.0, "vmax": 5.0}, "drive_gain": 35.0})
    assert controller_from_log(log) == PDSettings(kp=160.0, kv=243.0, gtau=35.0, vmax=5.0)
    # the controller's own gtau stands for a drive gain the log does not give at the top level
    assert controller_from_log(_log({"controller": {"kind": "pd", "kp": 1.0, "kv": 2.0, "gtau": 3.0}})).gtau == 3.0


def test_a_log_with_vir_and_no_controller_entry_is_a_pd_loop_of_its_top_level_gains() -> None:
    log = _log({"kp": 10.0, "kv": 20.0, "drive_gain": 30.0}, vir=True)
    assert records_controller(log) and log.controller is None
    assert controller_from_log(log) == PDSettings(kp=10.0, kv=20.0, gtau=30.0)


def test_a_ctc_log_is_replayed_without_the_online_update() -> None:
    ctl = controller_from_log(_log({"controller": {"kind": "ctc", "omega": 50.0, "window_s": 3.0, "ilic": True, "Kp": 1.0}}))
    assert isinstance(ctl, CTCSettings) and (ctl.omega, ctl.window_s, ctl.ilic) == (50.0, 3.0, False)


@pytest.mark.parametrize(
    ("meta", "vir", "message"),
    [
        ({}, False, "run.mat: the log records no controller"),
        ({"controller": {"kind": "pd", "kp": 1.0, "kv": 2.0}}, False, "run.mat: the log's PD controller lacks kp, kv or drive_gain"),
        ({"controller": {"kind": "pd", "kp": "fast", "kv": 2.0}, "drive_gain": 1.0}, False, "lacks kp, kv or drive_gain"),
        ({"kp": 1.0}, True, "lacks kp, kv or drive_gain"),
    ],
)
def test_a_log_without_a_usable_controller_is_refused(meta: dict[str, object], vir: bool, message: str) -> None:
    with pytest.raises(SimulationError) as info:
        controller_from_log(_log(meta, vir))
    assert message in info.value.message()
