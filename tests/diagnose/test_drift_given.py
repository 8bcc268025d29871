"""The catalogue's selection fits its candidates with a friction drift's trend columns in the model (issue 29).

Corpus log s730 (rev0.5, 500 Hz multisine): gravity beside a warm-up of viscous friction. Before, the catalogue was
selected on the rigid model and the drift sought after it: the drift's trend stayed in every candidate's residual
and the selection stated ``spring or gravity`` (the data cannot tell them apart). With the drift found on the rigid
model first (:func:`ilic_cli.diagnosis.propose.drift_given`) and its columns in the selection's model, gravity's
columns add beyond a spring's and gravity is proposed alone.
"""

from __future__ import annotations

import time
from dataclasses import replace

from ilic_cli.diagnosis.propose import propose
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.diagnosis.verdicts import Selection
from tests.corpus.robot import build, cases


def test_gravity_beside_a_drift_is_proposed_with_the_drift_in_the_model() -> None:
    t0 = time.perf_counter()
    case = next(c for c in cases() if c.name.endswith("/gravity+friction_drift/s730"))
    built = build(case)
    settings = DiagnosisSettings()
    settings = replace(settings, ls=settings.ls.at_rate(built.log.fs_hz))  # as diagnose does
    prop = propose(built.log, settings, None, None)
    first = prop.selection.accepted[0]
    assert first.effect == "gravity" and first.outcome is Selection.ACCEPTED, [(e.effect, e.reason) for e in prop.selection.accepted]
    assert first.indistinct_from is None
    assert time.perf_counter() - t0 < 30.0
