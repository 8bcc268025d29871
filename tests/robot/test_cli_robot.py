"""Arms of n joints on the command line: simulate robot-sim, identify its log, info, and one-line errors (issue 30, item 7)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import import_or_skip

import_or_skip("pinocchio")

from ilic_cli.cli import main  # noqa: E402

FIXTURES = Path(__file__).parents[2] / "fixtures"
ARM2 = str(FIXTURES / "arm2.urdf")
UR5 = str(FIXTURES / "ur5like.urdf")


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(list(args))
    out, err = capsys.readouterr()
    return int(exc.value.code or 0), out, err


@pytest.fixture(scope="module")
def sims(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    d = tmp_path_factory.mktemp("robot")
    first, second = d / "sim.csv", d / "other.csv"
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--urdf", ARM2, "--scenario", "robot-sim", "--duration", "30", "-o", str(first)])
    assert exc.value.code == 0
    with pytest.raises(SystemExit):
        main(["simulate", "--urdf", ARM2, "--scenario", "robot-sim", "--duration", "20", "--noise-tau", "0.05", "--seed", "2", "-o", str(second)])
    return first, second, ""


def test_simulate_prints_the_convergence_table_and_identify_recovers_the_parameters(capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str]) -> None:
    first, second, _ = sims
    capsys.readouterr()
    code, out, err = run(
        capsys, "identify", str(first), "--urdf", ARM2, "--method", "all", "--validate", str(second), "--max-iterations", "3", "--format", "json"
    )
    assert code == 0, err
    doc = json.loads(out)
    truth = doc["true_base_parameters"]
    assert len(doc["base_parameters"]) == 13 and doc["base_parameters"][0]["combines"] == pytest.approx({"mx_shoulder": 1.0, "m_elbow": 0.5})
    ls = doc["methods"]["IDIM-WLS"]
    for name, p in ls["parameters"].items():
        if p["rel_std_pct"] < 1.0:  # the well-determined ones: within 3 sigma of the truth
            assert abs(p["value"] - truth[name]) < 3 * p["std"], (name, p, truth[name])
    for joint in ("shoulder", "elbow"):
        for f in ("Fv", "Fc"):
            name = f"{f}_{joint}"
            assert abs(ls["friction"][name]["value"] - truth[name]) < 0.03 * abs(truth[name]), name
        assert f"offset_{joint}" in ls["friction"]
    assert 0 < ls["validation"]["relative_error_pct"] < 1.2 * doc["true_validation_relative_error_pct"]  # issue 30: within 1.2x the truth's
    # the essential parameters (%sigma <= 15): the offsets are not; the fit without them is as good
    assert {p for p, v in ls["parameters"].items() if v["rel_std_pct"] <= 15.0} == set(ls["essential"]) and "offset_shoulder" not in ls["essential"]
    assert len(ls["essential"]) < 13 and ls["essential_fit"]["relative_error_pct"] < 1.01 * ls["essential_fit"]["all_relative_error_pct"]
    ilic = doc["methods"]["IDIM-ILIC"]
    assert ilic["essential"] == [n for n, e in ilic["windows"][-1]["essential"].items() if e]
    assert len(ilic["windows"]) == 3 and ilic["window_s"] == 10.0
    for name in ("Ia_shoulderR", "Fv_shoulder", "Fc_shoulder", "mx_elbow", "Fc_elbow"):
        assert abs(ilic["parameters"][name]["value"] - truth[name]) < 0.003 * abs(truth[name]), name
    assert ilic["validation"]["relative_error_pct"] < 5.0
    for method in ("IDIM-IV", "DIDIM"):  # the log's CTC and its windows' models replayed
        m = doc["methods"][method]
        assert m["validation"]["relative_error_pct"] < 1.2 * doc["true_validation_relative_error_pct"] and 2 <= len(m["iterations"]) <= 4, method
        assert abs(m["friction"]["Fv_shoulder"]["value"] - truth["Fv_shoulder"]) < 0.03 * truth["Fv_shoulder"], method


def test_markdown_and_info(capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str]) -> None:
    first, _, _ = sims
    capsys.readouterr()
    code, out, err = run(capsys, "identify", str(first), "--urdf", ARM2, "--method", "ls")
    assert code == 0, err
    assert "## IDIM-WLS" in out and "| mx_shoulderR | mx_shoulder + 0.5 m_elbow |" in out and "## IDIM-ILIC" not in out
    rows = {r.split(" | ")[0][2:]: r.split(" | ") for r in out.splitlines() if r.startswith("| ")}
    assert rows["mx_shoulderR"][5] == "yes" and rows["offset_shoulder"][5] == ""  # the offset's %sigma is above 15: not essential
    assert "Essential (%σ ≤ 15 %, the ones IDIM-ILIC updates): 11 of 13. Fit with only them: relative error" in out
    code, out, err = run(capsys, "info", str(first))
    assert code == 0, err
    assert "| shoulder | revolute |" in out and "| elbow | revolute |" in out and "30000 samples" in out
    code, out, err = run(capsys, "info", str(first), "--urdf", ARM2, "--format", "json")
    doc = json.loads(out)
    assert [j["name"] for j in doc["joints"]] == ["shoulder", "elbow"] and doc["urdf"]["sha256"] and doc["reference"] is True
    assert doc["joints"][0]["q_min"] < doc["joints"][0]["q_max"]


def test_ur5like_to_mcap_and_identify(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_path = tmp_path / "ur5.mcap"
    code, out, err = run(capsys, "simulate", "--urdf", UR5, "--scenario", "robot-sim", "--duration", "10", "-o", str(out_path))
    assert code == 0, err
    assert out_path.is_file() and "| Fv_shoulder_pan_joint |" in out and "k=1" in out and "† not essential in that window (%σ > 15 %)" in out
    rows = [r for r in out.splitlines() if r.startswith("| offset_wrist_3_joint |")]
    assert len(rows) == 1 and rows[0].count("†") >= 1, rows  # the smallest offset is not essential: the controller keeps it
    code, out, err = run(capsys, "identify", str(out_path), "--urdf", UR5, "--method", "ls", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert len(doc["base_parameters"]) == 58 and len(doc["joints"]) == 6
    friction, truth = doc["methods"]["IDIM-WLS"]["friction"], doc["true_base_parameters"]
    for name in (f"{f}_{j['name']}" for j in doc["joints"] for f in ("Fv", "Fc")):
        assert friction[name]["value"] == pytest.approx(truth[name], rel=0.03), name  # issue 30: friction within 3 %
    # an arm's log without --urdf: `info` lists its joints with the types the log declares; a 1-joint command says how to read it
    code, out, err = run(capsys, "info", str(out_path))
    assert code == 0, err
    assert "| elbow_joint | revolute | " in out and "(assumed)" not in out and "10000 samples" in out and "| /joint_states |" in out
    assert "--urdf ARM.urdf" in _error(capsys, "identify", str(out_path), "--method", "ls")
    arm_mat = tmp_path / "ur5.mat"
    assert run(capsys, "convert", str(out_path), str(arm_mat))[0] == 0
    assert "an n-joint log of 6 joints (shoulder_pan_joint," in _error(capsys, "diagnose", str(arm_mat))  # not "missing variable 'qm'"
    # one joint of it through the one-joint chain: in its declared type's units, without the velocity the writer fills with 0
    code, out, err = run(capsys, "info", str(out_path), "--joint", "elbow_joint", "--format", "json")
    units = {c["name"]: c["unit"] for c in json.loads(out)["channels"]}
    assert code == 0 and units["q"] == "rad" and units["tau"] == "N·m" and units["qdd_ref"] == "rad/s^2" and "qd" not in units, (units, err)


def _error(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    code, out, err = run(capsys, *args)
    assert code == 2 and out == "" and err.count("\n") == 1 and err.startswith("ilic: error: ") and "Traceback" not in err, err
    return err


def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str], monkeypatch: pytest.MonkeyPatch) -> None:
    first, _, _ = sims
    assert "none.urdf: no such URDF file" in _error(capsys, "identify", str(first), "--urdf", str(tmp_path / "none.urdf"))
    assert "1 names for the 2 joints" in _error(capsys, "identify", str(first), "--urdf", ARM2, "--joints", "shoulder")
    assert "no joint wrist in the log (it has shoulder, elbow)" in _error(capsys, "identify", str(first), "--urdf", ARM2, "--joints", "shoulder,wrist")
    assert "--method: oe does not run on n joints" in _error(capsys, "identify", str(first), "--urdf", ARM2, "--method", "oe")
    lacking = tmp_path / "lacking.csv"
    lacking.write_text("t,q_shoulder,q_elbow\n" + "".join(f"{k / 1000!r},0.1,0.2\n" for k in range(300)))
    assert "no tau_<joint> column for shoulder, elbow (a log without effort)" in _error(capsys, "identify", str(lacking), "--urdf", ARM2)
    no_ref = tmp_path / "noref.csv"
    rows = np.column_stack([np.arange(300) / 1000, np.zeros((300, 4))])
    no_ref.write_text("t,q_shoulder,q_elbow,tau_shoulder,tau_elbow\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows.tolist()))
    assert "IDIM-ILIC needs the reference" in _error(capsys, "identify", str(no_ref), "--urdf", ARM2, "--method", "ilic")
    assert "needs --urdf" in _error(capsys, "simulate", "--scenario", "robot-sim", "-o", str(tmp_path / "x.csv"))
    assert "exists already" in _error(capsys, "simulate", "--urdf", ARM2, "--scenario", "robot-sim", "-o", str(first))
    monkeypatch.setitem(sys.modules, "pinocchio", None)  # the robot extra not installed
    assert "pinocchio is not installed: pip install 'ilic[robot]'" in _error(capsys, "info", str(first), "--urdf", ARM2)


def test_model_file_round_trip_through_replay_and_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str]) -> None:
    """identify --out writes model.json (URDF path and sha256, base parameters, friction) and a torque plot per joint; replay and simulate read it back."""
    from ilic_cli.io import jointlogs
    from ilic_cli.robot.base import base_parameters
    from ilic_cli.robot.model import load_urdf

    first, _, _ = sims
    out = tmp_path / "out"
    code, _, err = run(capsys, "identify", str(first), "--urdf", ARM2, "--method", "ls", "--out", str(out))
    assert code == 0, err
    model = json.loads((out / "model.json").read_text())
    robot = load_urdf(ARM2)
    base = base_parameters(robot)
    assert model["model"] == "robot" and model["method"] == "IDIM-WLS" and model["robot"]["sha256"] == robot.sha256
    assert list(model["parameters"]) == list(base.names) and model["robot"]["base_parameters"][0]["combines"] == pytest.approx(
        {"mx_shoulder": 1.0, "m_elbow": 0.5}
    )
    assert model["robot"]["friction"]["Fv_elbow"] == model["parameters"]["Fv_elbow"]
    assert all((out / f"torque_{j}.png").stat().st_size > 10_000 for j in robot.joints) and (out / "report.md").is_file()
    # simulate: the arm's plant is the model's (its base parameters exactly)
    sim = tmp_path / "from_model.csv"
    code, _, err = run(capsys, "simulate", "--urdf", ARM2, "--scenario", "robot-sim", "--duration", "10", "--model", str(out / "model.json"), "-o", str(sim))
    assert code == 0, err
    truth = jointlogs.read(sim, list(robot.joints)).provenance.true_parameters
    assert base.values(robot.parameters(truth)) == pytest.approx(list(model["parameters"].values()), rel=1e-12, abs=1e-12)
    # replay: the log's loop with the model's plant gives its torque within 2 % per joint (noise-free log; measured 0.90 and 1.19 %)
    replayed = tmp_path / "replayed.csv"
    code, _, err = run(capsys, "replay", str(first), "--urdf", ARM2, "--model", str(out / "model.json"), "-o", str(replayed))
    assert code == 0, err
    errors = [float(e) for e in err.split("torque error against the recording: ")[1].replace("%", "").replace(",", "").split()[1::2]]
    assert len(errors) == 2 and max(errors) < 2.0, err
    log, again = jointlogs.read(first, list(robot.joints)), jointlogs.read(replayed, list(robot.joints))
    assert again.tau.shape == log.tau.shape and np.array_equal(again.q_ref, log.q_ref)
    # a model made for another URDF (the same arm, one comment more: another sha256) is refused
    other = tmp_path / "arm2_edited.urdf"
    other.write_text(Path(ARM2).read_text() + "<!-- edited -->\n")
    for args in (
        ["replay", str(first), "--urdf", str(other), "-o", str(tmp_path / "x.csv")],
        ["simulate", "--urdf", str(other), "--scenario", "robot-sim", "-o", str(tmp_path / "y.csv")],
    ):
        assert "model.json: made for the URDF" in _error(capsys, *args, "--model", str(out / "model.json"))
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "y.csv").exists()
    assert "not an arm's model file" in _error(capsys, "replay", str(first), "--urdf", ARM2, "--model", str(out / "report.json"), "-o", str(tmp_path / "z.csv"))


def test_a_log_with_a_gap_is_split_by_idim_ls_and_refused_by_a_replay_irregular_stamps_refused_a_jittered_log_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str]
) -> None:
    """IDIM-LS takes the parts between a gap, each filtered on its own (filtered across the gap, mx_shoulderR came out
    +21 % with exit 0); the replays and IDIM-ILIC's windows refuse it in one line; a fixed-rate loop's stamp jitter is
    kept (the same estimates within 0.1 %)."""
    from dataclasses import replace

    from ilic_cli.io import jointlogs

    first, _, _ = sims
    log = jointlogs.read(first)
    keep = np.r_[0:12000, 12200 : len(log.t)]
    gapped = replace(log, t=log.t[keep], q=log.q[:, keep], tau=log.tau[:, keep], **{k: getattr(log, k)[:, keep] for k in ("q_ref", "qd_ref", "qdd_ref")})
    jointlogs.write(gapped, tmp_path / "gap.csv")
    err = _error(capsys, "identify", str(tmp_path / "gap.csv"), "--urdf", ARM2)  # IDIM-WLS and IDIM-ILIC
    assert "1 gap(s), the first of 0.201 s at t = 11.999 s" in err and "one run at a fixed rate" in err
    model = tmp_path / "model"
    assert run(capsys, "identify", str(first), "--urdf", ARM2, "--method", "ls", "--out", str(model))[0] == 0
    whole = json.loads((model / "report.json").read_text())["methods"]["IDIM-WLS"]["parameters"]
    parts = tmp_path / "parts"
    code, out, err = run(capsys, "identify", str(tmp_path / "gap.csv"), "--urdf", ARM2, "--method", "ls", "--out", str(parts), "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["parts"]["count"] == 2 and "2 parts between gaps" in (parts / "report.md").read_text()
    for name, p in doc["methods"]["IDIM-WLS"]["parameters"].items():  # 0.2 s of 30 s left out: the same estimates (measured: 0.006 %)
        assert p["value"] == pytest.approx(whole[name]["value"], rel=1e-3 if p["rel_std_pct"] < 10 else 2e-3), name
    assert all((parts / f"torque_{j}.png").is_file() for j in ("shoulder", "elbow"))
    # the stack is each part's own system, its rows standing for the part's samples, each part's edges at the gap left out (the
    # one-joint chain's rule, idim_ls.part_valid: the filters' transients; a 0.3 s gap cut mid-move in a 20 s log of seed 3 had moved
    # the estimates by up to 1.27 sigma from the whole log's, 0.61 without the edges)
    from ilic_cli.idim_ls import LSSettings, gap_edge, part_valid
    from ilic_cli.robot.base import base_parameters
    from ilic_cli.robot.idim import ROBOT_BAND_HZ, prepare, prepare_parts
    from ilic_cli.robot.model import load_urdf

    robot = load_urdf(ARM2)
    base, ls = base_parameters(robot), LSSettings(band_hz=ROBOT_BAND_HZ)
    q, tau = gapped.q.T, gapped.tau.T
    stack = prepare_parts(q, tau, 1000.0, robot, base, ((0, 12000), (12000, len(q))), ls)
    valid = part_valid(None, len(q) - 12000, True, False, ls.at_rate(1000.0))
    second = prepare(q[12000:], tau[12000:], 1000.0, robot, base, ls, valid=valid)
    assert np.array_equal(stack.W[-len(second.y) :], second.W) and np.array_equal(stack.sample[-len(second.y) :], second.sample + 12000)
    assert ls.at_rate(1000.0).trim <= stack.sample[0] < 12000 and np.all(np.diff(stack.sample[stack.joint == 0]) > 0)
    edge, r = gap_edge(ls.at_rate(1000.0)), ls.at_rate(1000.0).decimation
    assert not np.any((stack.sample > 12000 - edge - r) & (stack.sample < 12000 + edge + r - 1))  # no row's span reaches an edge
    assert len(prepare(q[12000:], tau[12000:], 1000.0, robot, base, ls).y) > len(second.y)
    replay = ("replay", str(tmp_path / "gap.csv"), "--urdf", ARM2, "--model", str(model / "model.json"), "-o", str(tmp_path / "r.csv"))
    assert "1 gap(s)" in _error(capsys, *replay)
    assert not (tmp_path / "r.csv").exists()
    irregular = replace(log, t=np.cumsum(np.random.default_rng(2).uniform(0.2e-3, 1.8e-3, len(log.t))))
    jointlogs.write(irregular, tmp_path / "irregular.csv")
    assert "irregular time stamps" in _error(capsys, "identify", str(tmp_path / "irregular.csv"), "--urdf", ARM2)
    jittered = replace(log, t=log.t + np.random.default_rng(1).normal(0.0, 2e-5, len(log.t)))
    jointlogs.write(jittered, tmp_path / "jitter.csv")
    values = []
    for path in (first, tmp_path / "jitter.csv"):
        code, out, _ = run(capsys, "identify", str(path), "--urdf", ARM2, "--method", "ls", "--format", "json")
        assert code == 0
        values.append({n: p["value"] for n, p in json.loads(out)["methods"]["IDIM-WLS"]["parameters"].items()})
    for name, value in values[0].items():
        if not name.startswith("offset"):
            assert values[1][name] == pytest.approx(value, rel=1e-3), name


def test_one_joint_is_the_case_n_1_of_the_arm_chain(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """axis1 (one prismatic joint, an EMPS-like 95 kg carriage): the URDF, the CTC with online IDIM-ILIC and IDIM-WLS run
    at n = 1 (pinocchio gives a one-joint Jacobian as a vector: it was an internal error). The base parameter of the
    moving mass combines the carriage's mass and the rotor inertia, as the one-joint chain's M."""
    log = tmp_path / "axis1.csv"
    code, out, err = run(capsys, "simulate", "--urdf", str(FIXTURES / "axis1.urdf"), "--scenario", "robot-sim", "--duration", "20", "-o", str(log))
    assert code == 0, err
    code, out, err = run(capsys, "identify", str(log), "--urdf", str(FIXTURES / "axis1.urdf"), "--method", "ls", "--format", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert [b["name"] for b in doc["base_parameters"]] == ["Ia_carriageR", "Fv_carriage", "Fc_carriage", "offset_carriage"]
    assert doc["base_parameters"][0]["combines"] == {"Ia_carriage": 1.0, "m_carriage": 1.0}
    truth, fit = doc["true_base_parameters"], doc["methods"]["IDIM-WLS"]["parameters"]
    assert truth["Ia_carriageR"] == pytest.approx(95.0 + 0.35)  # the scenario's rotor inertia on the one joint
    for name, tol in (("Ia_carriageR", 1e-3), ("Fv_carriage", 0.03), ("Fc_carriage", 0.03)):
        assert fit[name]["value"] == pytest.approx(truth[name], rel=tol), name


def test_an_arm_s_log_no_arm_could_make_is_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], sims: tuple[Path, Path, str]) -> None:
    """The one-joint chain's refusals, joint by joint (:mod:`ilic_cli.plausible`, :func:`ilic_cli.usable.nothing_to_fit`, ``glitch``).
    Before: arm2's log with its torques negated gave every base parameter turned (``Ia_shoulderR`` -1.385, ``Fv_shoulder`` -2.001)
    with exit 0; a torque of zeros at the elbow was fitted with exit 0; a frozen elbow was refused with NumPy's warnings on stderr."""
    from dataclasses import replace

    from ilic_cli.io import jointlogs

    first, _, _ = sims
    log = jointlogs.read(first)
    cases = {
        "negated.csv": (replace(log, tau=-log.tau), "the torque opposes the motion at joint(s) shoulder (Fv = -"),
        "zero.csv": (replace(log, tau=np.vstack([log.tau[0], 0.0 * log.tau[1]])), "joint elbow: the force is 0 at every sample"),
        "frozen.csv": (replace(log, q=np.vstack([log.q[0], np.full_like(log.q[1], 0.3)])), "joint elbow: the position is 0.3 at every sample"),
    }
    spiked = log.tau.copy()
    spiked[0, 5000] = 1e6
    cases["spike.csv"] = (replace(log, tau=spiked), "joint shoulder: the torque has 1 sample(s) far outside all the others (1e+06 at t = 5 s")
    for name, (bad, says) in cases.items():
        jointlogs.write(bad, tmp_path / name)
        assert f"ilic: error: {tmp_path / name}: {says}" in _error(capsys, "identify", str(tmp_path / name), "--urdf", ARM2, "--method", "ls"), name
    # the arm's replay refuses the glitch in the same line (it had reported the comparison as it was, with exit 0); nothing is written
    fitted = tmp_path / "fit"
    code, _, err = run(capsys, "identify", str(first), "--urdf", ARM2, "--method", "ls", "--out", str(fitted))
    assert code == 0, err
    out = tmp_path / "replayed.csv"
    says = cases["spike.csv"][1]
    assert f"ilic: error: {tmp_path / 'spike.csv'}: {says}" in _error(
        capsys, "replay", str(tmp_path / "spike.csv"), "--urdf", ARM2, "--model", str(fitted / "model.json"), "-o", str(out)
    )
    assert not out.exists()
    # with a 0.2 s gap before it, the glitch is placed at its stamp, not at its index over the rate (4.8 s)
    keep = np.r_[0:3000, 3200 : len(log.t)]
    gapped = replace(log, t=log.t[keep], q=log.q[:, keep], tau=spiked[:, keep], **{k: getattr(log, k)[:, keep] for k in ("q_ref", "qd_ref", "qdd_ref")})
    jointlogs.write(gapped, tmp_path / "gap_spike.csv")
    assert "(1e+06 at t = 5 s" in _error(capsys, "identify", str(tmp_path / "gap_spike.csv"), "--urdf", ARM2, "--method", "ls")
