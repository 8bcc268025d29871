"""A fleet of axes: many logs identified at once, and their parameters' trends.

- :mod:`~ilic_cli.fleet.execute`: one log's task (:func:`~ilic_cli.fleet.execute.run_task`) and where tasks run
  (this process, local processes, ``dask.distributed``);
- :mod:`~ilic_cli.fleet.preload`: what the local workers' fork server loads before it forks them;
- :mod:`~ilic_cli.fleet.batch`: which logs, their content keys, the per-log store that makes a batch resumable;
- :mod:`~ilic_cli.fleet.table`: the batch table (one row per log x joint x method x window), Parquet and CSV;
- :mod:`~ilic_cli.fleet.trend`: steps and slopes per machine, joint and parameter, with a multiple-test correction;
- :mod:`~ilic_cli.fleet.trendplot`: the trend plots;
- :mod:`~ilic_cli.fleet.generate`: a simulated fleet with wear and payload swaps, for tests and the demo.

The commands import these modules only when run (``ilic --help`` stays
instant); :mod:`~ilic_cli.fleet.execute` and :mod:`~ilic_cli.fleet.batch`
import no numpy, pandas, pyarrow or dask at import time, so that a spawned
worker sets its BLAS threads before numpy loads
(:func:`~ilic_cli.fleet.execute.one_thread_worker`).
"""
