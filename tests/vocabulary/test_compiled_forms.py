"""The plant's compiled forms agree with the effects' definitions, for every registered plant effect.

The kernel (:mod:`plant.kernel`) has a compiled form of each built-in effect; the definition is the effect's
plant force, its columns times coefficients (:meth:`ilic_cli.effects.Effect.plant_force`, summed by
:func:`plant.dynamics.force_model`), or its block (:mod:`plant.blocks`). For each effect, at states drawn at random:

- sliding: the kernel's acceleration under a force ``u`` is ``(u - F(q, qd, 0, t)) / m(t)``, with ``F`` the
  definition's inverse dynamics and ``m = F(qdd = 1) - F(qdd = 0)`` its mass;
- at rest: the axis sticks (no acceleration) for every ``u`` between the definition's static levels
  ``F(q, 0-, 0, t)`` and ``F(q, 0+, 0, t)``;
- at break-away, beyond them: it moves in the direction of the force with ``(u - F(q, 0+-, 0, t)) / m(t)``.

The effects that add no force to the axis (the actuator and measurement effects) leave these dynamics the rigid
axis's, and their blocks are checked against the compiled loop.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import ModuleType

import numpy as np
import pytest

from ilic_cli.effects import EFFECTS, EffectParams, make_effects, plant_ids
from plant import kernel
from plant.blocks import CurrentLoop, FlexibleLoad
from plant.dynamics import P_FC_NEG, P_FC_POS, P_FV_NEG, P_FV_POS, RigidParameters, drive_lag_s, force_model, plant_vector

PARAMS = RigidParameters(95.0, 200.0, 20.0, -3.0)

VALUES: dict[str, dict[str, float]] = {
    "asymmetric_friction": {"Fv_pos": 170.0, "Fv_neg": 240.0, "Fc_pos": 18.0, "Fc_neg": 23.0},
    "stribeck": {"Fs": 6.25, "vs": 0.0125},
    "position_ripple": {"A": 2.5, "L": 0.0125, "phase": 0.7},
    "spring": {"k": 125.0, "q0": 0.125},
    "gravity": {"MX": 0.0625, "MY": 0.03},
    "payload_change": {"dM": 12.5, "t_change": 75.0},
    "friction_drift": {"dFv": -50.0, "dFc": -5.0, "tau": 10.0, "Fv_rate": 0.2, "Fc_rate": 0.01},
    "flexibility": {"stiffness": 2.5e6, "damping": 625.0, "load_fraction": 0.375},
}
"""Values of the effects with a force on the axis (the others take their defaults)."""

FRICTION_LAWS: dict[str, dict[str, float]] = {"coulomb_smoothing": {"vc": 0.02}}
"""The effects that change the friction law rather than add a force (checked by their own test: no stiction)."""

NO_FORCE = ("delay", "saturation", "quantization", "noise", "disturbance", "current_loop")
"""The plant effects that add no force to the axis: actuator, measurement and drive blocks."""

N = 60


def _states(seed: int, sliding: bool) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    q = rng.uniform(-0.1, 0.2, N)
    qd = rng.uniform(0.01, 0.3, N) * rng.choice([-1.0, 1.0], N) if sliding else np.zeros(N)
    t = rng.uniform(0.0, 150.0, N)  # across payload_change's t_change and the drift's time constant
    return q, qd, t


def compiled(
    module: ModuleType, p: np.ndarray, u: float, q: float, qd: float, t: float, load: tuple[float, float] | None = None, drift: np.ndarray | None = None
) -> tuple[int, float]:
    """The kernel's friction direction and acceleration of the motor side at one state.

    ``load``: the flexible load's state; ``drift``: the friction slots at t = 0 under ``friction_drift`` (the slots
    at ``t`` are written as ``run_periods`` writes them).
    """
    if drift is not None:
        p = p.copy()
        module._drifted(p, drift, t)
    flex = load is not None
    x2, x3 = load if load is not None else (q, qd)
    mm, ml = module._masses(p, t, flex)
    return int(module._direction(p, u, q, qd, x2, x3, t, flex)), float(module._acceleration(p, u, q, qd, x2, x3, t, mm, ml, flex))


def definition(eff: Mapping[str, EffectParams], q: np.ndarray, qd: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The definition's force at ``qdd = 0`` and its mass, ``F(qdd = 1) - F(qdd = 0)``, at each state."""
    f0 = force_model(PARAMS, dict(eff), q, qd, np.zeros_like(q), t)
    return f0, force_model(PARAMS, dict(eff), q, qd, np.ones_like(q), t) - f0


