"""The simulation layer's services: what binds the plant (``plant/``) to the run logs and the estimators.

- :mod:`~ilic_cli.simulation.scenarios`: the named scenarios of ``ilic simulate`` (``paper-sim``, ``paper-payload``,
  ``emps-benchmark``), their overrides and :func:`~ilic_cli.simulation.scenarios.run_scenario`;
- :mod:`~ilic_cli.simulation.online`: IDIM-ILIC as the loop's online update (:class:`plant.closed_loop.OnlineUpdate`);
- :mod:`~ilic_cli.simulation.replay`: the replay of a log through the plant (:func:`~ilic_cli.simulation.replay.replay`)
  and the relative errors of a simulation against the recording (:func:`~ilic_cli.simulation.replay.relative_errors`);
- :mod:`~ilic_cli.simulation.timing`: the loop timing read from a recording (when the recorded command acts).

``plant/`` imports no estimator and no I/O; these modules may import both.
"""
