"""``ilic batch``: the table, a bad log's row, resume, and the same bytes on a dask.distributed cluster."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from ilic_cli.fleet import execute
from ilic_cli.fleet.batch import find_logs, group_pattern, run_batch
from ilic_cli.fleet.execute import TaskSettings
from ilic_cli.fleet.table import columns, read_table, write_table
from tests.clirun import run_cli
from tests.conftest import import_or_skip


@pytest.fixture(scope="module")
def logs(small_fleet, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The small fleet plus a corrupt log and a copy of one log under another name."""
    folder, _ = small_fleet
    work = tmp_path_factory.mktemp("batch_logs")
    shutil.copytree(folder, work / "fleet")
    (work / "fleet" / "m09").mkdir()
    (work / "fleet" / "m09" / "m09_2026-01-01.csv").write_text("t,q\n0,not a number\n", encoding="utf-8")
    shutil.copy(work / "fleet" / "m01" / "m01_2026-01-02.mcap", work / "fleet" / "m01" / "copy.mcap")
    return work / "fleet"


@pytest.fixture(scope="module")
def local_run(logs: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The batch in two local processes (the default runner on this machine)."""
    out = tmp_path_factory.mktemp("local") / "batch"
    res = run_cli("batch", str(logs), "--out", str(out), "--jobs", "2", "--format", "json")
    assert res.status == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["logs"] == 26 and summary["computed"] == 25 and summary["errors"] == 1  # the copy is the same content: computed once
    return out


def test_table_rows_columns_and_types(local_run: Path) -> None:
    frame = read_table(local_run / "table.parquet")
    assert list(frame.columns) == [c for c, _ in columns("rigid-offset")]
    assert str(frame["start_time"].dtype) == "datetime64[ns, UTC]" and str(frame["window"].dtype) == "int64"
    ok = frame[frame.status == "ok"]
    # one IDIM-LS row and one IDIM-ILIC window (8 s logs, 6.2 s windows) per good log
    assert sorted(ok.method.value_counts().items()) == [("IDIM-ILIC", 25), ("IDIM-LS", 25)]
    assert set(ok[ok.method == "IDIM-ILIC"].window) == {1} and set(ok[ok.method == "IDIM-LS"].window) == {0}
    assert set(ok.machine) == {"m01", "m02", "m03", "m04"}
    assert (ok.M_rel_std_pct < 2).all() and (abs(ok.M - 100 * ok.M_std / ok.M_rel_std_pct) < 1e-9 * ok.M).all()
    first = ok[(ok.machine == "m01") & (ok.method == "IDIM-LS")].sort_values("start_time")
    assert str(first.start_time.iloc[0]) == "2026-01-01 06:00:00+00:00"
    csv_text = (local_run / "table.csv").read_text()
    assert csv_text.splitlines()[0].split(",") == [c for c, _ in columns("rigid-offset")]
    assert len(csv_text.splitlines()) == len(frame) + 1


def test_a_bad_log_is_a_row_with_its_error(local_run: Path) -> None:
    frame = read_table(local_run / "table.csv")
    bad = frame[frame.status == "error"]
    assert len(bad) == 1
    assert bad.log.iloc[0].endswith("m09/m09_2026-01-01.csv") and "m09_2026-01-01.csv" in bad.error.iloc[0]
    assert bad.M.isna().all() and bad.method.isna().all()


def test_dask_cluster_gives_the_same_table_bit_for_bit(logs: Path, local_run: Path, tmp_path: Path) -> None:
    distributed = import_or_skip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        res = run_cli("batch", str(logs), "--out", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address)
        assert res.status == 0, res.stderr
        with distributed.Client(cluster) as client:
            assert len(client.scheduler_info()["workers"]) == 2
    for name in ("table.parquet", "table.csv"):
        assert (tmp_path / "dask" / name).read_bytes() == (local_run / name).read_bytes(), name


def test_in_process_gives_the_same_table(logs: Path, local_run: Path, tmp_path: Path) -> None:
    res = run_cli("batch", str(logs), "--out", str(tmp_path / "one"), "--jobs", "1")
    assert res.status == 0, res.stderr
    assert "25 computed, 0 resumed, 1 with an error" in res.stdout
    assert (tmp_path / "one" / "table.parquet").read_bytes() == (local_run / "table.parquet").read_bytes()


def test_a_stopped_batch_resumes_to_the_same_table(logs: Path, local_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "stopped"
    paths = find_logs([str(logs)])
    settings = TaskSettings()
    with pytest.raises(KeyboardInterrupt):
        run_batch(paths, out, settings, execute.in_process, stop_after=7)
    assert len(list((out / "logs").glob("*.json"))) == 7
    res = run_cli("batch", str(logs), "--out", str(out), "--jobs", "1", "--format", "json")
    assert res.status == 0, res.stderr
    summary = json.loads(res.stdout)
    assert (summary["computed"], summary["resumed"]) == (18, 7)
    for name in ("table.parquet", "table.csv"):
        assert (out / name).read_bytes() == (local_run / name).read_bytes(), name
    again = json.loads(run_cli("batch", str(logs), "--out", str(out), "--format", "json").stdout)
    assert (again["computed"], again["resumed"]) == (0, 25)


def test_other_settings_are_computed_again(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    paths = find_logs([str(folder / "m01")])
    out = tmp_path / "b"
    first = run_batch(paths, out, TaskSettings(method="ls"))
    second = run_batch(paths, out, TaskSettings(method="ls", structure="rigid"))
    assert first.computed == second.computed == len(paths) == 6
    table = write_table(second, "rigid")
    frame = read_table(table[0])
    assert "offset" not in frame.columns and set(frame.method) == {"IDIM-LS"}


def test_group_by_reads_machine_and_start_from_the_path(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    res = run_cli(
        "batch",
        str(folder / "m02" / "*.mcap"),
        "--out",
        str(tmp_path / "g"),
        "--method",
        "ls",
        "--jobs",
        "1",
        "--group-by",
        r"/(?P<joint>m\d+)/(?P<machine>m\d+)_(?P<start>\d{4}-\d{2}-\d{2})",
    )
    assert res.status == 0, res.stderr
    frame = read_table(tmp_path / "g" / "table.parquet")
    assert set(frame.machine) == {"m02"} and set(frame.joint) == {"m02"}
    assert [str(t.date()) for t in frame.start_time] == [f"2026-01-0{d}" for d in range(1, 7)]
    assert (frame.start_time.dt.hour == 0).all()  # the path's date, not the metadata's 06:07


def test_group_by_that_misses_a_path_is_that_logs_error(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    paths = find_logs([str(folder / "m01" / "m01_2026-01-01.mcap"), str(folder / "m02" / "m02_2026-01-01.mcap")])
    result = run_batch(paths, tmp_path / "b", TaskSettings(method="ls"))
    frame = read_table(write_table(result, "rigid-offset", group_pattern(r"(?P<machine>m01)_"))[0])
    assert list(frame.status) == ["ok", "error"] and "does not match --group-by" in frame.error.iloc[1]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nowhere/*.mcap"], "matches no log"),
        (["no_such.mcap"], "no such log"),
        (["LOGS", "--group-by", "(?P<robot>m\\d+)"], "unknown group 'robot'"),
        (["LOGS", "--group-by", "m\\d+"], "no named group"),
        (["LOGS", "--group-by", "(?P<machine>"], "not a regular expression"),
        (["LOGS", "--dask", "remote:2"], "expected local:N"),
        (["LOGS", "--dask", "local:2", "--scheduler", "tcp://x:1"], "not both"),
    ],
)
def test_bad_arguments_are_one_line_exit_2(small_fleet, tmp_path: Path, args: list[str], message: str) -> None:
    folder, _ = small_fleet
    args = [str(folder / "m01") if a == "LOGS" else a for a in args]
    res = run_cli("batch", *args, "--out", str(tmp_path / "o"))
    assert res.status == 2
    assert res.stderr.startswith("ilic: error: ") and res.stderr.count("\n") == 1 and message in res.stderr
    assert not (tmp_path / "o").exists()


def test_out_that_is_a_file_is_refused(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    (tmp_path / "f").write_text("x")
    res = run_cli("batch", str(folder / "m01"), "--out", str(tmp_path / "f"))
    assert res.status == 2 and "--out must be a folder" in res.stderr


def test_diagnose_puts_the_findings_in_every_row_of_the_log(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    log = folder / "m01" / "m01_2026-01-01.mcap"
    res = run_cli("batch", str(log), "--out", str(tmp_path / "d"), "--diagnose")
    assert res.status == 0, res.stderr
    frame = read_table(tmp_path / "d" / "table.csv")
    plain = read_table(write_table(run_batch([log], tmp_path / "p", TaskSettings()), "rigid-offset")[0])
    # the simulated rigid axis leaves nothing out; identification is the same with or without the diagnosis
    assert list(frame.findings) == ["none", "none"] and list(frame.not_judged) == ["none", "none"] and plain.findings.isna().all()
    assert list(frame.M) == list(plain.M) and frame.error.isna().all()


def test_an_undecided_diagnosis_is_not_a_clean_row(small_fleet, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A diagnosis that finds nothing but could not judge a proposal (its fit no plant, corpus s21512) is ``undecided`` in the
    table, the proposal in ``not_judged``; a clean one is ``none`` in both; a document stored before ``not_judged`` was kept
    leaves it null."""
    import ilic_cli.diagnosis as diagnosis

    folder, _ = small_fleet
    log = folder / "m01" / "m01_2026-01-01.mcap"

    class Undecided:
        def to_dict(self) -> dict[str, object]:
            return {"findings": [], "not_judged": ["flexibility"]}

    monkeypatch.setattr(diagnosis, "diagnose", lambda *a, **k: Undecided())
    result = run_batch([log], tmp_path / "u", TaskSettings(diagnose=True))
    frame = read_table(write_table(result, "rigid-offset")[0])
    assert list(frame.findings) == ["undecided", "undecided"] and list(frame.not_judged) == ["flexibility", "flexibility"]
    doc = result.documents[result.keys[0]]
    doc["not_judged"] = []
    frame = read_table(write_table(result, "rigid-offset")[0])
    assert list(frame.findings) == ["none", "none"] and list(frame.not_judged) == ["none", "none"]
    del doc["not_judged"]
    frame = read_table(write_table(result, "rigid-offset")[0])
    assert list(frame.findings) == ["none", "none"] and frame.not_judged.isna().all()


def test_a_killed_batch_resumes_to_the_same_table(logs: Path, local_run: Path, tmp_path: Path) -> None:
    """SIGKILL a batch process once its first log is stored (no clean-up at all); the rerun computes only the others."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "ilic_cli", "batch", str(logs), "--out", str(out), "--jobs", "1"], stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not list((out / "logs").glob("*.json")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.002)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    done = len(list((out / "logs").glob("*.json")))
    assert proc.returncode == -signal.SIGKILL and 1 <= done < 25 and not (out / "table.parquet").exists()
    res = run_cli("batch", str(logs), "--out", str(out), "--format", "json")
    assert res.status == 0, res.stderr
    assert (json.loads(res.stdout)["computed"], json.loads(res.stdout)["resumed"]) == (25 - done, done)
    for name in ("table.parquet", "table.csv"):
        assert (out / name).read_bytes() == (local_run / name).read_bytes(), name


def test_an_out_folder_inside_the_logs_is_not_read_as_logs(small_fleet, tmp_path: Path) -> None:
    folder, _ = small_fleet
    shutil.copytree(folder / "m03", tmp_path / "m03")
    for _ in range(2):  # the second run sees table.csv under the input folder
        res = run_cli("batch", str(tmp_path), "--out", str(tmp_path / "batch"), "--method", "ls", "--format", "json")
        assert res.status == 0, res.stderr
        assert json.loads(res.stdout)["logs"] == 6 and json.loads(res.stdout)["errors"] == 0


def test_a_stored_document_is_plain_json() -> None:
    import numpy as np

    from ilic_cli.fleet.batch import plain

    doc = {"a": np.float64(1.5), "b": [np.int64(3), float("nan"), float("inf")], "c": {"d": np.bool_(True)}, "e": "x"}
    assert json.dumps(plain(doc), allow_nan=False) == '{"a": 1.5, "b": [3, null, null], "c": {"d": true}, "e": "x"}'
