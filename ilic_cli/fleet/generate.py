"""A simulated fleet, for the tests and the demo: slow friction wear and payload swaps over days.

Each machine is the EMPS axis with its own commissioning parameters (M, Fv,
Fc), in the benchmark PD loop on the paper's exciting trajectory (varied per
log), as ``ilic simulate --scenario paper-sim --controller pd`` runs it. One
short log a day; within a log the parameters are constant, across days Fv and
Fc rise linearly by the machine's wear (from 0 on day 0 to the full wear on the
last day) and M steps by the payload swap from its day on. The machines cycle
through four kinds: unworn (wear 0-3 %, below any flagged change), worn
(15-40 %), a payload swap (12-25 kg on or off, between the first and the last
quarter of the period), and worn with a swap. Everything is drawn from the
seed: the same arguments write the same bytes.

Logs are ``FOLDER/mNN/mNN_YYYY-MM-DD.mcap``; their metadata carries
``machine`` and ``start_time_ns`` (and ``true_parameters``), so the batch
needs no ``--group-by``.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ilic_cli.fleet.table import format_time

DAY_NS = 86400 * 10**9
START_NS = 1767225600 * 10**9
"""2026-01-01T00:00:00Z: the fleet's day 0."""

WORN = (15.0, 40.0)
UNWORN = (0.0, 3.0)
SWAP_KG = (12.0, 25.0)


@dataclass(frozen=True)
class MachinePlan:
    """One machine's truth: commissioning parameters, wear over the period (%), payload swap day and mass."""

    machine: str
    M: float
    Fv: float
    Fc: float
    wear_Fv_pct: float
    wear_Fc_pct: float
    swap_day: int | None
    swap_kg: float

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def parameters(self, day: int, days: int) -> dict[str, float]:
        """M, Fv, Fc on ``day`` (of ``days``)."""
        share = day / max(days - 1, 1)
        mass = self.M + (self.swap_kg if self.swap_day is not None and day >= self.swap_day else 0.0)
        return {"M": mass, "Fv": self.Fv * (1 + share * self.wear_Fv_pct / 100), "Fc": self.Fc * (1 + share * self.wear_Fc_pct / 100)}

    @property
    def worn(self) -> bool:
        """Wear of Fv or Fc above 10 % over the period."""
        return max(self.wear_Fv_pct, self.wear_Fc_pct) > 10.0


def plan(machines: int, days: int, seed: int = 0) -> list[MachinePlan]:
    """The fleet's machines (module docstring), drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(machines):
        kind = i % 4
        worn = kind in (1, 3)
        lo, hi = WORN if worn else UNWORN
        wear_fv, wear_fc = (float(x) for x in rng.uniform(lo, hi, 2))
        swap_day: int | None = None
        swap_kg = 0.0
        if kind in (2, 3):
            swap_day = int(rng.integers(max(days // 4, 1), max(3 * days // 4, 2)))
            swap_kg = float(rng.uniform(*SWAP_KG) * rng.choice([-1.0, 1.0]))
        M, Fv, Fc = 95.0 + float(rng.uniform(-5, 5)), 200.0 + float(rng.uniform(-20, 20)), 20.0 + float(rng.uniform(-2, 2))
        out.append(MachinePlan(f"m{i + 1:02d}", M, Fv, Fc, wear_fv, wear_fc, swap_day, swap_kg))
    return out


def log_path(folder: Path, machine: str, day: int) -> Path:
    """``FOLDER/mNN/mNN_YYYY-MM-DD.mcap``."""
    return folder / machine / f"{machine}_{format_time(START_NS + day * DAY_NS)[:10]}.mcap"


def write_fleet(folder: Path, machines: int = 20, days: int = 30, *, seed: int = 0, duration_s: float = 8.0) -> list[MachinePlan]:
    """Write ``machines`` x ``days`` logs of ``duration_s`` each under ``folder``; return the machines' truth.

    Parameters
    ----------
    folder : Path
        Created if absent.
    machines, days : int
        The fleet's size and period.
    seed : int
        Seeds the plan, each log's noise and trajectory.
    duration_s : float
        Each log's length (8 s: one IDIM-ILIC window of 6.2 s and IDIM-LS's excitation).
    """
    # deferred: the scenarios import the plant, whose compiled loop pulls in numba (about a second), and only writing a fleet needs it
    from ilic_cli.io import write_log
    from ilic_cli.simulation.scenarios import Overrides, run_scenario

    fleet = plan(machines, days, seed)
    for i, m in enumerate(fleet):
        for day in range(days):
            n = seed * 1_000_003 + i * 1009 + day
            ov = Overrides(
                duration_s=duration_s, seed=n, trajectory="paper", trajectory_seed=n, controller="pd", params=m.parameters(day, days), effects={"noise": {}}
            )
            log = run_scenario("paper-sim", ov)
            # each machine runs its log at its own hour of the day
            log.meta.update(machine=m.machine, start_time_ns=START_NS + day * DAY_NS + (6 * 3600 + 420 * i) * 10**9)
            path = log_path(folder, m.machine, day)
            path.parent.mkdir(parents=True, exist_ok=True)
            write_log(log, path)
    return fleet


def main(argv: list[str] | None = None) -> None:
    """``python -m ilic_cli.fleet.generate FOLDER [--machines 20] [--days 30] [--seed 0] [--duration 8]``: write a fleet and its truth."""
    p = argparse.ArgumentParser(prog="python -m ilic_cli.fleet.generate", description=__doc__.split("\n\n")[0])
    p.add_argument("folder", type=Path)
    p.add_argument("--machines", type=int, default=20)
    p.add_argument("--days", type=int, default=30)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=8.0)
    a = p.parse_args(argv)
    fleet = write_fleet(a.folder, a.machines, a.days, seed=a.seed, duration_s=a.duration)
    (a.folder / "truth.json").write_text(json.dumps([m.to_dict() for m in fleet], indent=2) + "\n", encoding="utf-8")
    print(f"wrote {a.machines * a.days} logs and truth.json under {a.folder}")


if __name__ == "__main__":
    main()
