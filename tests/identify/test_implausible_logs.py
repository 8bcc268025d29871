"""Logs no axis could have made are refused in one line, not fitted into nonsense with exit 0: a force logged with the sign opposite
to the position's (a negative mass, :mod:`ilic_cli.plausible`), a position or force that never changes
(:func:`ilic_cli.usable.nothing_to_fit`), a logger's glitch (:func:`ilic_cli.usable.glitch`).

Before: the 0.5 kg·m² joint's trapezoid with its force negated gave ``identify`` M = -0.4999 kg·m², Fv = -0.798, Fc = -1.50, exit 0
and no word; ``diagnose`` said "Undecided" with exit 0. With its position frozen, or its force all zero, ``identify`` printed
M = Fv = Fc = 0 with exit 0, and ``diagnose`` "Undecided" with NumPy's warnings on stderr. One force sample at 1e6 gave
M = -84 kg·m², refused as a force opposing the motion.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ilic_cli.plausible import opposed_force
from tests.clirun import run_cli
from tests.corpus.independent import run_loop
from tests.corpus.robot import AXES, reference


def test_a_determined_negative_mass_is_no_axis_and_an_undetermined_one_is_left_to_its_sigma() -> None:
    names = ("M", "Fv", "Fc", "offset")
    why = opposed_force(names, [-0.5, -0.8, -1.5, 0.0], [0.001, 0.01, 0.01, 0.01], "revolute")
    assert why is not None and "inertia is negative, M = -0.5 ± 0.002 kg·m² (95 %) (Fv and Fc negative too)" in why
    assert "sign opposite" in why
    assert "mass is negative" in (opposed_force(names, [-95.0, 200.0, 20.0, 0.0], [1.0, 1.0, 1.0, 1.0]) or "")  # friction right: no "too"
    assert opposed_force(names, [-0.5, 0.8, 1.5, 0.0], [0.3, 0.01, 0.01, 0.01]) is None  # its 95 % interval holds 0
    assert opposed_force(names, [0.5, -0.8, 1.5, 0.0], [0.001, 0.01, 0.01, 0.01]) is None  # a positive mass
    assert opposed_force(("Fv", "Fc"), [-1.0, -1.0], [0.1, 0.1]) is None  # no mass in the model


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, list[str]]:
    axis = AXES["rev0.5"]
    _, q_ref = reference(axis, "trapezoid", 500.0, 5, 6.0)
    log = run_loop(axis, 500.0, q_ref, "same", {}, 5, "rev0.5")
    frame = pd.DataFrame({k: np.asarray(log[k]) for k in ("t", "q", "q_ref", "tau")})
    folder = tmp_path_factory.mktemp("opposed")
    frame.to_csv(folder / "log.csv", index=False)
    frame.assign(tau=-frame["tau"]).to_csv(folder / "negated.csv", index=False)
    frame.assign(tau=0.0).to_csv(folder / "zero.csv", index=False)
    frame.assign(q=0.1234).to_csv(folder / "frozen.csv", index=False)
    spiked = frame.copy()
    spiked.loc[2000, "tau"] = 1e6
    spiked.to_csv(folder / "spike.csv", index=False)
    kp, kv = axis.gains()
    flags = ["--controller", "pd", "--kp", repr(kp), "--kv", repr(kv), "--drive-gain", repr(axis.drive_gain), "--load-joint", "revolute"]
    return folder / "log.csv", folder / "negated.csv", flags


@pytest.mark.parametrize("command", [("identify", "--method", "ls"), ("diagnose",)])
def test_a_negated_force_is_refused_in_one_line(logs: tuple[Path, Path, list[str]], command: tuple[str, ...]) -> None:
    _, negated, flags = logs
    res = run_cli(command[0], str(negated), *command[1:], *flags)
    assert res.status == 2 and res.stdout == "", res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"ilic: error: {negated}: the force opposes the acceleration"), res.stderr
    assert "M = -0.5" in lines[0] and "(Fv and Fc negative too)" in lines[0]


def test_the_same_log_with_its_force_as_logged_is_identified(logs: tuple[Path, Path, list[str]]) -> None:
    good, _, flags = logs
    res = run_cli("identify", str(good), "--method", "ls", "--format", "json", *flags)
    assert res.status == 0, res.stderr
    values = {k: v["value"] for k, v in json.loads(res.stdout)["ls"]["parameters"].items()}
    assert values["M"] == pytest.approx(0.5, rel=0.01)


@pytest.mark.parametrize("command", [("identify", "--method", "ls"), ("diagnose",)])
@pytest.mark.parametrize(
    ("name", "says"),
    [
        ("zero.csv", "the force is 0 at every sample"),
        ("frozen.csv", "the position is 0.1234 at every sample"),
        ("spike.csv", "the force has 1 sample(s) far outside all the others (1e+06 at t = 4 s"),
    ],
)
def test_a_log_with_nothing_to_fit_or_a_glitch_is_refused(logs: tuple[Path, Path, list[str]], command: tuple[str, ...], name: str, says: str) -> None:
    good, _, flags = logs
    path = good.parent / name
    res = run_cli(command[0], str(path), *command[1:], *flags)
    assert res.status == 2 and res.stdout == "", res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"ilic: error: {path}: {says}"), res.stderr
    assert lines[0].endswith(("nothing to fit", "no model is fitted to it or compared with it; remove it"))


def test_nothing_to_fit_is_said_of_a_constant_channel_only() -> None:
    from ilic_cli.usable import nothing_to_fit

    t = np.linspace(0.0, 1.0, 100)
    assert nothing_to_fit(np.sin(t), np.cos(t)) is None
    assert nothing_to_fit(np.sin(t), np.r_[np.zeros(99), 1e-9]) is None  # a force that changes once still changes
    assert "never moves" in (nothing_to_fit(np.full(100, 2.0), np.cos(t)) or "")
    assert "carries no dynamics" in (nothing_to_fit(np.sin(t), np.full(100, 3.0)) or "")


def test_a_glitch_is_a_sample_ten_band_widths_beyond_the_others() -> None:
    """:func:`ilic_cli.usable.glitch`: a sample beyond the 0.1-99.9 % band by more than ten of its widths; pulses and a force's
    steps, however sharp, are not (the EMPS pulses lie 0.27 widths beyond it)."""
    from ilic_cli.usable import GLITCH_SPANS, glitch

    t = np.arange(5000) / 1000.0
    x = np.sin(2 * np.pi * t)
    assert glitch("the force", x, t) is None
    steps = np.where(t < 2.5, -1.0, 1.0) + np.where((t % 1.0) < 0.002, 0.5, 0.0)  # a step and 2 ms pulses
    assert glitch("the force", steps, t) is None
    y = x.copy()
    y[1234] = 1.0 + 1.01 * GLITCH_SPANS * 2.0  # just beyond ten widths of [-1, 1]
    why = glitch("the force", y, t)
    assert why is not None and "1 sample(s)" in why and "t = 1.234 s" in why
    y[1234] = 1.0 + 0.99 * GLITCH_SPANS * 2.0
    assert glitch("the force", y, t) is None


def test_an_arm_s_joint_whose_friction_would_drive_it_is_named() -> None:
    """:func:`ilic_cli.plausible.driving_friction`: a joint whose Fv and Fc are both negative beyond their 95 % intervals; one of them
    negative, or both within their intervals of 0, is no such joint (a base parameter's sign alone is no rule)."""
    from ilic_cli.plausible import driving_friction

    names = ("Ia_a", "Fv_a", "Fc_a", "Fv_b", "Fc_b")
    std = [0.01] * 5
    assert driving_friction(names, [1.0, 2.0, 3.0, 0.5, 0.7], std, ("a", "b")) is None
    assert driving_friction(names, [1.0, -2.0, 3.0, 0.5, -0.7], std, ("a", "b")) is None  # one negative each: not both
    assert driving_friction(names, [1.0, -0.01, -0.01, 0.5, 0.7], std, ("a", "b")) is None  # within their intervals of 0
    why = driving_friction(names, [1.0, 2.0, 3.0, -0.5, -0.7], std, ("a", "b"))
    assert why is not None and "at joint(s) b (Fv = -0.5, Fc = -0.7)" in why and " a (" not in why
    assert driving_friction(("M", "Fv", "Fc"), [1.0, -1.0, -1.0], [0.1] * 3, ("a",)) is None  # no joint's friction named


def test_replay_refuses_a_glitch_as_the_fits_do(logs: tuple[Path, Path, list[str]], tmp_path: Path) -> None:
    """``replay`` compares the model with the recording: one force sample at 1e6 made that comparison 100 % off whatever the model, with
    exit 0. It is refused in the same line as the fits' (:func:`ilic_cli.usable.refuse_glitches`), and nothing is written; the
    same log without the glitch replays."""
    good, _, flags = logs
    fitted = run_cli("identify", str(good), "--method", "ls", "--out", str(tmp_path / "fit"), *flags)
    assert fitted.status == 0, fitted.stderr
    model = str(tmp_path / "fit" / "model.json")
    spike, out = good.parent / "spike.csv", tmp_path / "replayed.csv"
    for extra in ((), ("--open-loop",)):
        res = run_cli("replay", str(spike), "--model", model, "-o", str(out), *extra, *flags)
        assert res.status == 2 and res.stdout == "" and not out.exists(), res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"ilic: error: {spike}: the force has 1 sample(s) far outside all the others"), res.stderr
    assert run_cli("replay", str(good), "--model", model, "-o", str(out), *flags).status == 0
