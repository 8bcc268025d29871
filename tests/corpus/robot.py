"""A corpus of robot-like logs with known truth: any axis, any rate, any trajectory (issue 29 item 8).

Where :mod:`tests.corpus` is EMPS-like (a 95 kg axis at 1 kHz under the paper's CTC), these logs are what a robot
records: the project's plant under a PD loop of about 10 Hz bandwidth (:func:`plant.replay.simulate_replay`),
the held drive command as the force, on

* four axes (:data:`AXES`): a 12 kg and a 200 kg linear axis, a 0.01 kg·m² wrist and a 0.5 kg·m² elbow joint;
* four trajectories (:data:`TRAJECTORIES`): S-curve and trapezoidal point-to-point moves with dwells at rest, a
  chirp and a multisine, each varied by the seed;
* rates of 500 Hz, 1 and 2 kHz (:data:`RATES_HZ`), and 250 Hz and 8 kHz in a smaller set (:data:`EDGE_RATES_HZ`);
* three noise models (:data:`NOISE`): sensor noise and quantisation, plus a current loop's lag, or plus a
  band-limited force disturbance;
* every catalogue effect the joint can have, gravity on the revolute joints, friction drift, and two-effect
  combinations (:data:`PAIRS`), each sized on its own log so that it changes the rigid fit's relative error
  (``identify --method ls`` as it built its rows when the corpus was sized: :func:`relative_error_pct`) by
  :data:`TARGETS_PTS` points (:func:`calibrate`), the change measured and kept.

A case is named ``AXIS/TRAJECTORY/RATE/NOISE/EFFECTS/sSEED``; :func:`cases` lists the corpus and :func:`build` makes
one log (deterministic: same case, bit-identical log). ``benchmarks/corpus_robot.py`` writes them to CSV and
ROS 2 bags, diagnoses them and prints the table of docs/diagnosis.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ilic_cli.effects.definition import Z95
from ilic_cli.runlog import RunLog

STANDARD_GRAVITY = 9.80665
BANDWIDTH_HZ = 10.0
"""The PD loop's bandwidth (damping 0.7): stable with its one-sample delay down to 250 Hz."""
DURATION_S = 10.0
"""Length of every log but the 8 kHz ones (:data:`LONG_RATE_DURATION_S`)."""
LONG_RATE_DURATION_S = 5.0
"""Length of an 8 kHz log (40 000 samples): its replays cost eight times a 1 kHz log's per second."""
TOLERANCE = 0.15
"""Parameters recovered within this relative error count as recovered (the issue's 15 %)."""
DELAY_SIZE_TOLERANCE = 0.5
"""A current-loop-sized ``delay`` on a log with that loop is right within this relative error of the loop's time constant."""


@dataclass(frozen=True)
class Axis:
    """One joint: its rigid truth (SI: kg or kg·m², N·s/m or N·m·s/rad, N or N·m), drive gain and motion scale."""

    name: str
    joint: str
    truth: dict[str, float]
    drive_gain: float
    """N/V (N·m/V): the command stays within the drive's +-10 V but at the peaks of a few effect logs (s371, s440: 1.8 and
    2.7 % of the samples clipped, which every command masks as a saturated drive)."""
    speed: float
    """Cruise speed of the moves (m/s, rad/s)."""
    span: float
    """Half the range of positions the moves visit (m, rad)."""
    noise: float
    resolution: float
    bandwidth_hz: float = BANDWIDTH_HZ
    """The PD loop's bandwidth (damping 0.7)."""

    @property
    def units(self) -> tuple[str, str]:
        return ("m", "N") if self.joint == "prismatic" else ("rad", "N·m")

    def gains(self) -> tuple[float, float]:
        """``kp, kv`` of a PD loop of :attr:`bandwidth_hz`, damping 0.7: ``gtau kv = 2 xi w M``, ``gtau kv kp = M w^2``."""
        w = 2 * math.pi * self.bandwidth_hz
        kv = 2 * 0.7 * w * self.truth["M"] / self.drive_gain
        return self.truth["M"] * w * w / (self.drive_gain * kv), kv


AXES: dict[str, Axis] = {
    "lin12": Axis("lin12", "prismatic", {"M": 12.0, "Fv": 35.0, "Fc": 4.0}, 10.0, 0.25, 0.15, 5e-7, 2e-7),
    "lin200": Axis("lin200", "prismatic", {"M": 200.0, "Fv": 450.0, "Fc": 45.0}, 100.0, 0.2, 0.12, 5e-7, 2e-7),
    "rev0.01": Axis("rev0.01", "revolute", {"M": 0.01, "Fv": 0.02, "Fc": 0.04}, 0.05, 2.5, 1.5, 1e-5, 1.2e-5),
    "rev0.5": Axis("rev0.5", "revolute", {"M": 0.5, "Fv": 0.8, "Fc": 1.5}, 2.0, 1.5, 1.2, 1e-5, 1.2e-5),
}
"""The axes: 3+ scales (12 and 200 kg linear, 0.01 and 0.5 kg·m² revolute), both joint types."""

