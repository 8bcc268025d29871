"""IDIM-LS on the real EMPS recordings reproduces the published tables to every printed digit."""

from __future__ import annotations

import json
from decimal import Decimal
from pathlib import Path

import pytest

from tests.clirun import run_cli
from tests.conftest import require_shared

FIXTURE = json.loads((Path(__file__).parents[2] / "fixtures" / "emps_benchmark_tables.json").read_text())
TABLES = FIXTURE["tables"]


def assert_printed_digits(ours: float, published: str, what: str) -> None:
    """|ours - published| <= half a unit of the last printed digit."""
    decimals = -Decimal(published).as_tuple().exponent
    assert round(ours, decimals) == pytest.approx(float(published), abs=0.5 * 10.0**-decimals), f"{what}: {ours} vs {published}"
    assert f"{ours:.{decimals}f}" == published, f"{what}: printed {ours:.{decimals}f}, published {published}"


@pytest.fixture(scope="module")
def emps() -> Path:
    return require_shared()


def identify_json(*args: str) -> dict:
    res = run_cli("identify", *args, "--format", "json")
    assert res.status == 0, res.stderr
    return json.loads(res.stdout)


def test_rigid_offset_table_every_digit(emps: Path) -> None:
    doc = identify_json(str(emps / "DATA_EMPS.mat"), "--method", "ls")
    table = TABLES["rigid_offset"]
    ls = doc["ls"]
    assert ls["method"] == "IDIM-LS"
    for name, row in table["parameters"].items():
        for key, published in row.items():
            assert_printed_digits(ls["parameters"][name][key], published, f"{name}.{key}")
    for key in ("condition_number", "error_norm", "relative_error_pct", "error_std"):
        assert_printed_digits(ls[key], table[key], key)
    assert doc["ilic"] is None
    # the rows prefer the sign to any smoothed Coulomb law (the grid's lowest speed, 0.25 mm/s): no friction-shape warning
    assert doc["friction_shape"]["at_edge_of_range"] is True and doc["friction_shape"]["material"] is False
    assert abs(doc["friction_shape"]["change"]["Fc"]) < 0.01


def test_rigid_offset_markdown_prints_published_numbers(emps: Path) -> None:
    res = run_cli("identify", str(emps / "DATA_EMPS.mat"), "--method", "ls")
    assert res.status == 0, res.stderr
    for text in (
        "| M (kg) | 95.1089 | 0.1085 | 0.1141 |",
        "| Fv (N·s/m) | 203.5034 | 1.1460 | 0.5631 |",
        "| Fc (N) | 20.3935 | 0.1012 | 0.4964 |",
        "| offset (N) | -3.1648 | 0.0444 | 1.4021 |",
        "Condition number 25.9883",
        "relative error 4.0834 %",
    ):
        assert text in res.stdout


def test_asymmetric_table_and_cross_test_validation(emps: Path) -> None:
    doc = identify_json(str(emps / "DATA_EMPS.mat"), "--method", "ls", "--structure", "asymmetric")
    table = TABLES["asymmetric"]
    for name, row in table["parameters"].items():
        for key, published in row.items():
            assert_printed_digits(doc["ls"]["parameters"][name][key], published, f"{name}.{key}")
    for key in ("relative_error_pct", "error_norm", "condition_number"):
        assert_printed_digits(doc["ls"][key], table[key], key)


def test_cross_test_validation_on_pulses(emps: Path) -> None:
    doc = identify_json(str(emps / "DATA_EMPS.mat"), "--method", "ls", "--validate", str(emps / "DATA_EMPS_PULSES.mat"))
    table = TABLES["rigid_offset_cross_test"]
    (val,) = doc["validation"]
    assert val["source"].endswith("DATA_EMPS_PULSES.mat")
    for key in ("error_norm", "relative_error_pct", "error_std", "condition_number"):
        assert_printed_digits(val[key], table[key], key)


def test_ilic_windows_on_emps_close_to_ls(emps: Path) -> None:
    """IDIM-ILIC on the reference trajectory of the PD-controlled recording.

    The recording's PD loop trails its reference by 7 ms (tracking error ratio
    7e-3, a hundred times the paper's CTC); the reference is delayed by the lag
    estimated from the positions. Measured: 4 windows of 6.2 s; M +0.8..1.3 %,
    Fv -2.1..-3.9 %, Fc +1.8..3.6 % from IDIM-LS (paper: < 1.5 % on its CTC
    machine). Without the delay Fv is 10..13 % off, which the second test shows.
    """
    doc = identify_json(str(emps / "DATA_EMPS.mat"))
    assert doc["ilic"]["ref_lag_samples"] == 7
    ls = doc["ls"]["parameters"]
    wins = doc["ilic"]["windows"]
    assert [w["k"] for w in wins] == [1, 2, 3, 4]
    assert wins[0]["t_start"] == 0.0 and wins[1]["t_start"] == pytest.approx(6.2, abs=2e-3)
    for w in wins:
        p = w["parameters"]
        assert abs(p["M"]["value"] / ls["M"]["value"] - 1) < 0.02
        assert abs(p["Fv"]["value"] / ls["Fv"]["value"] - 1) < 0.05
        assert abs(p["Fc"]["value"] / ls["Fc"]["value"] - 1) < 0.05
        assert w["essential"]["M"] and w["essential"]["Fv"] and w["essential"]["Fc"]
        assert 0.005 < w["tracking_error_ratio"] < 0.01
        assert 3 < w["relative_error_pct"] < 5


def test_ilic_without_reference_delay_is_biased_on_the_pd_recording(emps: Path) -> None:
    doc = identify_json(str(emps / "DATA_EMPS.mat"), "--method", "ilic", "--ref-lag", "0")
    assert doc["ilic"]["ref_lag_samples"] == 0
    fv = [w["parameters"]["Fv"]["value"] for w in doc["ilic"]["windows"]]
    assert all(220 < v < 235 for v in fv), fv
