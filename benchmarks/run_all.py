"""Run the speed benchmarks beside this file (``make bench``); print their figures.

Each script runs in its own interpreter: one benchmark's heap (the 1-hour
arrays of ``bench_identify.py``) must not slow the next (it cost the sqlite3
read about 20 % when they shared a process).

``bench_large.py`` (a 1-hour MCAP log: minutes to generate and read) runs only
with ``--large`` (``make bench-large``).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def main() -> None:
    here = Path(__file__).parent
    large = "--large" in sys.argv[1:]
    for script in sorted(here.glob("bench_*.py")):
        if (script.name == "bench_large.py") != large:
            continue
        print(f"== {script.name}", flush=True)
        subprocess.run([sys.executable, str(script)], check=True)
        print(flush=True)


if __name__ == "__main__":
    main()
