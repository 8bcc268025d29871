"""The simulation layer's services: what binds the plant (``plant/``) to the run logs and the estimators.

- :mod:`~ilic_cli.simulation.scenarios`: the named scenarios of ``ilic simulate`` (``paper-sim``, ``paper-payload``,
  ``emps-benchmark``), their overrides and :func:`~ilic_cli.simulation.scenarios.run_scenario`;
- :mod:`~ilic_cli.simulation.online`: IDIM-ILIC as the loop's online update (:class:`plant.closed_loop.OnlineUpdate`).

``plant/`` imports no estimator and no I/O; these modules may import both.
"""
