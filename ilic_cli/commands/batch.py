"""``ilic batch``: identify (and diagnose) many logs, resumably, here, in local processes or on dask."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ilic_cli.commands.common import STRUCTURES, note, progress_enabled
from ilic_cli.commands.groups import option_group
from ilic_cli.errors import IlicError
from ilic_cli.fleet import execute
from ilic_cli.fleet.batch import find_logs, group_pattern, run_batch
from ilic_cli.fleet.table import write_table
from ilic_cli.method_names import choices


def _placement(jobs: int | None, dask_spec: str | None, scheduler: str | None) -> execute.Placement:
    """The placement ``--jobs``, ``--dask local:N`` and ``--scheduler`` ask for; a contradiction or a malformed value is refused."""
    if dask_spec is not None and scheduler is not None:
        raise IlicError("--dask", "give --dask local:N or --scheduler, not both")
    if (dask_spec is not None or scheduler is not None) and jobs is not None:
        raise IlicError("--jobs", "sets local processes; with dask the cluster decides")
    workers = None
    if dask_spec is not None:
        kind, _, n = dask_spec.partition(":")
        if kind != "local" or not n.isdigit() or int(n) < 1:
            raise IlicError("--dask", f"'{dask_spec}': expected local:N with N >= 1 workers")
        workers = int(n)
    if scheduler is not None and "://" not in scheduler:
        raise IlicError("--scheduler", f"'{scheduler}': expected an address such as tcp://HOST:PORT")
    return execute.Placement(jobs=jobs, dask_workers=workers, scheduler=scheduler)


def _task_settings(method: str, structure: str, window_s: float, diagnose: bool) -> execute.TaskSettings:
    return execute.TaskSettings(method=method, structure=structure, window_s=window_s, diagnose=diagnose)


@click.command("batch")
@click.argument("logs", nargs=-1, required=True)
@click.option(
    "--out", "out_dir", type=click.Path(path_type=Path), required=True, help="Folder of the batch: table.parquet, table.csv and logs/ (one document per log)."
)
@option_group(
    "settings",
    _task_settings,
    click.option(
        "--method",
        type=click.Choice(list(choices(output_error=False))),
        default="both",
        show_default=True,
        help="What `ilic identify --method` runs.",
    ),
    click.option(
        "--structure", type=click.Choice(STRUCTURES), default="rigid-offset", show_default=True, help="Model structure (the table's parameter columns)."
    ),
    click.option("--window", "window_s", type=click.FloatRange(min=0, min_open=True), default=6.2, show_default=True, help="IDIM-ILIC window T_obs (s)."),
    click.option("--diagnose", "diagnose", is_flag=True, help="Also diagnose each log; its findings go to the table (seconds per log)."),
)
@click.option(
    "--group-by",
    "group_by",
    default=None,
    metavar="REGEX",
    help="Read the machine, joint and start from each path with named groups (?P<machine>...), (?P<joint>...), (?P<start>...) "
    "[default: from the logs' metadata].",
)
@option_group(
    "placement",
    _placement,
    click.option("--jobs", type=click.IntRange(min=1), default=None, help="Local processes [default: the cores available, $ILIC_THREADS]."),
    click.option("--dask", "dask_spec", default=None, metavar="local:N", help="Run the tasks on a dask.distributed LocalCluster of N worker processes."),
    click.option(
        "--scheduler", default=None, metavar="tcp://HOST:PORT", help="Run the tasks on this dask.distributed scheduler (its workers must see the logs' paths)."
    ),
)
@click.option("--format", "out_format", type=click.Choice(["md", "json"]), default="md", show_default=True, help="What to print on stdout: a summary or JSON.")
def command(
    logs: tuple[str, ...],
    out_dir: Path,
    settings: execute.TaskSettings,
    group_by: str | None,
    placement: execute.Placement,
    out_format: str,
) -> None:
    """Identify every log in LOGS (paths, globs, folders) and write one table.

    One row per log x joint x method x window: the parameters with σ and %σ,
    the relative error, the findings (--diagnose), the log's start time, its
    machine and joint; a log that cannot be identified is a row with its error.
    Every finished log is stored in OUT/logs/ as it finishes, so a batch
    stopped half way resumes where it stopped (each log is known by a hash of
    its content and the settings). The table is the same, bit for bit, however
    and wherever the logs were computed.

    \b
    Examples:
      ilic batch 'fleet/**/*.mcap' --out batch/
      ilic batch fleet/ --out batch/ --group-by '(?P<machine>m\\d+)/(?P<start>[0-9-]+)'
      ilic batch fleet/ --out batch/ --dask local:2
      ilic batch fleet/ --out batch/ --scheduler tcp://10.0.0.5:8786
    """
    if out_dir.exists() and not out_dir.is_dir():
        raise IlicError(out_dir, "--out must be a folder")
    try:
        rx = group_pattern(group_by)
    except IlicError as exc:  # the library names the pattern; the command names its option
        raise IlicError("--group-by", exc.problem) from None
    paths = [p for p in find_logs(logs) if out_dir.resolve() not in p.resolve().parents]  # not the batch's own table.csv
    if not paths:
        raise IlicError(logs[0], f"no log outside --out {out_dir}")
    runner = placement.runner(len(paths))
    result = run_batch(paths, out_dir, settings, runner, progress=_progress() if progress_enabled() else None)
    result.written = write_table(result, settings.structure, rx)
    summary = result.to_dict()
    if out_format == "json":
        click.echo(json.dumps(summary, indent=2))
    else:
        click.echo(
            f"{summary['logs']} logs: {summary['computed']} computed, {summary['resumed']} resumed, {summary['errors']} with an error\n"
            f"table: {', '.join(summary['written'])}"
        )
    if result.errors:
        note(f"ilic: warning: {result.errors} log(s) gave no estimate: their rows in the table say why")


def _progress():
    def report(done: int, total: int) -> None:
        click.echo(f"\r  {done}/{total} logs", err=True, nl=done >= total)

    return report
