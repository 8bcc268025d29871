"""Logs from a simulator written apart from ``ilic``'s plant: what a user's own simulator, or a robot, records.

The project's corpora run ``plant.simulate_replay``, whose PD loop is the EMPS benchmark's (velocity of the position averaged
over two samples, the command acting one period after its sample) and whose integrator and friction are the ones the replays
use. A log from elsewhere need not share any of it. This simulator shares nothing but the axes and references of
:mod:`tests.logs.test_rates`:

- the textbook discrete PD loop: ``u(k) = kv (kp (q_ref(k) - q_m(k)) - (q_m(k) - q_m(k-1)) / T)``, clipped to +-10 V, acting
  from its own sample (``loop="same"``) or one period later (``"previous"``), logged as ``effort = drive_gain u(k)``; or the
  loop a simulator writes with the state at hand (``"state"``): the plant's own velocity in place of the difference, acting
  from its sample;
- a semi-implicit Euler integration, ``SUBSTEPS`` steps a period;
- Coulomb friction with stiction (Karnopp): at rest the axis stays while the drive's force is within the break-away level,
  and a velocity crossing zero within a step stops there; or smoothed without stiction, ``Fc tanh(v / eps)``
  (``smooth_speed = eps``), as simulators often write it: the axis then creeps at the dwells;
- the effects written out in the force balance: a warm-up of the viscous coefficient ``Fv + dFv (1 - exp(-t / tau))``,
  gravity ``g (MX cos q - MY sin q)``, a spring ``k (q - q0)``, Stribeck friction (the Coulomb level rising to ``Fs`` at
  rest, ``Fc + (Fs - Fc) exp(-(v / vs)^2)``, and breaking away there), a payload ``dM`` added at ``t``, an actuator delay
  (the force acts ``delay`` s after the command), cogging ``A sin(2 pi q / L + phase)``, and a viscous coefficient of its
  own when moving backwards (``Fv_neg``);
- position noise and encoder quantisation as the axis states.

Pure Python, one loop over the substeps (0.1 s for 9 s at 500 Hz, 10 steps a period).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ilic_cli.runlog import RunLog
from tests.logs.test_rates import AXES, reference

SUBSTEPS = 10
"""Euler steps a period by default (the tests'). At 0.2 ms (500 Hz) its steps lag a break-away from Stribeck friction enough for
the diagnosis to see a delay of a tenth of a millisecond beside it; with 40 (50 µs) that is gone (:mod:`benchmarks.corpus_independent`)."""
G = 9.81
LOOPS = ("same", "previous", "state", "continuous")


def simulate(name: str, fs_hz: float, loop: str, effects: dict[str, dict[str, float]], seed: int, repeat: int = 1, smooth_speed: float = 0.0) -> RunLog:
    """The axis ``name`` of :data:`tests.logs.test_rates.AXES` following its moves ``repeat`` times (each repetition from where the last
    ended) at ``fs_hz`` under the textbook PD loop, with ``effects`` (``drift``: ``dFv, tau``; ``gravity``: ``MX, MY``; ``spring``:
    ``k, q0``; ``stribeck``: ``Fs, vs``; ``payload``: ``dM, t``; ``delay``: ``delay`` s; ``ripple``: ``A, L, phase``;
    ``asymmetric``: ``Fv_neg``); the log as a user's CSV is read with the loop declared: ``t, q, q_ref, tau``, no ``vir``."""
    axis = AXES[name]
    _, q1 = reference(axis, fs_hz)
    q_ref = np.concatenate([q1 + i * q1[-1] for i in range(repeat)])
    return run_loop(axis, fs_hz, q_ref, loop, effects, seed, name, smooth_speed=smooth_speed)


def run_loop(
    axis: Any,
    fs_hz: float,
    q_ref: np.ndarray,
    loop: str,
    effects: dict[str, dict[str, float]],
    seed: int,
    name: str = "",
    substeps: int = SUBSTEPS,
    smooth_speed: float = 0.0,
) -> RunLog:
    """``axis`` (its ``truth``, ``drive_gain``, ``gains()``, ``noise``, ``resolution``, ``joint``: :class:`tests.logs.test_rates.Axis` or
    :class:`tests.corpus.robot.Axis`) following ``q_ref`` sampled at ``fs_hz`` under the textbook PD loop (:func:`simulate`), in
    ``substeps`` Euler steps a period; ``smooth_speed`` > 0: Coulomb friction ``tanh(v / smooth_speed)``, no stiction."""
    if loop not in LOOPS:
        raise ValueError(f"loop: one of {LOOPS}")
    t = np.arange(len(q_ref)) / fs_hz
    T, h = 1.0 / fs_hz, 1.0 / (fs_hz * substeps)
    M, Fv, Fc = axis.truth["M"], axis.truth["Fv"], axis.truth["Fc"]
    kp, kv = axis.gains()
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, axis.noise, len(t))
    drift, gravity, lag = effects.get("drift"), effects.get("gravity"), effects.get("delay")
    spring, stribeck, payload = effects.get("spring"), effects.get("stribeck"), effects.get("payload")
    ripple, asymmetric = effects.get("ripple"), effects.get("asymmetric")
    breakaway = stribeck["Fs"] if stribeck else Fc
    pending = [0.0] * (int(round(lag["delay"] / h)) + 1 if lag else 1)  # the commanded force on its way to the axis
    q = v = 0.0
    q_prev = 0.0
    u_prev = 0.0
    qm = np.empty(len(t))
    effort = np.empty(len(t))
    for k in range(len(t)):
        meas = round((q + noise[k]) / axis.resolution) * axis.resolution
        law = kv * (kp * (q_ref[k] - meas) - (v if loop == "state" else (meas - (q_prev if k else meas)) / T))
        if loop == "continuous":  # logged at the sample: the law on the state there
            law = kv * (kp * (q_ref[k] - q) - v)
        u = u_prev if loop == "previous" else law
        u = min(max(u, -10.0), 10.0)
        u_prev, q_prev = law, meas
        qm[k], effort[k] = meas, axis.drive_gain * u
        for s in range(substeps):
            if loop == "continuous" and s:  # the law inside the dynamics (a solver's right-hand side): on the state, every step
                r = q_ref[k] + (q_ref[min(k + 1, len(t) - 1)] - q_ref[k]) * s / substeps
                u = min(max(kv * (kp * (r - q) - v), -10.0), 10.0)
            pending.append(axis.drive_gain * u)
            force = pending.pop(0)
            time = t[k] + s * h
            fv = Fv + drift["dFv"] * (1.0 - math.exp(-time / drift["tau"])) if drift else Fv
            if gravity:
                force -= G * (gravity["MX"] * math.cos(q) - gravity["MY"] * math.sin(q))
            if spring:
                force -= spring["k"] * (q - spring["q0"])
            if ripple:  # cogging: a force periodic in the position
                force -= ripple["A"] * math.sin(2.0 * math.pi * q / ripple["L"] + ripple["phase"])
            if asymmetric and v < 0.0:  # viscous friction of its own when moving backwards
                fv += asymmetric["Fv_neg"] - Fv
            if smooth_speed > 0.0:  # no stiction: the sign smoothed
                direction = math.tanh(v / smooth_speed)
            elif v == 0.0 and abs(force) <= breakaway:  # stuck
                continue
            else:
                direction = math.copysign(1.0, v if v != 0.0 else force)
            fc = Fc + (stribeck["Fs"] - Fc) * math.exp(-((v / stribeck["vs"]) ** 2)) if stribeck else Fc
            m = M + payload["dM"] if payload and time >= payload["t"] else M
            v_next = v + h * (force - fv * v - fc * direction) / m
            v = 0.0 if smooth_speed == 0.0 and v != 0.0 and v_next * v < 0.0 else v_next
            q += h * v
    position, force_unit = ("m", "N") if axis.joint == "prismatic" else ("rad", "N·m")
    meta: dict[str, Any] = {"controller": {"kind": "pd", "kp": kp, "kv": kv}, "drive_gain": axis.drive_gain, "source": f"independent {name or axis.joint}"}
    return RunLog({"t": t, "q": qm, "q_ref": q_ref, "tau": effort}, {"t": "s", "q": position, "q_ref": position, "tau": force_unit}, meta)
