"""``ilic trend``: a batch table's parameters per machine against time; flagged steps, slopes, payload swaps."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ilic_cli.commands.common import note, options_named
from ilic_cli.commands.groups import option_group
from ilic_cli.errors import IlicError
from ilic_cli.fleet.table import read_table
from ilic_cli.io.atomic import atomic_write_text

if TYPE_CHECKING:
    from ilic_cli.fleet.trend import TrendSettings


def _trend_settings(method: str, alpha: float, min_change: float, correction: str) -> TrendSettings:
    # deferred: ilic_cli.fleet.trend loads numpy, which `ilic trend --help` must not (tests/fleet/test_fleet_cli.py)
    from ilic_cli.fleet.trend import TrendSettings

    return TrendSettings(alpha=alpha, min_change_pct=min_change, correction=correction, method=method)


@click.command("trend")
@click.argument("table", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None, help="Folder for trend.md, trend.json and the plots.")
@option_group(
    "settings",
    _trend_settings,
    click.option(
        "--method", default="IDIM-LS", show_default=True, help="Whose estimates to trend: a method of the table (IDIM-LS, IDIM-ILIC, DIDIM, IDIM-IV)."
    ),
    click.option(
        "--alpha", type=click.FloatRange(min=0, max=1, min_open=True, max_open=True), default=0.01, show_default=True, help="Level after the correction."
    ),
    click.option(
        "--min-change",
        "min_change",
        type=click.FloatRange(min=0),
        default=10.0,
        show_default=True,
        help="Smallest flagged change, % of the first level.",
    ),
    click.option(
        "--correction",
        type=click.Choice(["holm", "bh"]),
        default="holm",
        show_default=True,
        help="Across machines x joints x parameters: Holm (family-wise) or Benjamini-Hochberg (false discovery rate).",
    ),
)
@click.option("--plots", "plot_format", type=click.Choice(["png", "svg", "none"]), default="png", show_default=True, help="Plot format under --out.")
@click.option("--format", "out_format", type=click.Choice(["md", "json"]), default="md", show_default=True, help="What to print on stdout.")
def command(table: Path, out_dir: Path | None, settings: TrendSettings, plot_format: str, out_format: str) -> None:
    """Trend each parameter of TABLE (an `ilic batch` table.parquet or table.csv) per machine and joint.

    Each series is fitted with a line in time and with a two-level step; the
    better fit's change is tested (slope t-test, or step F-test with
    Bonferroni over the splits), the p-values of all series corrected
    together (Holm or Benjamini-Hochberg), and a change is flagged when the
    corrected p is below --alpha and the change at least --min-change % of
    the first level. A flagged rise of Fv or Fc is wear; a flagged step of M
    a payload swap, named by its day. The summary ranks the machines.

    \b
    Examples:
      ilic trend batch/table.parquet --out trend/
      ilic trend batch/table.csv --min-change 15 --correction bh --format json
    """
    # deferred: the trends and the JSON renderer load numpy, which `ilic trend --help` must not (tests/fleet/test_fleet_cli.py)
    from ilic_cli.fleet.trend import to_markdown, trend
    from ilic_cli.identify_report import to_json

    if out_dir is not None and out_dir.exists() and not out_dir.is_dir():
        raise IlicError(out_dir, "--out must be a folder")
    frame = read_table(table)
    methods = sorted(set(frame["method"].dropna()))
    if settings.method not in methods:
        raise IlicError("--method", f"'{settings.method}' has no row in {table} (it has: {', '.join(methods) or 'no estimate'})")
    with options_named():
        report = trend(frame, settings)
    md, js = to_markdown(report), to_json(report.to_dict())
    if out_dir is not None:
        from ilic_cli.fleet.trendplot import write_plots  # deferred: matplotlib

        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out_dir / "trend.md", md, inputs=(table,))
        atomic_write_text(out_dir / "trend.json", js, inputs=(table,))
        written = [out_dir / "trend.md", out_dir / "trend.json"]
        if plot_format != "none":
            written += write_plots(report, out_dir, plot_format)
        note(f"ilic: wrote {len(written)} files under {out_dir}")
    click.echo(js if out_format == "json" else md, nl=False)