BEYOND_AXES: dict[str, Axis] = {
    "lin2": Axis("lin2", "prismatic", {"M": 2.0, "Fv": 8.0, "Fc": 1.5}, 4.0, 0.5, 0.1, 2e-7, 1e-7, bandwidth_hz=14.0),
    "lin50": Axis("lin50", "prismatic", {"M": 50.0, "Fv": 120.0, "Fc": 15.0}, 60.0, 0.4, 0.3, 1e-6, 5e-7, bandwidth_hz=6.0),
    "rev0.002": Axis("rev0.002", "revolute", {"M": 0.002, "Fv": 0.004, "Fc": 0.01}, 0.03, 4.0, 2.0, 2e-5, 2e-5, bandwidth_hz=15.0),
    "rev3": Axis("rev3", "revolute", {"M": 3.0, "Fv": 2.0, "Fc": 6.0}, 10.0, 1.0, 1.0, 1e-5, 1.2e-5, bandwidth_hz=8.0),
}
"""Axes beyond the design (:func:`beyond_cases`): other masses, friction ratios, encoders and loop bandwidths (6 to 15 Hz)."""
ALL_AXES: dict[str, Axis] = {**AXES, **BEYOND_AXES}

TRAJECTORIES = ("s-curve", "trapezoid", "chirp", "multisine")
"""Point-to-point moves with dwells (raised-cosine or linear speed ramps), a chirp, a multisine."""
DWELL_TRAJECTORIES = ("s-curve", "trapezoid")

RATES_HZ = (500.0, 1000.0, 2000.0)
EDGE_RATES_HZ = (250.0, 8000.0)
BEYOND_RATES_HZ = (400.0, 1500.0, 4000.0)
"""Rates of :func:`beyond_cases`: none of the design's (400 Hz and 1.5 kHz between its rates, 4 kHz between 2 and 8 kHz)."""


def noise_effects(axis: Axis, kind: str) -> dict[str, dict[str, float]]:
    """The noise model ``kind`` of :data:`NOISE` on ``axis``: nothing a rigid model can explain but a current loop's lag."""
    out: dict[str, dict[str, float]] = {"noise": {"q_std": axis.noise}, "quantization": {"resolution": axis.resolution}}
    if kind == "current_loop":
        out["current_loop"] = {"bandwidth_hz": 700.0}
    elif kind == "disturbance":
        out["disturbance"] = {"std": 0.1 * axis.truth["Fc"], "bandwidth_hz": 10.0}
    return out


NOISE = ("sensor", "current_loop", "disturbance")


# ---------------------------------------------------------------------------
# the references
# ---------------------------------------------------------------------------
def _moves(axis: Axis, seed: int, duration_s: float) -> list[tuple[float, float, float, float]]:
    """``(v, t_acc, t_cruise, dwell)`` of moves between random targets in ``[-span, span]``, filling ``duration_s``."""
    rng = np.random.default_rng(seed)
    out, here, used = [], 0.0, 0.3
    while True:
        target = here
        while abs(target - here) < 0.5 * axis.span:
            target = float(rng.uniform(-axis.span, axis.span))
        dist = target - here
        v = axis.speed * float(rng.uniform(0.6, 1.0))
        ta = float(rng.uniform(0.08, 0.15))
        if abs(dist) / v < 2 * ta:  # too short to cruise: slower
            v = abs(dist) / (2 * ta)
        tc = abs(dist) / v - ta
        dwell = float(rng.uniform(0.25, 0.45))
        if used + 2 * ta + tc + dwell > duration_s:
            return out
        out.append((math.copysign(v, dist), ta, tc, dwell))
        here, used = target, used + 2 * ta + tc + dwell


