"""DIDIM and IDIM-IV on the real EMPS recordings: the figures of docs/methods.md, to the printed digits.

Trained on ``DATA_EMPS.mat``; ``DATA_EMPS_PULSES.mat`` is held out: the
closed-loop replay's force error (``ilic replay``) and the benchmark's
open-loop figure (``ilic replay --open-loop``: RMSE mm, fit %). A figure
printed with d decimals holds when the computed value prints the same.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.clirun import run_cli
from tests.conftest import require_shared

ESTIMATES = {
    # docs/methods.md "Closed-loop identification": rigid-offset on DATA_EMPS.mat (DIDIM / IV replay the loop that ran: the
    # command from the same sample, acting at once; with the documented loop, one period late, DIDIM gave M = 93.72)
    "ls": {"M": "95.11", "Fv": "203.5", "Fc": "20.39", "offset": "-3.165"},
    "didim": {"M": "94.93", "Fv": "207.9", "Fc": "20.08", "offset": "-3.169"},
    "iv": {"M": "95.14", "Fv": "203.6", "Fc": "20.39", "offset": "-3.165"},
}
HELD_OUT = {
    # (structure, method): closed-loop force error % on PULSES (its recorded loop timing), open-loop RMSE mm, fit %
    # (open loop: the state from the first 20 samples only, the benchmark's protocol; issue 31)
    ("rigid-offset", "ls"): ("5.27", "8.38", "89.8"),
    ("rigid-offset", "didim"): ("5.16", "7.75", "90.6"),
    ("rigid-offset", "iv"): ("5.28", "8.38", "89.9"),
    ("asymmetric", "ls"): ("4.57", "13.04", "84.2"),
    ("asymmetric", "didim"): ("4.43", "12.35", "85.0"),
}


def decimals(text: str) -> int:
    return len(text.partition(".")[2])


def as_printed(x: float, text: str) -> str:
    return f"{x:.{decimals(text)}f}"


@pytest.fixture(scope="module")
def emps() -> Path:
    return require_shared()


@pytest.fixture(scope="module")
def rigid_doc(emps: Path) -> dict:
    res = run_cli("identify", str(emps / "DATA_EMPS.mat"), "--method", "all", "--format", "json")
    assert res.status == 0, res.stderr
    return json.loads(res.stdout)


def test_estimates_beside_idim_ls(rigid_doc: dict) -> None:
    for method, table in ESTIMATES.items():
        got = rigid_doc[method]["parameters"]
        for name, text in table.items():
            value = got[name]["value"]
            assert as_printed(value, text) == text, (method, name, value, text)
    assert rigid_doc["didim"]["converged"] and rigid_doc["didim"]["iterations"] == 2
    assert rigid_doc["iv"]["converged"] and rigid_doc["iv"]["iterations"] == 1


@pytest.mark.parametrize(("structure", "method"), list(HELD_OUT))
def test_held_out_pulses(emps: Path, tmp_path: Path, structure: str, method: str) -> None:
    force, rmse, fit = HELD_OUT[(structure, method)]
    out = tmp_path / "fit"
    res = run_cli("identify", str(emps / "DATA_EMPS.mat"), "--method", method, "--structure", structure, "--out", str(out), "--plots", "none")
    assert res.status == 0, res.stderr
    assert json.loads((out / "model.json").read_text())["method"] == {"ls": "IDIM-LS", "didim": "DIDIM", "iv": "IDIM-IV"}[method]
    pulses = str(emps / "DATA_EMPS_PULSES.mat")
    closed = run_cli("replay", pulses, "--model", str(out / "model.json"), "-o", str(tmp_path / "closed.mcap"))
    assert closed.status == 0, closed.stderr
    m = re.search(r"against the recording .*force error ([0-9.]+) %", closed.stderr)
    assert m is not None, closed.stderr
    assert as_printed(float(m.group(1)), force) == force, (m.group(1), force)
    opened = run_cli("replay", pulses, "--model", str(out / "model.json"), "-o", str(tmp_path / "open.mcap"), "--open-loop")
    assert opened.status == 0, opened.stderr
    m = re.search(r"RMSE ([0-9.]+) mm, fit ([0-9.]+) %", opened.stderr)
    assert m is not None, opened.stderr
    assert (as_printed(float(m.group(1)), rmse), as_printed(float(m.group(2)), fit)) == (rmse, fit), m.groups()


def test_documented_loop_on_request(emps: Path, tmp_path: Path) -> None:
    """docs/methods.md: "--pd-timing documented runs the documented loop": DIDIM M = 93.72 kg, the pulse run's force error 8.71 % / 8.36 %."""
    res = run_cli("identify", str(emps / "DATA_EMPS.mat"), "--method", "didim", "--pd-timing", "documented", "--format", "json", "--out", str(tmp_path / "d"))
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["loop_timing"] is None and "loop timing" not in res.stderr
    assert as_printed(doc["didim"]["parameters"]["M"]["value"], "93.72") == "93.72"
    pulses = str(emps / "DATA_EMPS_PULSES.mat")
    for timing, force in (("documented", "8.36"), ("recorded", "5.05")):
        out = run_cli("replay", pulses, "--model", str(tmp_path / "d" / "model.json"), "-o", str(tmp_path / f"{timing}.mcap"), "--pd-timing", timing)
        assert out.status == 0, out.stderr
        m = re.search(r"against the recording .*force error ([0-9.]+) %", out.stderr)
        assert m is not None and as_printed(float(m.group(1)), force) == force, (timing, out.stderr)
        # the recorded timing is announced on stderr, the documented loop is silent about it
        assert ("ilic: loop timing: The recorded command follows the PD law on the same sample's position" in out.stderr) == (timing == "recorded")
