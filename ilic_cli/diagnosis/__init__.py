"""Diagnosis: when simulation and recording differ, locate the mismatch, name the physics
the model left out, model it, and show the fit improve.

Stages, each passing typed values to the next (:mod:`~ilic_cli.diagnosis.verdicts`: the decisions as enums):

- propose: :mod:`~ilic_cli.diagnosis.propose` (the inverse model's forward selection, :mod:`~ilic_cli.diagnosis.select`;
  Stribeck friction at a reference's dwells, :mod:`~ilic_cli.diagnosis.dwell`);
- decide: :mod:`~ilic_cli.diagnosis.decide` (materiality, :mod:`~ilic_cli.diagnosis.materiality`; the replay,
  :mod:`~ilic_cli.diagnosis.heldout_replay`; the Monte-Carlo null, :mod:`~ilic_cli.diagnosis.null`);
- refit: :mod:`~ilic_cli.diagnosis.refit` (the closed-loop refit, :mod:`~ilic_cli.diagnosis.closed_loop_refit`;
  the open-loop segments, :mod:`~ilic_cli.diagnosis.segments`);
- report: :mod:`~ilic_cli.diagnosis.core` (:func:`diagnose` -> :class:`Diagnosis`), rendered by
  :mod:`~ilic_cli.diagnosis.report` and :mod:`~ilic_cli.diagnosis.plots`.

The effects themselves (ids, physics, regressor form, search, signature) are :mod:`ilic_cli.effects`; the settings
of every stage one :class:`DiagnosisSettings` (:mod:`~ilic_cli.diagnosis.settings`).
"""

from ilic_cli.diagnosis.core import Diagnosis, Finding, diagnose
from ilic_cli.diagnosis.select import SelectSettings
from ilic_cli.diagnosis.settings import DiagnoseSettings, DiagnosisSettings

__all__ = ["DiagnoseSettings", "DiagnosisSettings", "Diagnosis", "Finding", "SelectSettings", "diagnose"]
