"""A small simulated fleet shared by the fleet tests (written once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ilic_cli.fleet.generate import MachinePlan, write_fleet


@pytest.fixture(scope="session")
def small_fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[MachinePlan]]:
    """4 machines x 6 days of 8 s logs (every kind of machine once)."""
    folder = tmp_path_factory.mktemp("small_fleet")
    return folder, write_fleet(folder, machines=4, days=6, seed=3)


@pytest.fixture(scope="session")
def trend_fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[MachinePlan]]:
    """8 machines x 12 days: two of each kind (unworn, worn, payload swap, worn with a swap)."""
    folder = tmp_path_factory.mktemp("trend_fleet")
    return folder, write_fleet(folder, machines=8, days=12, seed=1)
