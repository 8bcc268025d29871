"""Spring or gravity (issue 29): the J-test between them, and a spring's stiffness being positive."""

from __future__ import annotations

import numpy as np

from ilic_cli.diagnosis.rivals import parsimonious_first, rival_test
from ilic_cli.diagnosis.select import Evaluation, SelectSettings, forward_select
from ilic_cli.diagnosis.stats import nested_f_test
from ilic_cli.effects import EFFECTS, Effect
from ilic_cli.idim_ls import IDIMData, lsq_rows
from ilic_cli.regressor import get_model
from tests.unit.synth import FS, motion, rigid_force

BASE = get_model("rigid-offset")


def _evaluations(W: np.ndarray, y: np.ndarray, q: np.ndarray) -> list[tuple[Evaluation, Effect, np.ndarray, np.ndarray]]:
    """Gravity's and the spring's candidates on ``(W, y)``, best fit first (as the selection sorts them)."""
    evals = []
    for eid, cols in (("gravity", np.c_[9.81 * np.cos(q), -9.81 * np.sin(q)]), ("spring", np.c_[q])):
        W1 = np.hstack([W, cols])
        rel = float(np.linalg.norm(y - W1 @ np.linalg.lstsq(W1, y, rcond=None)[0]) / np.linalg.norm(y))
        evals.append((Evaluation(eid, None, None, nested_f_test(W, y, W1, y, cols.shape[1]), rel), EFFECTS[eid], W1, y))
    return sorted(evals, key=lambda e: e[0].relative_error_pct)


def test_a_curvature_gravity_cannot_make_does_not_name_gravity() -> None:
    """A spring with a stiffening of its own (``0.03 q^4`` beside ``0.3 q`` over +-1.2 rad): gravity fits best, and its two columns beyond
    the spring catch the curvature (p ~ 1e-78), which named gravity before the J-test; gravity's fitted force, whose curvature is tied to
    its slope, adds nothing significant beyond the spring (p = 0.12) while the spring's straight line adds to gravity (p ~ 1e-70): a
    spring, without an ambiguity (planting the two columns in ``rival_test`` fails it)."""
    rng = np.random.default_rng(0)
    q = np.linspace(-1.2, 1.2, 3000)
    W = np.c_[np.ones_like(q), rng.standard_normal(q.size)]
    y = W @ np.array([0.1, 1.0]) + 0.3 * q + 0.03 * q**4 + 0.01 * rng.standard_normal(q.size)
    evals = _evaluations(W, y, q)
    assert evals[0][0].effect == "gravity"  # it fits best: two columns
    assert rival_test(evals[1][2], evals[0][2], W.shape[1], y).p_value > 0.1
    ev = parsimonious_first(evals, W, y, 0.001)[0][0]
    assert (ev.effect, ev.indistinct_from) == ("spring", None)


def test_the_j_test_adds_one_column_the_rival_s_fitted_force() -> None:
    """The rival's force, fitted with the shared columns, is the one column added: its F-test equals the nested test with that column."""
    rng = np.random.default_rng(1)
    q = np.linspace(0.0, 1.5, 500)
    W = np.c_[np.ones_like(q), rng.standard_normal(q.size)]
    y = W @ np.array([0.2, 1.0]) + 0.5 * np.cos(q) + 0.05 * rng.standard_normal(q.size)
    Wg, Ws = np.c_[W, np.cos(q), np.sin(q)], np.c_[W, q]
    theta = np.linalg.lstsq(Wg, y, rcond=None)[0]
    t = rival_test(Ws, Wg, 2, y)
    assert t.df1 == 1
    assert t.F == nested_f_test(Ws, y, np.c_[Ws, Wg[:, 2:] @ theta[2:]], y, 1).F
    assert t.p_value < 1e-6  # the curvature of a cosine over 1.5 rad is no straight line


def _gravity_log(mx: float, my: float) -> IDIMData:
    """IDIM rows of a revolute joint swinging +-0.8 rad with gravity ``g (MX cos q - MY sin q)``, 10 N·m of noise hiding the curvature."""
    t, q, qd, qdd = motion(20_000)
    q, qd, qdd = 8.0 * q, 8.0 * qd, 8.0 * qdd
    force = rigid_force(qd, qdd, M=0.5, Fv=0.8, Fc=1.5, offset=0.0) + 9.81 * (mx * np.cos(q) - my * np.sin(q))
    return lsq_rows(t, q, force + np.random.default_rng(0).normal(0.0, 10.0, q.size), FS, BASE)


def test_gravity_about_an_upright_is_no_negative_spring() -> None:
    """Gravity whose torque grows away from q = 0 (MY > 0: the arm near its upright) is, over +-0.8 rad and under noise that hides the
    curvature, a straight line of negative slope: a spring of negative stiffness, which no passive spring has. Gravity is named, not
    "spring or gravity" (corpus s530, s732; planting ``th[0] >= -math.inf`` in the spring's ``impossible`` fails it)."""
    res = forward_select(_gravity_log(0.05, 0.3), BASE, FS, SelectSettings(effects=("spring", "gravity"), max_effects=1))
    assert [(e.effect, e.indistinct_from) for e in res.accepted] == [("gravity", None)]
    spring = res.last_word("spring")
    assert spring is not None and spring.reason.startswith("physically impossible: negative stiffness")


def test_an_ambiguity_the_j_test_states_is_not_undone_by_the_stronger_candidate_check() -> None:
    """Gravity of a small first moment (MX 0.05, MY -0.3) over +-0.8 rad: the spring's straight line and gravity's force cannot be
    told apart, and the spring is proposed with gravity as ``indistinct_from``, although gravity's F-test is the stronger (p 9e-62
    against 3e-61). The selection's check that a candidate is significant beside a stronger one (``select._beside_stronger``)
    leaves two linear effects to the J-test: without that exception (planted), the spring is not significant beside gravity's two
    columns and gravity is named bare (corpus s12711, a spring named gravity)."""
    res = forward_select(_gravity_log(0.05, -0.3), BASE, FS, SelectSettings(effects=("spring", "gravity"), max_effects=1))
    assert [(e.effect, e.indistinct_from) for e in res.accepted] == [("spring", "gravity")]
    gravity, spring = res.last_word("gravity"), res.last_word("spring")
    assert gravity is not None and spring is not None and gravity.test.p_adjusted < spring.test.p_adjusted
