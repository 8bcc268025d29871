"""Diagnosis: when simulation and recording differ, locate the mismatch, name the physics
the model left out, model it, and show the fit improve.

- the effects themselves (ids, physics, regressor form, search, signature) are :mod:`ilic_cli.effects`;
- :mod:`~ilic_cli.diagnosis.baseline`: the sample hold and the reversal rows the rigid baseline accounts for;
- :mod:`~ilic_cli.diagnosis.locate`: where a residual is structured (state, time, frequency);
- :mod:`~ilic_cli.diagnosis.stats`: prewhitened F-tests, blocked folds, Diebold-Mariano;
- :mod:`~ilic_cli.diagnosis.select`: forward selection on the IDIM least squares;
- :mod:`~ilic_cli.diagnosis.compare`: simulation against recording (the replay itself is :mod:`ilic_cli.simulation.replay`);
- :mod:`~ilic_cli.diagnosis.decide`: materiality, and the replay decides which proposed effects are findings;
- :mod:`~ilic_cli.diagnosis.dwell`: Stribeck friction at a reference's dwells, which the closed loop proposes;
- :mod:`~ilic_cli.diagnosis.core`: :func:`diagnose` -> :class:`Diagnosis`;
- :mod:`~ilic_cli.diagnosis.report`, :mod:`~ilic_cli.diagnosis.plots`: rendering.
"""

from ilic_cli.diagnosis.core import DiagnoseSettings, Diagnosis, Finding, diagnose
from ilic_cli.diagnosis.select import SelectSettings

__all__ = ["DiagnoseSettings", "Diagnosis", "Finding", "SelectSettings", "diagnose"]