def _point_to_point(moves: list[tuple[float, float, float, float]], t: np.ndarray, shape: str) -> np.ndarray:
    """Exact position of the moves (speed ramps linear for ``trapezoid``, raised-cosine for ``s-curve``) after a 0.3 s dwell."""
    q = np.zeros_like(t)
    start = 0.3
    for v, ta, tc, dwell in moves:
        s = np.clip(t - start, 0.0, None)

        def ramp(x: np.ndarray, v: float = v, ta: float = ta) -> np.ndarray:  # distance x into a ramp from 0 to v
            x = np.clip(x, 0.0, ta)
            if shape == "trapezoid":
                return 0.5 * v * x * x / ta
            return 0.5 * v * (x - ta / np.pi * np.sin(np.pi * x / ta))

        q = q + ramp(s) + v * np.clip(s - ta, 0.0, tc) + v * np.clip(s - ta - tc, 0.0, ta) - ramp(s - ta - tc)
        start += 2 * ta + tc + dwell
    return q


def reference(axis: Axis, trajectory: str, fs_hz: float, seed: int, duration_s: float = DURATION_S) -> tuple[np.ndarray, np.ndarray]:
    """``t, q_ref`` of ``duration_s`` at ``fs_hz``: shape ``trajectory`` on ``axis``'s scale, varied by ``seed``."""
    t = np.arange(int(round(duration_s * fs_hz))) / fs_hz
    if trajectory in DWELL_TRAJECTORIES:
        return t, _point_to_point(_moves(axis, seed, duration_s), t, trajectory)
    rng = np.random.default_rng(seed)
    if trajectory == "chirp":  # 0.2 -> f1 Hz over the log, faded in over 1 s, peak speed about the axis's
        f0, f1 = 0.2, float(rng.uniform(1.5, 2.5))
        amp = min(axis.span, 1.2 * axis.speed / (2 * np.pi * f1))
        phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) * t * t / duration_s)
        fade = 0.5 * (1 - np.cos(np.pi * np.clip(t / 1.0, 0.0, 1.0)))
        return t, amp * fade * np.sin(phase)
    # multisine: harmonics 1..12 of 0.2 Hz, equal velocity amplitude, random phases, faded in over 1 s
    ks = np.arange(1, 13)
    w = 2 * np.pi * 0.2 * ks
    ph = rng.uniform(0, 2 * np.pi, len(ks))
    v_amp = 0.45 * axis.speed * math.sqrt(2.0 / len(ks))
    q = (v_amp / w[:, None] * (np.sin(w[:, None] * t + ph[:, None]) - np.sin(ph[:, None]))).sum(axis=0)
    fade = 0.5 * (1 - np.cos(np.pi * np.clip(t / 1.0, 0.0, 1.0)))
    return t, fade * q


# ---------------------------------------------------------------------------
# the effects, as functions of one relative size
# ---------------------------------------------------------------------------
def effect_of_size(eid: str, s: float, axis: Axis, variant: int = 0, duration_s: float = DURATION_S) -> dict[str, float]:
    """Parameters of effect ``eid`` of relative size ``s`` on ``axis`` (relative to its own friction, mass or range)."""
    m, fv, fc = (axis.truth[k] for k in ("M", "Fv", "Fc"))
    if eid == "asymmetric_friction":
        return {"Fv_pos": fv, "Fv_neg": fv * (1 + s), "Fc_pos": fc, "Fc_neg": fc}
    if eid == "stribeck":
        return {"Fs": s * fc, "vs": (0.04, 0.06, 0.08)[variant % 3] * axis.speed}
    if eid == "position_ripple":
        return {"A": s * fc, "L": (0.2, 0.25, 0.3)[variant % 3] * axis.span, "phase": (0.3, 1.2, -0.7)[variant % 3]}
    if eid == "spring":
        return {"k": s * fc / axis.span, "q0": 0.2 * axis.span}
    if eid == "gravity":
        mx = s * fc / STANDARD_GRAVITY
        return {"MX": mx, "MY": (0.5, -0.4, 0.8)[variant % 3] * mx}
    if eid == "payload_change":
        return {"dM": s * m, "t_change": (0.4, 0.5, 0.6)[variant % 3] * duration_s}
    if eid == "delay":
        return {"delay": -s * 1e-3}
    if eid == "flexibility":
        f_res, zeta = ((28.0, 0.1), (35.0, 0.15), (31.0, 0.12))[variant % 3]
        k = (2.0 * math.pi * f_res) ** 2 * s * m
        return {"stiffness": k, "damping": 2.0 * zeta * math.sqrt(k * s * m), "load_fraction": s}
    if eid == "friction_drift":
        if variant % 2 == 0:  # a warm-up of viscous friction
            return {"dFv": -s * fv, "dFc": 0.0, "tau": (0.25, 0.3, 0.2)[variant % 3] * duration_s, "Fv_rate": 0.0, "Fc_rate": 0.0}
        return {"dFv": 0.0, "dFc": 0.0, "tau": 1.0, "Fv_rate": 0.0, "Fc_rate": s * fc / duration_s}  # a wear of Coulomb friction
    raise ValueError(f"no size rule for effect {eid!r}")


