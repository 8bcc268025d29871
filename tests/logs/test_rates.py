"""Dwell-and-move logs at 250 Hz to 8 kHz, read back by the CLI as a user's CSV: one preparation, right answers (issue #29).

Each log is the project's plant under the PD loop (``plant.replay.simulate_replay``) following point-to-point moves
with dwells at rest (S-curve moves of a 12 kg linear axis, trapezoidal ones of a 0.08 kg·m² revolute joint, each
about 10 Hz of loop bandwidth), with position noise and encoder quantisation, written by pandas as a robot's CSV
(``time, position, effort, reference``: no units, no metadata) and read back by ``ilic`` with the loop given by
``--controller pd --kp --kv --drive-gain``, as a user would.

Measured (``ilic identify --method ls``, before the rule for samples at rest): Fc -64 %, Fv +40 % on the 2 kHz linear
log; after it, M, Fv and Fc within 1 % of the truth at every rate and on both axes, and ``identify`` and ``diagnose``
fit the same rows.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.diagnosis.core import _prepare, base_model, diagnose
from ilic_cli.diagnosis.decide import below_period
from ilic_cli.diagnosis.select import Step
from ilic_cli.effects import EFFECTS
from ilic_cli.identify import identify
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io import read_log
from ilic_cli.prepare import prepare_log
from ilic_cli.runlog import RunLog
from ilic_cli.usable import REST_RULE, SIGN_RULE, with_rest
from plant.controllers import PDSettings
from plant.replay import simulate_replay
from plant.trajectories import Move, Trajectory
from tests.clirun import run_cli
from tests.conftest import require_shared

RATES_HZ = (250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
BANDWIDTH_HZ = 10.0
"""The PD loop's bandwidth: stable with its one-sample delay down to 250 Hz."""
TOLERANCE = 0.02
"""The issue's: M, Fv and Fc within 2 %."""


@dataclass(frozen=True)
class Axis:
    """An axis, its truth and how it moves: ``moves`` of ``(speed, ramp s, cruise s, dwell s)``."""

    joint: str
    truth: dict[str, float]
    drive_gain: float
    """N/V (N·m/V): the command stays within the drive's +-10 V."""
    moves: tuple[tuple[float, float, float, float], ...]
    shape: str
    noise: float
    resolution: float

    def gains(self) -> tuple[float, float]:
        """``kp, kv`` of a PD loop of :data:`BANDWIDTH_HZ`, damping 0.7: ``gtau kv = 2 xi w M``, ``gtau kv kp = M w^2``."""
        w = 2 * np.pi * BANDWIDTH_HZ
        kv = 2 * 0.7 * w * self.truth["M"] / self.drive_gain
        return self.truth["M"] * w * w / (self.drive_gain * kv), kv


AXES = {
    "linear": Axis(
        "prismatic",
        {"M": 12.0, "Fv": 35.0, "Fc": 4.0, "offset": 0.0},
        10.0,
        ((0.25, 0.12, 0.30, 0.30), (-0.18, 0.09, 0.45, 0.25), (0.20, 0.10, 0.20, 0.35), (-0.24, 0.12, 0.15, 0.30), (0.15, 0.08, 0.50, 0.30)),
        "s-curve",
        5e-7,
        2e-7,
    ),
    "revolute": Axis(
        "revolute",
        {"M": 0.08, "Fv": 0.2, "Fc": 0.3, "offset": 0.0},
        0.5,
        ((2.0, 0.10, 0.35, 0.30), (-1.5, 0.08, 0.50, 0.25), (1.8, 0.09, 0.25, 0.35), (-2.0, 0.10, 0.20, 0.30), (1.2, 0.06, 0.55, 0.30)),
        "trapezoid",
        2e-5,
        1e-5,
    ),
}


