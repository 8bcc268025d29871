"""A payload's change near a held-out block's edge (issue 29): every fold trains on both sides of it.

Corpus s710 (a 0.5 kg·m² revolute joint, 500 Hz trapezoid, a 700 Hz current loop, a spring and a payload change of
+5.5 % of the inertia): the change is placed at 6.49 s, where 80 % of the diagnosis's rows lie before it. Blocked over
the whole log, the last fold held out 103 of the 111 rows after the change and trained on 1: the inverse model's
held-out error went 3.7 % -> 130 %, the closed-loop replay's 4.15 % -> 176 %, the change was rejected and gravity was
named in its place. Laid on each side of the change (:func:`ilic_cli.diagnosis.stats.folds_either_side`), in the
selection, the replay and the fit's figures alike, the change and the spring are named.
"""

from __future__ import annotations

from ilic_cli.diagnosis.core import diagnose
from tests.corpus.robot import TOLERANCE, build, case_named, score

S710 = "rev0.5/trapezoid/500Hz/current_loop/spring+payload_change/s710"


def test_a_payload_change_at_a_block_s_edge_is_named_with_its_spring() -> None:
    """Measured: payload dM 0.02736 kg (truth 0.02725) from 6.49 s (truth 6.0, the dwell it falls in), spring 0.0871 N·m/rad
    (truth 0.0884); the replay's held-out force error 3.76 % -> 2.84 % -> 2.13 %; nothing else named."""
    case = case_named(S710)
    built = build(case)
    diag = diagnose(built.log)
    found = [(f.effect.id, f.plant_effect, f.evidence.indistinct_from) for f in diag.findings]
    s = score(built, found)
    assert s["exact"] and set(s["parameter_error"]) == {"payload_change", "spring"}, found
    assert all(e <= TOLERANCE for e in s["parameter_error"].values()), s["parameter_error"]
    (payload,) = [ev for step in diag.tried for ev in step if ev.effect == "payload_change" and ev.accepted]
    assert payload.heldout_after_pct is not None and payload.heldout_before_pct is not None
    assert payload.heldout_after_pct < payload.heldout_before_pct, payload.to_dict()  # 130 % with a fold blind to the change
    held = diag.fit["heldout_relative_error_pct"]
    assert held["after"] is not None and held["before"] is not None and held["after"] < held["before"], held  # the report's figure too