SIZE_GUESS = {
    "asymmetric_friction": 0.2,
    "stribeck": 0.3,
    "position_ripple": 0.1,
    "spring": 0.1,
    "gravity": 0.1,
    "payload_change": 0.05,
    "delay": 0.5,
    "flexibility": 0.05,
    "friction_drift": 0.2,
}
"""Starting relative size of the calibration's search."""

PRISMATIC_EFFECTS = ("asymmetric_friction", "stribeck", "position_ripple", "spring", "payload_change", "delay", "flexibility", "friction_drift")
REVOLUTE_EFFECTS = (*PRISMATIC_EFFECTS, "gravity")
BAND_PTS = (0.2, 1.5)
"""The change of the rigid fit's relative error (points) an effect is sized to (the issue's 0.2-1.5 points)."""
TARGETS_PTS = (0.4, 0.8, 1.2)
"""Sizes aimed at (points of the rigid fit's relative error), by seed index."""
PAIRS = (("asymmetric_friction", "position_ripple"), ("spring", "payload_change"), ("stribeck", "flexibility"), ("gravity", "friction_drift"))
PAIR_TARGET_PTS = 0.5
"""Size of each effect of a pair alone (points)."""
SEEDS_PER_CASE = 3


# ---------------------------------------------------------------------------
# cases
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    """A recipe: the axis, trajectory, rate, noise model, seed, and the effects with their relative sizes and targets."""

    axis: str
    trajectory: str
    fs_hz: float
    noise: str
    seed: int
    effects: tuple[str, ...] = ()
    target_pts: float = 0.0
    writer: str = "library"
    """How the log reaches ``ilic``: ``csv`` or ``ros2`` (written, then ``ilic diagnose`` on the file), or ``library``."""
    sizes: dict[str, float] = field(default_factory=dict, compare=False)

    @property
    def name(self) -> str:
        return f"{self.axis}/{self.trajectory}/{self.fs_hz:g}Hz/{self.noise}/{'+'.join(self.effects) or 'clean'}/s{self.seed}"

    @property
    def clean(self) -> bool:
        return not self.effects

    @property
    def duration_s(self) -> float:
        return LONG_RATE_DURATION_S if self.fs_hz >= 8000.0 else DURATION_S

    @property
    def variant(self) -> int:
        return self.seed % 3

    def expected_lag_s(self) -> float:
        """The current loop's time constant (s) when the noise model has one, else 0."""
        return 1.0 / (2.0 * math.pi * 700.0) if self.noise == "current_loop" else 0.0


