"""The typed views of a log's metadata (:class:`~ilic_cli.runlog.Controller`, :class:`~ilic_cli.runlog.Sensor`,
:class:`~ilic_cli.runlog.Provenance`): what each reads from the serialised dictionary the readers fill."""

from __future__ import annotations

import numpy as np

from ilic_cli.runlog import Controller, RunLog


def _log(units: dict[str, str] | None = None, **meta: object) -> RunLog:
    t = np.arange(5) * 1e-3
    return RunLog({"t": t, "q": t, "tau": t}, units or {}, dict(meta))


def test_pd_controller_reads_its_gains_and_the_drive_gain() -> None:
    log = _log(controller={"kind": "PD", "kp": 160.18, "kv": 243.45}, drive_gain=35.15)
    ctl = log.controller
    assert ctl is not None and (ctl.kind, ctl.kp, ctl.kv, ctl.drive_gain) == ("pd", 160.18, 243.45, 35.15)
    # gains at the top level and the controller's own gtau, as older logs write them
    old = Controller.from_meta({"controller": {"kind": "pd", "gtau": 2.0}, "kp": 1.0, "kv": 3.0})
    assert old is not None and (old.kp, old.kv, old.drive_gain) == (1.0, 3.0, 2.0)


def test_no_controller_is_none_and_a_missing_gain_is_none() -> None:
    assert _log().controller is None
    ctl = _log(controller={"kind": "ctc", "omega": 30.0}).controller
    assert ctl is not None and ctl.kind == "ctc" and ctl.kp is None and ctl.settings["omega"] == 30.0


def test_sensor_joint_type_from_the_position_unit_and_vertical_from_the_metadata() -> None:
    rev = _log({"q": "rad", "tau": "N·m"}, joint="shoulder", sample_rate_hz=500).sensor
    assert (rev.joint, rev.joint_type, rev.position_unit, rev.force_unit, rev.sample_rate_hz) == ("shoulder", "revolute", "rad", "N·m", 500.0)
    lin = _log(orientation="Vertical").sensor
    assert lin.joint_type == "prismatic" and lin.vertical and lin.joint is None
    assert not _log(vertical=False).sensor.vertical and _log(axis_vertical="yes").sensor.vertical


def test_provenance() -> None:
    p = _log(source="/x/a.mcap", true_parameters={"M": 95.0}, start_time_ns=12, machine=7).provenance
    assert (p.source, p.true_parameters, p.start_time_ns, p.machine, p.replay_of) == ("/x/a.mcap", {"M": 95.0}, 12, "7", None)


def test_provenance_start_is_a_whole_number_or_none() -> None:
    """A start the log does not give as a whole number is left out, never rounded nor raised on (a CSV's text, a ROS stamp)."""
    big = 1_733_000_000_123_456_789  # beyond a float's exact integers: parsed from its text, not through float
    assert _log(start_time_ns=str(big)).provenance.start_time_ns == big
    assert _log(start_time_ns=2.0e9).provenance.start_time_ns == 2_000_000_000
    for bad in ("yesterday", 1.5, True, None, [1]):
        assert _log(start_time_ns=bad).provenance.start_time_ns is None
