"""``ilic trend``: on a simulated fleet it flags every worn machine and no other, and names each payload swap's day."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.fleet.batch import find_logs, run_batch
from ilic_cli.fleet.execute import TaskSettings
from ilic_cli.fleet.generate import DAY_NS, START_NS
from ilic_cli.fleet.table import format_time, read_table, write_table
from ilic_cli.fleet.trend import Series, TrendSettings, benjamini_hochberg, holm, step_fit, trend
from tests.clirun import run_cli


@pytest.fixture(scope="module")
def table(trend_fleet, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder, _ = trend_fleet
    out = tmp_path_factory.mktemp("trend_batch")
    result = run_batch(find_logs([str(folder)]), out, TaskSettings(method="ls"))
    return write_table(result, "rigid-offset")[0]


@pytest.fixture(scope="module")
def report_json(table: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[dict, Path]:
    out = tmp_path_factory.mktemp("trend_out")
    res = run_cli("trend", str(table), "--out", str(out), "--format", "json")
    assert res.status == 0, res.stderr
    return json.loads(res.stdout), out


def test_the_fleet_has_every_kind(trend_fleet) -> None:
    _, truth = trend_fleet
    assert sum(m.worn for m in truth) == 4 and sum(m.swap_day is not None for m in truth) == 4
    assert all(max(m.wear_Fv_pct, m.wear_Fc_pct) <= 3 for m in truth if not m.worn)  # unworn: some wear, below the flagged change


def test_flags_every_worn_machine_and_no_other(trend_fleet, report_json) -> None:
    _, truth = trend_fleet
    doc, _ = report_json
    flagged = {m["machine"] for m in doc["machines"] if m["wear"]}
    assert flagged == {m.machine for m in truth if m.worn}
    for m in truth:
        series = {s["parameter"]: s for s in doc["series"] if s["machine"] == m.machine}
        for name, wear in (("Fv", m.wear_Fv_pct), ("Fc", m.wear_Fc_pct)):
            if wear > 10:
                assert series[name]["flagged"] and series[name]["kind"] == "slope", (m.machine, name)
                assert abs(series[name]["change_pct"] - wear) < 3, (m.machine, name, series[name]["change_pct"], wear)
    ranks = [m["machine"] for m in doc["machines"]]
    assert set(ranks[:4]) == flagged  # the worn machines rank first


def test_names_each_payload_swap_day(trend_fleet, report_json) -> None:
    _, truth = trend_fleet
    doc, _ = report_json
    named = {m["machine"]: [s["day"] for s in m["payload_swaps"]] for m in doc["machines"]}
    expected = {m.machine: [format_time(START_NS + m.swap_day * DAY_NS)[:10]] if m.swap_day is not None else [] for m in truth}
    assert named == expected
    for m in truth:
        swaps = [s for s in doc["machines"] if s["machine"] == m.machine][0]["payload_swaps"]
        if m.swap_day is not None:
            assert abs(swaps[0]["M_after"] - swaps[0]["M_before"] - m.swap_kg) < 1.0
    # no machine's M is flagged as anything but its swap
    assert not [s for s in doc["series"] if s["parameter"] == "M" and s["flagged"] and s["kind"] != "step"]


def test_summary_and_plots(report_json) -> None:
    doc, out = report_json
    md = (out / "trend.md").read_text()
    assert "Holm" in md and "p < 0.01" in md and "| rank | machine |" in md
    assert "payload swap on 2026-01-" in md
    assert json.loads((out / "trend.json").read_text()) == doc
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["fleet_Fc.png", "fleet_Fv.png"] + [f"trend_m0{i}.png" for i in range(1, 9)]
    assert all((out / p).stat().st_size > 10_000 for p in pngs)


def test_csv_table_gives_the_same_report(table: Path, report_json) -> None:
    doc, _ = report_json
    res = run_cli("trend", str(table.with_suffix(".csv")), "--format", "json")
    assert res.status == 0, res.stderr
    assert json.loads(res.stdout) == doc


def test_a_higher_threshold_flags_fewer(table: Path, report_json) -> None:
    doc, _ = report_json
    frame = read_table(table)
    strict = trend(frame, TrendSettings(min_change_pct=1000.0, correction="bh")).to_dict()
    assert not [m for m in strict["machines"] if m["wear"] or m["payload_swaps"]]
    assert len([s for s in doc["series"] if s["flagged"]]) >= 12


def test_holm_and_benjamini_hochberg_by_hand() -> None:
    p = np.array([0.01, 0.04, 0.03, 0.005])
    # Holm: sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1, running maximum
    assert np.allclose(holm(p), [0.03, 0.06, 0.06, 0.02])
    # BH: sorted times 4/1, 4/2, 4/3, 4/4, running minimum from the top
    assert np.allclose(benjamini_hochberg(p), [0.02, 0.04, 0.04, 0.02])
    assert (holm(np.array([0.9, 0.8])) <= 1).all()


def test_step_fit_finds_the_split() -> None:
    y = np.r_[np.full(5, 10.0), np.full(7, 12.0)] + np.array([0.01, -0.01] * 6)
    k, before, after, rss, splits = step_fit(y)
    assert (k, round(before, 1), round(after, 1), splits) == (5, 10.0, 12.0, 9)
    assert rss < 0.01


def test_a_constant_noisy_series_is_not_flagged() -> None:
    rng = np.random.default_rng(5)
    s = Series("m", "", "Fv", "N·s/m", [START_NS + d * DAY_NS for d in range(20)], list(200 + rng.normal(0, 2, 20)), [2.0] * 20)
    s.fit()
    assert s.kind in ("slope", "step") and s.p > 0.01 and abs(s.change_pct) < 3


def test_bad_table_and_method_are_one_line_exit_2(table: Path, tmp_path: Path) -> None:
    res = run_cli("trend", str(tmp_path / "none.parquet"))
    assert res.status == 2 and "no such table" in res.stderr and res.stderr.count("\n") == 1
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    res = run_cli("trend", str(tmp_path / "x.csv"))
    assert res.status == 2 and "not a batch table" in res.stderr
    res = run_cli("trend", str(table), "--method", "DIDIM")
    assert res.status == 2 and "'DIDIM' has no row" in res.stderr
