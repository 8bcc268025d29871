"""Run the speed benchmarks beside this file (``make bench``); print their figures.

``bench_large.py`` (a 1-hour MCAP log: minutes to generate and read) runs only
with ``--large`` (``make bench-large``).
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path


def main() -> None:
    here = Path(__file__).parent
    large = "--large" in sys.argv[1:]
    for script in sorted(here.glob("bench_*.py")):
        if (script.name == "bench_large.py") != large:
            continue
        print(f"== {script.name}", flush=True)
        sys.argv = [str(script)]
        runpy.run_path(str(script), run_name="__main__")
        print(flush=True)


if __name__ == "__main__":
    main()