def cases() -> list[Case]:
    """The whole corpus (clean logs, single effects with 3 seeds each, pairs with 3 seeds each), in a fixed order.

    Clean: every axis x trajectory x main rate, the noise model rotating (48 logs), and every axis x edge rate on the
    dwell trajectories (16). Effects: every effect of each axis with 3 seeds; seed ``k`` takes rate ``RATES_HZ[k]``,
    target ``TARGETS_PTS[k]``, the trajectory and noise model rotating. Pairs likewise on the revolute elbow and the
    12 kg axis (gravity pairs: revolute only). Edge rates: one effect per axis and rate. A third of the logs go through
    the CLI as CSV, a sixth as ROS 2 bags (prismatic joints only: a bag cannot say its joint is revolute).
    """
    out: list[Case] = []
    for i, (a, tr, fs) in enumerate((a, tr, fs) for a in AXES for tr in TRAJECTORIES for fs in RATES_HZ):
        out.append(Case(a, tr, fs, NOISE[(i + i // 3) % 3], 1 + i, writer=_writer(a, i + 2 * (i // 3))))
    for i, (a, tr, fs) in enumerate((a, tr, fs) for a in AXES for tr in DWELL_TRAJECTORIES for fs in EDGE_RATES_HZ):
        if fs < 8000.0 or tr == DWELL_TRAJECTORIES[i // 4 % 2]:  # 8 kHz: one trajectory per axis, in turn
            out.append(Case(a, tr, fs, NOISE[(i + i // 2) % 2], 101 + i, writer=_writer(a, i)))
    n = 0
    for ai, a in enumerate(AXES):
        effects = REVOLUTE_EFFECTS if AXES[a].joint == "revolute" else PRISMATIC_EFFECTS
        for ei, eid in enumerate(effects):
            for k in range(SEEDS_PER_CASE):
                tr = TRAJECTORIES[(ai + ei + k) % 4]
                out.append(Case(a, tr, RATES_HZ[k], NOISE[(ei + k) % 3], 200 + 10 * n + k, (eid,), TARGETS_PTS[k], writer=_writer(a, n + k)))
            n += 1
    for pi, pair in enumerate(PAIRS):
        for a in ("lin12", "rev0.5"):
            if "gravity" in pair and AXES[a].joint != "revolute":
                continue
            for k in range(SEEDS_PER_CASE):
                tr = TRAJECTORIES[(pi + k) % 4]
                out.append(Case(a, tr, RATES_HZ[k], NOISE[(pi + k) % 3], 700 + 10 * pi + k, pair, PAIR_TARGET_PTS, writer=_writer(a, pi + k)))
    for ai, a in enumerate(AXES):
        for ri, fs in enumerate(EDGE_RATES_HZ):
            if fs >= 8000.0 and a not in ("lin12", "rev0.5"):  # 8 kHz: one axis of each joint type
                continue
            eid = ("asymmetric_friction", "spring", "payload_change", "position_ripple")[(ai + ri) % 4]
            out.append(Case(a, DWELL_TRAJECTORIES[(ai + ri) % 2], fs, "sensor", 900 + 10 * ai + ri, (eid,), 0.8, writer=_writer(a, ai + ri)))
    return out


def case_named(name: str, seed: int | None = None) -> Case:
    """The case of :func:`cases` named ``name``, with ``seed`` in place of its own when given (the log of another seed set)."""
    case = next(c for c in cases() if c.name == name)
    return case if seed is None else replace(case, seed=seed)


def beyond_cases() -> list[Case]:
    """Logs beyond the design, to check that its rates do not rest on its own axes, rates and loop (``--beyond``).

    :data:`BEYOND_AXES` (2 and 50 kg linear, 0.002 and 3 kg·m² revolute; PD loops of 6 to 15 Hz) at
    :data:`BEYOND_RATES_HZ`: clean, every axis x rate x dwell trajectory and each axis's chirp and multisine (32 logs);
    every effect each axis can have, once, the rate, trajectory, noise model and size (0.5 or 1 point) rotating (34 logs).
    """
    out: list[Case] = []
    seed = 5000
    for ai, a in enumerate(BEYOND_AXES):
        for ri, fs in enumerate(BEYOND_RATES_HZ):
            for ti, tr in enumerate(DWELL_TRAJECTORIES):
                seed += 1
                out.append(Case(a, tr, fs, NOISE[(ai + ri + ti) % 3], seed, writer=("csv", "library")[(ai + ri + ti) % 2]))
        for ti, tr in enumerate(TRAJECTORIES[2:]):
            seed += 1
            out.append(Case(a, tr, BEYOND_RATES_HZ[(ai + ti) % 3], NOISE[(ai + ti + 1) % 3], seed, writer=_writer(a, ai + ti)))
    for ai, a in enumerate(BEYOND_AXES):
        effects = REVOLUTE_EFFECTS if BEYOND_AXES[a].joint == "revolute" else PRISMATIC_EFFECTS
        for ei, eid in enumerate(effects):
            seed += 1
            k = ai + ei
            out.append(Case(a, TRAJECTORIES[k % 4], BEYOND_RATES_HZ[k % 3], NOISE[k % 3], seed, (eid,), (0.5, 1.0)[k % 2], writer=_writer(a, k)))
    return out


def _writer(axis: str, i: int) -> str:
    if i % 3 == 0:
        return "csv"
    if i % 6 == 1 and ALL_AXES[axis].joint == "prismatic":
        return "ros2"
    return "library"


# ---------------------------------------------------------------------------
# simulation and sizing
# ---------------------------------------------------------------------------
def controller_meta(axis: Axis) -> dict[str, Any]:
    """The metadata the command-line flags ``--controller pd --kp --kv --drive-gain`` give (what a user says)."""
    kp, kv = axis.gains()
    return {"controller": {"kind": "pd", "kp": kp, "kv": kv}, "drive_gain": axis.drive_gain}


def simulate(case: Case, effects: dict[str, dict[str, float]]) -> RunLog:
    """The log of ``case`` with ``effects`` (plant parameters) concealed: ``t, q, tau, q_ref`` as a robot records them."""
    from plant.controllers import PDSettings  # deferred: the plant's compiled loop (numba)
    from plant.replay import simulate_replay

    axis = ALL_AXES[case.axis]
    t, q_ref = reference(axis, case.trajectory, case.fs_hz, case.seed, case.duration_s)
    pos, force = axis.units
    units = {"t": "s", "q": pos, "q_ref": pos, "tau": force}
    ref = RunLog({"t": t, "q_ref": q_ref, "q": q_ref.copy(), "tau": np.zeros_like(t)}, units, {})
    kp, kv = axis.gains()
    spec = {**noise_effects(axis, case.noise), **effects}
    substeps = max(2, int(round(10_000.0 / case.fs_hz)))  # an integration step of 0.1 ms or finer at every rate
    truth = {**axis.truth, "offset": 0.0}
    sim = simulate_replay(ref, truth, spec, controller=PDSettings(kp=kp, kv=kv, gtau=axis.drive_gain), substeps=substeps, seed=case.seed)
    meta = {**controller_meta(axis), "source": f"robot-corpus:{case.name}"}
    return RunLog({n: np.asarray(sim[n]) for n in ("t", "q", "tau", "q_ref")}, units, meta)


def relative_error_pct(log: RunLog) -> float:
    """Relative error (%) of the rigid fit on the rows ``identify --method ls`` keeps, with no drive lag: the design's measure of an
    effect's size, the corpus's own.

    It is ``identify``'s preparation and IDIM-LS's rows as they were when the corpus was sized (b0588dd; bit for bit on 510
    logs compared directly, and the corpus's 189 sizes and base errors all the same through its calibration): the log
    prepared and its samples at rest found as every command's are (:func:`ilic_cli.usable.with_rest`), the rows built from
    every sample and those whose span touches one it may not use left out. Held apart from ``identify`` so that a change to
    how ``identify`` builds its rows is measured on the same logs, not on logs it resized; with no lag, as before ``identify``
    estimated one (:mod:`ilic_cli.drive_lag`), which takes a ``delay`` or a current loop's share of the error and would
    resize every log. A log ``identify`` refuses (too few rows, a glitch, nothing to fit) is refused here alike
    (:class:`ilic_cli.errors.IlicError`).
    """
    from ilic_cli.errors import IdentificationError  # deferred: scipy, as identify
    from ilic_cli.estimators.base import ModelSpec
    from ilic_cli.idim_ls import LSSettings, _too_few_rows, decimated_systems
    from ilic_cli.lsq import solve
    from ilic_cli.prepare import prepare_log
    from ilic_cli.row_spans import valid_rows
    from ilic_cli.usable import identification_hold_s, identification_speed_noise, with_rest

    prepared = prepare_log(log)
    ls = LSSettings().at_rate(prepared.fs_hz)
    prepared = with_rest(prepared, ls)
    if prepared.segments is not None and len(prepared.segments) > 1:
        raise ValueError(f"{prepared.source}: the corpus's logs have no gap")
    model = ModelSpec("rigid-offset", {"delay": 0.0}).regressor(prepared.fs_hz)
    run = prepared.log
    hold, noise = identification_hold_s(prepared), identification_speed_noise(prepared)
    W, y, _, _ = decimated_systems(run.t, run["q"], run["tau"], prepared.fs_hz, model, ls, None, prepared.segments, hold, noise)
    if prepared.valid is not None:  # the rows whose span touches a sample the fit may not use, left out
        rows = valid_rows(np.asarray(prepared.valid, dtype=bool)[ls.trim :], ls.decimation)
        W, y = W[rows], y[rows]
    try:
        _too_few_rows(len(y), model)  # as IDIM-LS refuses them, and identify says so
    except ValueError as exc:
        raise IdentificationError(prepared.source, str(exc)) from None
    return float(solve(W, y, model.names, sigma=ls.sigma).relative_error_pct)


def calibrate(case: Case, eid: str, target: float, base: float) -> tuple[float, float]:
    """Relative size ``s`` (3 significant digits) at which ``eid`` alone changes ``case``'s error by about ``target`` points.

    Bisection on a log scale, stopped within 25 % of the target; ``(s, change)``. The change is not always monotone
    nor continuous in ``s``: a Stribeck peak beyond the drive's reach sticks the axis (rev0.01/s-curve/1000Hz/.../s371:
    0.24 points at ``Fs = 4.8 Fc``, 92 points at ``11.7 Fc``), a flexibility's change turns over. When the bisection
    ends outside :data:`BAND_PTS`, the size tried whose change was inside the band and nearest the target is taken
    (none inside: the bisection's, and the case's ``size_pts`` says so). A size whose log ``identify`` refuses is beyond any
    change (infinite): the loop saturated the drive (``--reseed 9`` s27510, a flexibility behind the 0.5 kg·m² joint at 500 Hz:
    3 rows left once the saturated samples are masked).
    """
    from ilic_cli.errors import IlicError  # deferred as relative_error_pct's imports

    axis = ALL_AXES[case.axis]

    def change(s: float) -> float:
        try:
            return relative_error_pct(simulate(case, {eid: effect_of_size(eid, s, axis, case.variant, case.duration_s)})) - base
        except IlicError:
            return math.inf

    lo, hi = 0.0, SIZE_GUESS[eid]
    c = change(hi)
    tried = [(hi, c)]
    cap = 0.8 if eid == "flexibility" else 64 * SIZE_GUESS[eid]  # a load fraction is below 1
    while c < target and 2.0 * hi <= cap:
        lo, hi = hi, hi * 2.0
        c = change(hi)
        tried.append((hi, c))
    s = hi
    for _ in range(10):
        if abs(c - target) <= 0.25 * target:
            break
        s = math.sqrt(lo * hi) if lo > 0 else 0.5 * hi
        c = change(s)
        tried.append((s, c))
        lo, hi = (s, hi) if c < target else (lo, s)
    s = float(f"{s:.3g}")
    c = change(s)
    inside = [(abs(ci - target), si) for si, ci in tried if BAND_PTS[0] <= ci <= BAND_PTS[1]]
    if not BAND_PTS[0] <= c <= BAND_PTS[1] and inside:
        s = float(f"{min(inside)[1]:.3g}")
        c = change(s)
    return s, c


@dataclass
class Built:
    """A case's log and its truth: the plant parameters of its effects and the measured size (points)."""

    case: Case
    log: RunLog
    effects: dict[str, dict[str, float]]
    size_pts: float
    base_error_pct: float

    def to_dict(self) -> dict[str, Any]:
        return {"case": self.case.name, "effects": self.effects, "size_pts": self.size_pts, "base_error_pct": self.base_error_pct}


def build(case: Case) -> Built:
    """Simulate ``case``: calibrate each effect's size on this log (its clean twin gives the base error), then the log with all."""
    axis = ALL_AXES[case.axis]
    base = relative_error_pct(simulate(case, {}))
    effects: dict[str, dict[str, float]] = {}
    for eid in case.effects:
        s, _ = calibrate(case, eid, case.target_pts, base)
        effects[eid] = effect_of_size(eid, s, axis, case.variant, case.duration_s)
    log = simulate(case, effects)
    size = relative_error_pct(log) - base if effects else 0.0
    return Built(case, log, {k: {n: float(f"{v:.6g}") for n, v in p.items()} for k, p in effects.items()}, round(size, 3), round(base, 3))


# ---------------------------------------------------------------------------
# scoring
# ---------------------------------------------------------------------------
def _compared(eid: str, p: dict[str, float]) -> dict[str, float]:
    """The main parameters of an effect, as compared."""
    if eid == "asymmetric_friction":
        return {"dFv": p["Fv_neg"] - p["Fv_pos"]}
    if eid == "stribeck":
        return {"Fs": p["Fs"], "vs": p["vs"]}
    if eid == "position_ripple":
        return {"A": p["A"], "L": p["L"]}
    if eid == "spring":
        return {"k": p["k"]}
    if eid == "gravity":
        return {"MX": p["MX"], "MY": p["MY"]}
    if eid == "payload_change":
        return {"dM": p["dM"], "t_change": p["t_change"]}
    if eid == "delay":
        return {"lag": max(-p["delay"], 0.0)}
    if eid == "flexibility":
        return {"stiffness": p["stiffness"], "load_fraction": p["load_fraction"]}
    if eid == "friction_drift":
        if p.get("dFv", 0.0) or p.get("dFc", 0.0):
            return {"dFv": p.get("dFv", 0.0), "dFc": p.get("dFc", 0.0), "tau": p["tau"]}
        return {"Fv_rate": p.get("Fv_rate", 0.0), "Fc_rate": p.get("Fc_rate", 0.0)}
    return dict(p)


STATED_AS: dict[str, tuple[str, ...]] = {"lag": ("delay",), "dFv": ("Fv_change",), "dFc": ("Fc_change",), "tau": ("Fv_tau", "Fc_tau")}
"""A compared value's names among a finding's stated parameters, where they differ, the first stated taken (a lag is the negative
``delay``; a drift states each drifting coefficient's change and time constant)."""


def within_stated(truth: dict[str, float], got: dict[str, float], stated: dict[str, dict[str, Any]]) -> bool | None:
    """Whether every compared value beyond :data:`TOLERANCE` lies within what the finding states of it: within 1.96 of its stated
    standard deviation (the 95 % interval), or stated undetermined; ``None`` when one has no stated standard deviation."""
    verdict = True
    for k, v in truth.items():
        if v == 0 or abs(got.get(k, math.nan) - v) <= TOLERANCE * abs(v):
            continue
        st = next((stated[n] for n in STATED_AS.get(k, (k,)) if n in stated), None)
        if st is None:
            return None
        if st.get("determined") is False:
            continue
        std = st.get("std")
        if std is None or not std > 0:
            return None
        verdict = verdict and abs(got.get(k, math.nan) - v) <= Z95 * std
    return verdict


def score(
    built: Built,
    findings: list[tuple[str, dict[str, float] | None]] | list[tuple[str, dict[str, float] | None, str | None]],
    stated: dict[str, dict[str, dict[str, Any]]] | None = None,
) -> dict[str, Any]:
    """Judge a diagnosis of ``built``'s log: ``offset`` is right, a concealed effect named is right, a current-loop-sized
    ``delay`` on a log with that loop is right, anything else is a false alarm; parameter errors of the effects named.
    ``stated``: each finding's parameters as the diagnosis states them (name -> ``std``, ``determined``): for an effect
    beyond :data:`TOLERANCE`, whether it is within what the diagnosis states (:func:`within_stated`, ``parameter_stated``).

    A finding may carry a third element, the effect the diagnosis says it cannot tell it from (``indistinct_from``): when
    either is concealed the verdict is ``indistinct`` (a stated ambiguity: no false alarm, and the concealed one is not
    named exactly: it counts as missed), else a false alarm."""
    case = built.case
    verdicts, errors = [], {}
    honest: dict[str, bool | None] = {}
    ambiguous: set[str] = set()
    for eid, plant, *rest in findings:
        other = rest[0] if rest else None
        if eid == "offset":
            verdicts.append("right")
        elif other is not None and (eid in built.effects or other in built.effects):
            verdicts.append("indistinct")
            ambiguous |= {eid, other}
        elif eid in built.effects:
            verdicts.append("right")
            truth = _compared(eid, built.effects[eid])
            if eid == "delay":
                truth = {"lag": truth["lag"] + case.expected_lag_s()}
            got = _compared(eid, plant) if plant is not None else None
            errors[eid] = math.nan if got is None else max(abs(got.get(k, math.nan) - v) / abs(v) for k, v in truth.items() if v != 0)
            if got is not None and stated is not None and not errors[eid] <= TOLERANCE:
                honest[eid] = within_stated(truth, got, stated.get(eid, {}))
        elif eid == "delay" and case.expected_lag_s() > 0 and plant is not None:
            lag, tau = max(-plant["delay"], 0.0), case.expected_lag_s()
            verdicts.append("right" if abs(lag - tau) <= DELAY_SIZE_TOLERANCE * tau else "false alarm")
        else:
            verdicts.append("false alarm")
    named = {f[0] for f, v in zip(findings, verdicts, strict=True) if v == "right"}
    missed = sorted(set(built.effects) - named)
    false = verdicts.count("false alarm")
    return {
        "verdicts": verdicts,
        "missed": missed,
        "parameter_error": errors,
        "parameter_stated": honest,
        "false_alarms": false,
        "exact": not missed and false == 0,
        "indistinct": sorted(ambiguous & set(built.effects)),
    }


def rigid_errors(found: dict[str, float], axis: Axis) -> dict[str, float]:
    """Relative errors of ``M, Fv, Fc`` against the axis's truth."""
    return {k: found[k] / axis.truth[k] - 1.0 for k in ("M", "Fv", "Fc")}


CI_SLOTS: tuple[tuple[float, str, str], ...] = (
    (250.0, "prismatic", "clean"),
    (250.0, "revolute", "effect"),
    (500.0, "prismatic", "friction_drift"),
    (500.0, "revolute", "clean"),
    (1000.0, "prismatic", "clean"),
    (1000.0, "revolute", "gravity"),
    (2000.0, "prismatic", "spring"),
    (2000.0, "revolute", "clean"),
    (8000.0, "prismatic", "clean"),
    (8000.0, "revolute", "effect"),
)
"""The suite's stratified subset: one log per rate x joint type, clean and with an effect in turn (drift, gravity, a spring;
``effect``: the corpus's one effect case at that edge rate and joint)."""


def ci_subset() -> list[Case]:
    """The first case of :func:`cases` in each slot of :data:`CI_SLOTS` (clean, any single effect, or that effect)."""
    out = []
    for fs, joint, kind in CI_SLOTS:
        fits = [c for c in cases() if c.fs_hz == fs and AXES[c.axis].joint == joint and len(c.effects) <= 1]
        if kind == "clean":
            fits = [c for c in fits if c.clean]
        elif kind == "effect":
            fits = [c for c in fits if not c.clean]
        else:
            fits = [c for c in fits if c.effects == (kind,)]
        out.append(fits[0])
    return out