def reference(axis: Axis, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """``t, q_ref``: a dwell of 0.3 s, then the axis's moves (each followed by its dwell), sampled at ``fs_hz``."""
    if axis.shape == "trapezoid":
        segments = [(0.3, 0.0)] + [s for v, ta, tc, dwell in axis.moves for s in Move(v, ta, tc, dwell).segments()]
        traj = Trajectory(tuple(segments), q0=0.0, repeat=False)
        n = int(sum(d for d, _ in segments) * fs_hz)
        t, q, _, _ = traj.sample(n, fs_hz)
        return t, q
    # S-curve: each ramp's velocity a raised cosine (continuous acceleration), the position its exact integral
    duration = 0.3 + sum(2 * ta + tc + dwell for _, ta, tc, dwell in axis.moves)
    t = np.arange(int(duration * fs_hz)) / fs_hz
    q = np.zeros_like(t)
    start, here = 0.3, 0.0
    for v, ta, tc, dwell in axis.moves:
        s = np.clip(t - start, 0.0, None)

        def ramp(x: np.ndarray) -> np.ndarray:  # distance covered x into a raised-cosine ramp from 0 to v
            x = np.clip(x, 0.0, ta)
            return 0.5 * v * (x - ta / np.pi * np.sin(np.pi * x / ta))

        up = ramp(s)
        cruise = v * np.clip(s - ta, 0.0, tc)
        down = v * np.clip(s - ta - tc, 0.0, ta) - ramp(s - ta - tc)
        q = q + up + cruise + down
        here += v * (ta + tc)
        start += 2 * ta + tc + dwell
    return t, q


@cache
def csv_log(name: str, fs_hz: float, folder: Path) -> Path:
    """The axis's PD log at ``fs_hz``, written by pandas as a robot's CSV (once per session)."""
    import pandas as pd

    axis = AXES[name]
    t, q_ref = reference(axis, fs_hz)
    position, force = ("m", "N") if axis.joint == "prismatic" else ("rad", "N·m")
    ref = RunLog({"t": t, "q_ref": q_ref, "q": q_ref.copy(), "tau": np.zeros_like(t)}, {"t": "s", "q": position, "q_ref": position, "tau": force}, {})
    kp, kv = axis.gains()
    effects = {"noise": {"q_std": axis.noise}, "quantization": {"resolution": axis.resolution}}
    substeps = max(2, int(round(10_000.0 / fs_hz)))  # an integration step of 0.1 ms or finer at every rate
    sim = simulate_replay(ref, axis.truth, effects, controller=PDSettings(kp=kp, kv=kv, gtau=axis.drive_gain), substeps=substeps, seed=3)
    path = folder / f"{name}-{fs_hz:g}Hz.csv"
    pd.DataFrame({"time": sim.t, "position": sim["q"], "effort": sim["tau"], "reference": sim["q_ref"]}).to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("rates")


def user_options(name: str) -> list[str]:
    """The options a user gives: the loop that ran (its gains and drive gain) and the joint's type."""
    axis = AXES[name]
    kp, kv = axis.gains()
    return ["--controller", "pd", "--kp", repr(kp), "--kv", repr(kv), "--drive-gain", repr(axis.drive_gain), "--load-joint", axis.joint]


def as_read(name: str, path: Path) -> RunLog:
    """The CSV as the CLI reads it with the user's options (the PD loop in its metadata)."""
    axis = AXES[name]
    kp, kv = axis.gains()
    log = read_log(path)
    position, force = ("m", "N") if axis.joint == "prismatic" else ("rad", "N·m")
    units = {**log.units, "q": position, "q_ref": position, "tau": force}
    return RunLog(dict(log.channels), units, {**log.meta, "controller": {"kind": "pd", "kp": kp, "kv": kv}, "drive_gain": axis.drive_gain})


@pytest.mark.parametrize("fs_hz", RATES_HZ, ids=lambda f: f"{f:g}Hz")
@pytest.mark.parametrize("name", list(AXES))
def test_identify_ls_is_right_on_a_dwell_and_move_log_at_every_rate(name: str, fs_hz: float, folder: Path) -> None:
    """``ilic identify --method ls``: M, Fv, Fc within 2 %; the rows at rest are left out and the rule is in the report."""
    path = csv_log(name, fs_hz, folder)
    res = run_cli("identify", str(path), "--method", "ls", *user_options(name), "--format", "json")
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["sample_rate_hz"] == fs_hz
    truth = AXES[name].truth
    errors = {n: doc["ls"]["parameters"][n]["value"] / truth[n] - 1 for n in ("M", "Fv", "Fc")}
    assert all(abs(e) <= TOLERANCE for e in errors.values()), errors
    # no offset in the truth: none within 3 standard deviations (at 8 kHz the decimation's filter, rounded out of its design,
    # passed part of the loop's answer to the sensor noise: 0.091 N·m on the revolute joint, 240 standard deviations)
    offset = doc["ls"]["parameters"]["offset"]
    assert abs(offset["value"]) <= 3 * offset["std"], offset
    rows = doc["usable_rows"]
    assert rows["rule"] == REST_RULE and rows["dwells"] >= len(AXES[name].moves)
    assert rows["rows_at_rest"] > 0 and rows["usable_rows"] == doc["ls"]["rows"] == rows["decimated_rows"] - rows["rows_at_rest"]
    assert rows["regressor_delay_s"] == pytest.approx(0.5 / fs_hz)  # the drive's held command
    assert rows["coulomb_sign"] == SIGN_RULE and rows["sign_speed_noise"] == doc["ls"]["sign_speed_noise"] > 0  # the expected sign


@pytest.mark.parametrize("fs_hz", RATES_HZ, ids=lambda f: f"{f:g}Hz")
@pytest.mark.parametrize("name", list(AXES))
def test_identify_and_diagnose_fit_the_same_rows(name: str, fs_hz: float, folder: Path) -> None:
    """The rows IDIM-LS fits are the rows of the diagnosis's system, row for row (one preparation)."""
    log = as_read(name, csv_log(name, fs_hz, folder))
    report = identify(log, method="ls")
    assert report.ls is not None and report.ls.kept is not None and report.usable is not None
    ls = LSSettings()
    data = _prepare(with_rest(prepare_log(log), ls), base_model(None, "rigid-offset"), ls)
    assert data.rows is not None and np.array_equal(data.rows, report.ls.kept)
    assert data.kin.speed_noise == report.ls.speed_noise > 0  # one Coulomb column (SIGN_RULE)
    assert int(report.ls.kept.sum()) == report.ls.result.rows == report.usable.usable == len(data.y)
    assert data.joint == AXES[name].joint  # the units the diagnosis's reasons write its values in


def test_diagnose_on_the_issues_log_fits_identifys_rows_and_finds_nothing(folder: Path) -> None:
    """The issue's case (a clean 2 kHz point-to-point log): ``diagnose`` fits identify's rows and values, and names nothing.

    Before: identify gave Fc 1.54 N (-61 %) where diagnose fitted 4.06 N on its own rows.
    """
    path = csv_log("linear", 2000.0, folder)
    ident = run_cli("identify", str(path), "--method", "ls", *user_options("linear"), "--format", "json")
    out = folder / "diagnosis"
    diag = run_cli("diagnose", str(path), *user_options("linear")[:-2], "--format", "json", "--out", str(out))  # a prismatic joint: the default
    assert ident.status == 0 and diag.status == 0, ident.stderr + diag.stderr
    i, d = json.loads(ident.stdout), json.loads(diag.stdout)
    assert d["rows_total"] == i["ls"]["rows"] == d["usable_rows"]["usable_rows"] == i["usable_rows"]["usable_rows"]
    assert d["usable_rows"]["rule"] == i["usable_rows"]["rule"] == REST_RULE
    for n in ("M", "Fv", "Fc"):
        assert d["base"]["parameters"][n]["value"] == pytest.approx(i["ls"]["parameters"][n]["value"], rel=1e-9)
    assert {f["effect"] for f in d["findings"]} <= {"offset"}, d["findings"]
    assert f"{d['usable_rows']['rows_at_rest']} at rest left out" in (out / "report.md").read_text()
    sign = f"the Coulomb column erf(v / (√2 σv)), the expected sign of a velocity whose noise σv is {d['usable_rows']['sign_speed_noise']:.3g} m/s"
    assert sign in (out / "report.md").read_text() and d["usable_rows"]["sign_speed_noise"] == i["usable_rows"]["sign_speed_noise"] > 0
    u = i["usable_rows"]
    md = run_cli("identify", str(path), "--method", "ls", *user_options("linear")).stdout  # the text states the rule too
    assert f"{u['usable_rows']} of {u['decimated_rows']} decimated rows fitted: {u['rows_at_rest']} at rest left out ({u['dwells']} dwells: {REST_RULE})" in md
    assert f"the Coulomb column erf(v / (√2 σv)), the expected sign of a velocity whose noise σv is {u['sign_speed_noise']:.3g} m/s over the dwells" in md


def test_a_log_with_dwells_that_does_not_say_how_its_force_is_sampled_is_warned_of(folder: Path) -> None:
    """Without the loop's flags a robot's CSV does not say its force is the drive's held command: fitted at the sample instants,
    the rule and its cost said on stderr and in the JSON's warnings; with them, no word."""
    path = csv_log("revolute", 500.0, folder)
    bare = run_cli("identify", str(path), "--method", "ls", "--format", "json")
    assert bare.status == 0, bare.stderr
    warned = [w for w in json.loads(bare.stdout)["warnings"] if w.startswith("the log does not say how its force samples the drive")]
    assert len(warned) == 1 and f"ilic: warning: {warned[0]}" in bare.stderr.splitlines()
    assert json.loads(bare.stdout)["usable_rows"]["regressor_delay_s"] == 0.0
    flagged = run_cli("identify", str(path), "--method", "ls", *user_options("revolute"), "--format", "json")
    assert flagged.status == 0 and "how its force samples" not in flagged.stderr, flagged.stderr


def test_a_log_without_standstill_keeps_every_row_and_the_published_procedure() -> None:
    """DATA_EMPS.mat: its reversals pass through zero speed in 9 ms (below the 30 ms of a dwell): no row at rest, no hold."""
    emps = require_shared()
    res = run_cli("identify", str(emps / "DATA_EMPS.mat"), "--method", "ls", "--format", "json")
    assert res.status == 0, res.stderr
    doc = json.loads(res.stdout)
    rows = doc["usable_rows"]
    assert rows["rows_at_rest"] == 0 and rows["dwells"] == 0 and rows["regressor_delay_s"] == 0.0
    assert doc["ls"]["rows"] == rows["decimated_rows"] == 2480


CLEAN_DIAGNOSES = [
    ("linear", 250.0),
    ("linear", 500.0),
    ("linear", 1000.0),
    ("linear", 4000.0),
    ("revolute", 250.0),
    ("revolute", 500.0),
    ("revolute", 2000.0),
]
"""Rates diagnosed here beside the 2 kHz linear log (through the CLI above), within the suite's time: every rate but 8 kHz on
one joint or the other (4 kHz 1.9 s of CPU). 8 kHz: the robot corpus's subset (``tests/corpus/test_robot_corpus.py``) diagnoses
a clean linear log and a revolute one with asymmetric friction; the revolute clean log here, measured clean too, 4.2 s."""


@pytest.mark.parametrize(("name", "fs_hz"), CLEAN_DIAGNOSES)
def test_a_clean_log_has_no_timing_finding_at_any_rate(name: str, fs_hz: float, folder: Path) -> None:
    """The half-period hold is the log's own (a PD loop's command, given by its flags), so a clean log has no delay, nor anything else.

    In the issue (an independent simulator's logs) a 2 kHz clean log got a delay of -1.0 us, and a 500 Hz log, whose
    force the diagnosis did not take for the held command (no ``vir`` channel), a delay of -1 ms: the half-period
    hold. Measured here before: the rigid fit of the 500 Hz linear log Fv -8 %, Fc +10 % (now within 1 %). (The 2 kHz
    linear log: above, through the CLI.)
    """
    diag = diagnose(as_read(name, csv_log(name, fs_hz, folder)))
    assert {f.effect.id for f in diag.findings} <= {"offset"}, [(f.effect.id, f.plant_effect) for f in diag.findings]
    assert not any(v.effect == "delay" and v.accepted for v in diag.decisions), diag.decisions
    assert diag.usable is not None and diag.usable.hold_s == pytest.approx(0.5 / fs_hz) and diag.usable.at_rest > 0


def test_a_delay_below_a_tenth_of_the_period_is_not_a_finding() -> None:
    delay = EFFECTS["delay"]
    assert below_period(Step(delay, -1.0e-6), 2000.0) is not None  # the issue's -1.0 us at 2 kHz: 0.2 % of a period
    assert "below 0.1 of the log's sample period (500 us)" in str(below_period(Step(delay, -1.0e-6), 2000.0))
    assert below_period(Step(delay, -0.227e-3), 1000.0) is None  # a 700 Hz current loop's lag at 1 kHz: 23 % of a period
    assert below_period(Step(delay, -20e-6), 8000.0) is None and below_period(Step(delay, -20e-6), 1000.0) is not None
    assert below_period(Step(EFFECTS["spring"], 1e-9), 1000.0) is None


def test_a_threefold_drop_of_the_heldout_error_is_not_rejected() -> None:
    """A spring (0.3 N·m/rad) on the 2 kHz revolute dwell-and-move log: the replay's held-out force error falls threefold and the spring is named.

    Measured: 7.76 % -> 2.46 %, p = 5e-24 (Diebold-Mariano over every held-out decimated sample), k within 0.1 %. The
    issue's case (21.9 % -> 7.5 % rejected at p = 0.011, an independent simulator's log) is not reproduced by this one.
    """
    axis = AXES["revolute"]
    t, q_ref = reference(axis, 2000.0)
    ref = RunLog({"t": t, "q_ref": q_ref, "q": q_ref.copy(), "tau": np.zeros_like(t)}, {"t": "s", "q": "rad", "q_ref": "rad", "tau": "N·m"}, {})
    kp, kv = axis.gains()
    effects = {"noise": {"q_std": axis.noise}, "quantization": {"resolution": axis.resolution}, "spring": {"k": 0.3, "q0": 0.3}}
    sim = simulate_replay(ref, axis.truth, effects, controller=PDSettings(kp=kp, kv=kv, gtau=axis.drive_gain), substeps=5, seed=3)
    meta = {"controller": {"kind": "pd", "kp": kp, "kv": kv}, "drive_gain": axis.drive_gain, "source": "spring"}
    diag = diagnose(RunLog({n: sim[n] for n in ("t", "q", "tau", "q_ref")}, {"t": "s", "q": "rad", "q_ref": "rad", "tau": "N·m"}, meta))
    (verdict,) = [v for v in diag.decisions if v.effect == "spring"]
    assert verdict.accepted and verdict.force_before is not None and verdict.force_after is not None
    assert verdict.force_after < verdict.force_before / 2.5, verdict.reason
    (found,) = [f for f in diag.findings if f.effect.id == "spring"]
    assert found.plant_effect is not None and abs(found.plant_effect["k"] / 0.3 - 1) < 0.15
    assert {f.effect.id for f in diag.findings} <= {"spring", "offset"}


def test_the_report_says_which_estimates_lean_together(folder: Path) -> None:
    """The largest correlation between two estimates, in the JSON and the report: a dwell-and-move log's Fv and Fc lean together more
    (-0.95 here) than DATA_EMPS.mat's, whose moves run at many speeds (-0.90)."""
    path = csv_log("revolute", 500.0, folder)
    res = run_cli("identify", str(path), "--method", "ls", *user_options("revolute"), "--format", "json")
    assert res.status == 0, res.stderr
    pair = json.loads(res.stdout)["ls"]["most_correlated"]
    assert pair["parameters"] == ["Fv", "Fc"] and -0.99 < pair["correlation"] < -0.93, pair
    md = run_cli("identify", str(path), "--method", "ls", *user_options("revolute"))
    assert f"Most correlated estimates: Fv and Fc, r = {pair['correlation']:+.2f}" in md.stdout, md.stdout
    emps = run_cli("identify", str(require_shared() / "DATA_EMPS.mat"), "--method", "ls", "--format", "json")
    assert emps.status == 0, emps.stderr
    other = json.loads(emps.stdout)["ls"]["most_correlated"]
    assert other["parameters"] == ["Fv", "Fc"] and round(other["correlation"], 3) == -0.899 and other["correlation"] > pair["correlation"]


def test_diagnose_and_replay_take_the_joint_s_type_as_identify_does(folder: Path, tmp_path: Path) -> None:
    """``--load-joint`` declares a unit-less CSV's joint in ``diagnose`` and ``replay`` as in ``identify``: its units, and on a revolute
    joint the gravity candidate. Before, ``diagnose`` had no such option: a revolute joint was diagnosed as a prismatic one (m, N,
    gravity never tried) and ``replay`` wrote its log in m and N."""
    from ilic_cli.diagnosis.report import _sensor_words

    path, options = csv_log("revolute", 1000.0, folder), user_options("revolute")
    assert options[-2:] == ["--load-joint", "revolute"]
    declared, as_logged = (run_cli("diagnose", str(path), *o, "--no-simulation", "--format", "json") for o in (options, options[:-2]))
    assert declared.status == as_logged.status == 0, declared.stderr + as_logged.stderr
    d, p = json.loads(declared.stdout), json.loads(as_logged.stdout)
    assert d["joint_type"] == "revolute" and d["units"] == {"M": "kg·m²", "Fv": "N·m·s/rad", "Fc": "N·m", "offset": "N·m"}
    assert p["joint_type"] == "prismatic" and p["units"]["M"] == "kg"
    tried = [{e["effect"] for step in doc["selection"] for e in step} for doc in (d, p)]
    assert "gravity" in tried[0] and "gravity" not in tried[1]
    assert d["base"]["parameters"] == p["base"]["parameters"] and d["rows_total"] == p["rows_total"]  # values unchanged
    # --controller given with --no-simulation still says how the force was sampled: the rows are identify's
    ident = json.loads(run_cli("identify", str(path), "--method", "ls", *options, "--format", "json").stdout)
    assert d["rows_total"] == ident["ls"]["rows"] and d["base"]["parameters"]["Fc"]["value"] == pytest.approx(
        ident["ls"]["parameters"]["Fc"]["value"], rel=1e-9
    )
    assert "white position noise 20 urad, encoder step 10 urad" in _sensor_words({"noise": {"q_std": 2e-5}, "quantization": {"resolution": 1e-5}}, "revolute")
    model = tmp_path / "model.json"
    model.write_text(json.dumps({p: v["value"] for p, v in ident["ls"]["parameters"].items()}))
    replayed = tmp_path / "replayed.csv"
    res = run_cli("replay", str(path), "--model", str(model), *options, "-o", str(replayed))
    assert res.status == 0, res.stderr
    units = read_log(replayed).units
    assert (units["q"], units["tau"], units["qd_plant"]) == ("rad", "N·m", "rad/s")


@pytest.mark.parametrize(
    ("command", "option"), [("identify", ("--load-joint", "revolute")), ("identify", ("--gear-ratio", "10")), ("replay", ("--load-joint", "revolute"))]
)
def test_a_one_joint_declaration_with_an_arm_s_urdf_is_refused(command: str, option: tuple[str, str], tmp_path: Path) -> None:
    """An arm's joints take their types from the URDF: --load-joint or --gear-ratio beside --urdf is refused in one line, not ignored."""
    urdf = Path(__file__).parents[2] / "fixtures" / "arm2.urdf"
    extra = ["--model", str(tmp_path / "model.json"), "-o", str(tmp_path / "out.csv")] if command == "replay" else []
    res = run_cli(command, str(tmp_path / "arm.csv"), "--urdf", str(urdf), *option, *extra)
    assert res.status == 2 and res.stderr.startswith(f"ilic: error: {option[0]}: declares a one-joint log's joint") and res.stderr.count("\n") == 1
