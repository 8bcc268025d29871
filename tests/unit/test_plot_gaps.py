"""Plots of a log with gaps break their lines at the gaps (a line across a gap draws samples that do not exist)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ilic_cli import plotting
from ilic_cli.plotting import broken_at_gaps


def test_a_nan_goes_into_each_gap_and_nowhere_else() -> None:
    t = np.array([0.0, 0.1, 0.2, 0.3, 1.0, 1.1, 1.2, 5.0, 5.1])
    tb, yb = broken_at_gaps(t, np.arange(9.0))
    assert np.flatnonzero(np.isnan(yb)).tolist() == [4, 8] and np.all(np.diff(tb) > 0)
    assert np.array_equal(yb[~np.isnan(yb)], np.arange(9.0)) and np.array_equal(tb[~np.isnan(yb)], t)
    # a uniform axis (with the jitter of real stamps) is left as it is
    even = np.arange(50) * 0.01 + np.random.default_rng(0).normal(0.0, 1e-4, 50)
    assert all(np.array_equal(a, b) for a, b in zip(broken_at_gaps(even, np.ones(50)), (even, np.ones(50)), strict=True))


def test_an_arms_torque_plot_is_broken_at_the_gap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    figures = []
    monkeypatch.setattr(plotting, "_save", lambda fig, path: figures.append(fig) or path)
    t = np.concatenate([np.arange(100) * 0.01, 2.0 + np.arange(100) * 0.01])  # two parts, 1 s apart
    y = np.sin(t)
    plotting.plot_joint_torques(t, ["j"], ["N·m"], [y], [0.9 * y], "test", tmp_path)
    lines = [line for ax in figures[0].axes for line in ax.get_lines()]
    assert len(lines) == 3 and all(int(np.isnan(np.asarray(line.get_ydata(), dtype=float)).sum()) == 1 for line in lines)
    plotting._pyplot().close("all")


def test_the_error_scale_leaves_out_each_parts_edges() -> None:
    """The filters start and end at a gap as at the log's ends: the rows there are out of an error axis's scale."""
    t = np.concatenate([np.arange(100) * 0.01, 2.0 + np.arange(100) * 0.01])
    assert plotting.edge_spans(t, 3) == [(0, 3), (97, 100), (100, 103), (197, 200)]
    keep = plotting.scaled_rows(t, 3)
    assert keep.sum() == 200 - 12 and not keep[97:103].any() and keep[3:97].all()
    # without a gap, the log's two ends as before
    assert plotting.edge_spans(np.arange(50) * 0.01, 2) == [(0, 2), (48, 50)]
