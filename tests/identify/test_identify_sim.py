"""``ilic identify`` on a simulated paper-sim log recovers the paper's Table I (section VI-E).

Tolerance (``fixtures/paper_table1.json``): window k = 1 at least as close to the
truth as the paper's k = 1 (94.4, 199, 20.1: 0.63 %, 0.5 %, 0.5 %); from k = 3
on, the estimates print as the truth to the paper's three significant digits
(95.0, 200, 20.0). k = 2 is not held to the paper's "95, 200, 20": its window
opens on the switch from chi0 and Fc lands at 20.1 (+0.5 %), see the fixture's note.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ilic_cli.io import write_log
from ilic_cli.simulation.scenarios import Overrides, run_scenario
from tests.clirun import run_cli

TABLE = json.loads((Path(__file__).parents[2] / "fixtures" / "paper_table1.json").read_text())
TRUTH = TABLE["truth"]


@pytest.fixture(scope="module")
def doc(tmp_path_factory: pytest.TempPathFactory) -> dict:
    path = tmp_path_factory.mktemp("sim") / "paper-sim.mcap"
    write_log(run_scenario("paper-sim", Overrides(duration_s=6.2 * 5, seed=1)), path)
    res = run_cli("identify", str(path), "--structure", "rigid", "--format", "json")
    assert res.status == 0, res.stderr
    return json.loads(res.stdout)


def test_ilic_k1_as_close_as_the_paper(doc: dict) -> None:
    w1 = doc["ilic"]["windows"][0]["parameters"]
    for name, truth in TRUTH.items():
        paper_err = abs(TABLE["paper"]["k1"][name] - truth) / truth
        assert abs(w1[name]["value"] - truth) / truth <= paper_err, (name, w1[name]["value"])


def test_ilic_converged_windows_print_the_truth(doc: dict) -> None:
    wins = doc["ilic"]["windows"]
    assert len(wins) == 5 and doc["ilic"]["ref_lag_samples"] == 0
    for w in wins[2:]:
        for name, truth in TRUTH.items():
            assert f"{w['parameters'][name]['value']:.3g}" == f"{truth:.3g}", (w["k"], name, w["parameters"][name]["value"])
            assert w["essential"][name]


def test_idim_ls_on_the_same_log_agrees(doc: dict) -> None:
    ls = doc["ls"]["parameters"]
    last = doc["ilic"]["windows"][-1]["parameters"]
    for name, truth in TRUTH.items():
        assert ls[name]["value"] == pytest.approx(truth, rel=0.005)
        assert ls[name]["value"] == pytest.approx(last[name]["value"], rel=0.005)
