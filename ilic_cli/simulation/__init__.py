"""The simulation layer's services, between the estimators and the diagnosis.

- :mod:`~ilic_cli.simulation.replay`: the replay of a log through the plant (:func:`~ilic_cli.simulation.replay.replay`)
  and the relative errors of a simulation against the recording (:func:`~ilic_cli.simulation.replay.relative_errors`);
- :mod:`~ilic_cli.simulation.timing`: the loop timing read from a recording (when the recorded command acts).
"""
