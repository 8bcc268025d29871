"""Every plot that make demo, identify --out and diagnose --out write has units on every axis, and no edge spike sets a scale."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

from tests.clirun import run_cli  # noqa: E402

UNIT = re.compile(r"\((?:[^()]|\([^()]*\))+\)\s*$")


@pytest.fixture()
def saved(monkeypatch: pytest.MonkeyPatch) -> dict[str, Figure]:
    """Figures as they are saved, by file name."""
    figures: dict[str, Figure] = {}
    original = Figure.savefig

    def record(self: Figure, fname: object, *args: object, **kwargs: object) -> None:
        figures[Path(str(fname)).name] = self  # a temporary sibling's name holds the target's
        original(self, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", record)
    return figures


def _labels_have_units(figures: dict[str, Figure]) -> None:
    assert figures
    for name, fig in figures.items():
        for ax in fig.axes:
            if not ax.lines and not ax.collections:
                continue
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                if label or ax.get_subplotspec().is_last_row():
                    assert UNIT.search(label), (name, label)


def test_identify_plots(tmp_path: Path, saved: dict[str, Figure]) -> None:
    sim = tmp_path / "sim.mcap"
    assert run_cli("simulate", "--scenario", "paper-sim", "--duration", "19", "--seed", "1", "-o", str(sim)).status == 0
    res = run_cli("identify", str(sim), "--out", str(tmp_path / "out"))
    assert res.status == 0, res.stderr
    _labels_have_units(saved)
    params = next(f for n, f in saved.items() if "parameters" in n)
    for ax in params.axes:  # the true values of the simulated log are drawn, inside the frame
        true = [line for line in ax.lines if line.get_label() == "true (simulated)"]
        lo, hi = ax.get_ylim()
        assert ax.get_ylabel().split(" (")[0] != "M" or true
        for line in ax.lines:
            y = line.get_ydata()
            assert all(lo < v < hi for v in y if v == v), (ax.get_ylabel(), lo, hi)


def test_diagnose_plots(emps_mat: Path, tmp_path: Path, saved: dict[str, Figure]) -> None:
    res = run_cli("diagnose", str(emps_mat), "--out", str(tmp_path / "d"))
    assert res.status == 0, res.stderr
    _labels_have_units(saved)
    assert next(f for n, f in saved.items() if "residual" in n).axes[0].get_title() == "IDIM residual; shaded: located regions (significant)"
    force = next(f for n, f in saved.items() if "force_fit" in n)
    lo, hi = force.axes[1].get_ylim()
    assert hi - lo < 60  # the replay's start transient (about -89 N at t = 0) does not set the scale


def test_a_revolute_joint_s_plots_are_in_its_units(tmp_path: Path, saved: dict[str, Figure]) -> None:
    """A revolute joint's figures read rad, rad/s and N·m, never a linear axis's m or N (identify --out and diagnose --out)."""
    from tests.corpus.measure import controller_flags, write_csv
    from tests.corpus.robot import Case, build

    case = Case("rev0.5", "trapezoid", 500.0, "sensor", 4242)
    path = write_csv(build(case), tmp_path / "joint.csv")
    for cmd in ("identify", "diagnose"):
        res = run_cli(cmd, str(path), *controller_flags(case), "--out", str(tmp_path / cmd))
        assert res.status == 0, res.stderr
    _labels_have_units(saved)
    labels = [label for fig in saved.values() for ax in fig.axes for label in (ax.get_xlabel(), ax.get_ylabel()) if label]
    units = {UNIT.search(label).group(0) for label in labels if UNIT.search(label)}  # type: ignore[union-attr]
    assert {"(N·m)", "(rad)", "(rad/s)"} <= units and not units & {"(N)", "(m)", "(m/s)"}, units


def test_the_residual_title_names_shading_only_when_a_region_is_shaded() -> None:
    """A drift finding or a spectral line alone shades nothing on the residual plot, and its title does not say it does."""
    from ilic_cli.diagnosis.locate import Region
    from ilic_cli.diagnosis.plots import residual_title

    def region(kind: str, significant: bool = True) -> Region:
        return Region(kind, "", (0.0, 1.0), 10, 0.0, 1.0, 5.0, 0.001, significant)

    assert residual_title([]) == "IDIM residual (no region located)"
    assert residual_title([region("frequency"), region("lag")]) == "IDIM residual (no region located)"
    assert residual_title([region("velocity", significant=False)]) == "IDIM residual (no region located)"
    for kind in ("velocity", "position", "time", "drift"):
        assert residual_title([region("frequency"), region(kind)]) == "IDIM residual; shaded: located regions (significant)"