def check_against_definition(module: ModuleType, eff: Mapping[str, EffectParams], seed: int = 3, defined: Mapping[str, EffectParams] | None = None) -> None:
    """Sliding, at rest and at break-away: the compiled loop ``module`` of ``eff`` against the inverse dynamics of ``defined`` (default ``eff``)."""
    p = plant_vector(PARAMS, dict(eff))
    defined = eff if defined is None else defined
    drift = np.array([p[P_FV_POS], p[P_FV_NEG], p[P_FC_POS], p[P_FC_NEG]]) if "friction_drift" in eff else None
    rng = np.random.default_rng(seed)
    # sliding
    q, qd, t = _states(seed, sliding=True)
    u = rng.uniform(-100.0, 100.0, N)
    f0, m = definition(defined, q, qd, t)
    got = np.array([compiled(module, p, u[i], q[i], qd[i], t[i], drift=drift) for i in range(N)])
    np.testing.assert_array_equal(got[:, 0], np.sign(qd))
    np.testing.assert_allclose(got[:, 1], (u - f0) / m, rtol=1e-12, atol=1e-12)
    # at rest: the static levels of the definition, from either side of zero velocity
    q, _, t = _states(seed + 1, sliding=False)
    up, m = definition(defined, q, np.full(N, 1e-15), t)
    down, _ = definition(defined, q, np.full(N, -1e-15), t)
    assert np.all(up - down > 1.0), "a band of sticking forces"
    for frac in (0.02, 0.5, 0.98):  # stuck
        inside = [compiled(module, p, down[i] + frac * (up[i] - down[i]), q[i], 0.0, t[i], drift=drift) for i in range(N)]
        assert inside == [(0, 0.0)] * N, frac
    push = rng.uniform(0.01, 30.0, N)
    forwards = np.array([compiled(module, p, up[i] + push[i], q[i], 0.0, t[i], drift=drift) for i in range(N)])
    backwards = np.array([compiled(module, p, down[i] - push[i], q[i], 0.0, t[i], drift=drift) for i in range(N)])
    np.testing.assert_array_equal(forwards[:, 0], 1)
    np.testing.assert_array_equal(backwards[:, 0], -1)
    np.testing.assert_allclose(forwards[:, 1], push / m, rtol=1e-9)
    np.testing.assert_allclose(backwards[:, 1], -push / m, rtol=1e-9)


def test_every_plant_effect_is_covered() -> None:
    """Each registered plant effect is checked here: by its force, by its flexible load, or as adding no force."""
    assert set(plant_ids()) == set(VALUES) | set(NO_FORCE) | set(FRICTION_LAWS)
    for eid in VALUES:
        effect = EFFECTS[eid]
        linear = effect.linear_form(effect.values(VALUES[eid])) is not None
        assert linear == (eid not in ("friction_drift", "flexibility")), eid  # drift and flexibility: blocks on the columns
    assert all(EFFECTS[eid].linear_form(EFFECTS[eid].values()) is None for eid in (*NO_FORCE, *FRICTION_LAWS))


@pytest.mark.parametrize("others", [(), ("stribeck", "asymmetric_friction")])
def test_smoothed_coulomb_friction_agrees_with_the_definition_and_never_sticks(others: tuple[str, ...]) -> None:
    """``coulomb_smoothing``: sliding, the kernel's acceleration is the definition's, ``tanh(qd/vc)`` in every column of the sign
    (Stribeck's and an asymmetry's sides too); at rest no band of sticking forces: every force accelerates the axis by
    ``(u - F(q, 0, 0, t)) / m``, the friction there 0."""
    eff = make_effects({**FRICTION_LAWS, **{e: VALUES[e] for e in others}})
    p = plant_vector(PARAMS, dict(eff))
    rng = np.random.default_rng(5)
    for sliding in (True, False):
        q, qd, t = _states(6, sliding)
        qd = qd * 0.2  # about vc: the smoothed part of the law
        u = rng.uniform(-100.0, 100.0, N)
        f0, m = definition(eff, q, qd, t)
        got = np.array([compiled(kernel, p, u[i], q[i], qd[i], t[i]) for i in range(N)])
        np.testing.assert_array_equal(got[:, 0], np.where(qd >= 0.0, 1, -1))
        np.testing.assert_allclose(got[:, 1], (u - f0) / m, rtol=1e-12, atol=1e-12)
        assert np.all(got[:, 1] != 0.0)  # nothing sticks
    if not others:  # the law itself: Fc tanh(qd/vc) for the rigid axis's Fc, at qd = vc
        at_vc = [definition(e, np.zeros(1), np.array([0.02]), np.zeros(1))[0][0] for e in (eff, make_effects({}))]
        assert at_vc[0] - at_vc[1] == pytest.approx(PARAMS.Fc * (np.tanh(1.0) - 1.0), rel=1e-12)


@pytest.mark.parametrize("eid", [None, *(e for e in VALUES if e != "flexibility")])
def test_compiled_force_agrees_with_the_definition(eid: str | None) -> None:
    check_against_definition(kernel, make_effects({} if eid is None else {eid: VALUES[eid]}))


def test_compiled_forms_add_up() -> None:
    """Every force effect at once (a spring, gravity, Stribeck, drifting friction and a payload change together)."""
    check_against_definition(kernel, make_effects({e: v for e, v in VALUES.items() if e not in ("flexibility", "asymmetric_friction")}), seed=11)


def test_flexible_load_agrees_with_its_block() -> None:
    """Sliding and at rest, with the load away from the motor: the motor side feels the block's coupling force and
    only its own share of the mass; the load accelerates under the coupling with the rest (a payload change included)."""
    values = VALUES["flexibility"]
    eff = make_effects({"flexibility": values, "payload_change": VALUES["payload_change"]})
    rigid = make_effects({"payload_change": VALUES["payload_change"]})
    p = plant_vector(PARAMS, eff)
    rng = np.random.default_rng(8)
    for sliding in (True, False):
        q, qd, t = _states(9, sliding)
        dq, dv = rng.normal(0, 2e-6, N), rng.normal(0, 1e-3, N)
        u = rng.uniform(-100.0, 100.0, N)
        f0, m = definition(rigid, q, qd, t)
        coupling = np.array([FlexibleLoad(values["stiffness"], values["damping"], q[i] - dq[i], qd[i] - dv[i]).force(q[i], qd[i]) for i in range(N)])
        m_motor = (1.0 - values["load_fraction"]) * PARAMS.M
        for i in range(N):
            load = (q[i] - dq[i], qd[i] - dv[i])
            s, acc = compiled(kernel, p, u[i], q[i], qd[i], t[i], load)
            f = u[i] - coupling[i]
            if sliding:
                assert s == np.sign(qd[i])
                assert acc == pytest.approx((f - f0[i]) / m_motor, rel=1e-12, abs=1e-12)
            else:
                up = definition(rigid, q[i : i + 1], np.array([1e-15]), t[i : i + 1])[0][0]
                down = definition(rigid, q[i : i + 1], np.array([-1e-15]), t[i : i + 1])[0][0]
                assert s == (1 if f > up else -1 if f < down else 0)
            mm, ml = kernel._masses(p, t[i], True)
            load_acc = kernel._deriv(p, max(s, 1), u[i], q[i], qd[i], *load, t[i], mm, ml, True)[3]
            assert load_acc == pytest.approx(coupling[i] / (m[i] - m_motor), rel=1e-12)


@pytest.mark.parametrize("eid", NO_FORCE)
def test_effects_without_a_force_leave_the_axis_rigid(eid: str) -> None:
    """The actuator and measurement effects add nothing to the axis's dynamics: the rigid definition holds as it is."""
    check_against_definition(kernel, make_effects({eid: {"delay": -0.0013} if eid == "delay" else {}}), defined={})


def test_the_drive_lag_block_is_the_delay() -> None:
    """A negative ``delay`` is the drive's lag: whole periods and a switch within the period that add up to it."""
    T, substeps = 1e-3, 10
    for d in (-0.0013, -0.002, -0.00023):
        p = plant_vector(PARAMS, make_effects({"delay": {"delay": d}}))
        lag_n, phi, n1, n2, h1, h2 = kernel._lag_split(p, T, T / substeps, substeps)
        assert lag_n * T + phi == pytest.approx(-d, abs=1e-15) and drive_lag_s(make_effects({"delay": {"delay": d}})) == -d
        if phi > 0:
            assert n1 + n2 == substeps and n1 * h1 == pytest.approx(phi) and n2 * h2 == pytest.approx(T - phi)


def test_the_current_loop_block_is_the_compiled_one() -> None:
    """The compiled current loop applies the block's mean force over each substep and ends with its state."""
    bw, h, nsub = 700.0, 1e-4, 10
    p = plant_vector(PARAMS, make_effects({"current_loop": {"bandwidth_hz": bw}}))
    rng = np.random.default_rng(2)
    for _ in range(20):
        y0, c, q, qd = rng.uniform(-50, 50), rng.uniform(-80, 80), rng.uniform(-0.1, 0.1), rng.uniform(0.05, 0.2)
        block = CurrentLoop(bw, y0)
        x = (q, qd, q, qd)
        for j in range(nsub):  # the axis under the block's mean force, step by step, as the compiled loop does
            mm, ml = kernel._masses(p, j * h, False)
            x = kernel._step(p, block.step(c, h), *x, j * h, h, mm, ml, False)
        *state, y = kernel._current_loop_substeps(p, c, y0, 0.0, q, qd, q, qd, 0.0, h, nsub, False, 1.0 / (2.0 * np.pi * bw))
        assert y == pytest.approx(block.state, rel=1e-14, abs=1e-12)
        np.testing.assert_allclose(state, x, rtol=1e-13, atol=1e-15)
