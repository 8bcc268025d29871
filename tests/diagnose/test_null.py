"""The replay's Monte-Carlo null (``ilic diagnose --null montecarlo``, :mod:`ilic_cli.diagnosis.null`).

Measured on the corpus (``benchmarks/null_calibration.py``; docs/diagnosis.md
section): the calibration of the p-value on forced spurious candidates, and
the power on concealed effects. Here, small and fast: the p-value's formula
and the refusal of too few replicates, the noise model against a corpus log's
known noise, the replicates' determinism, one forced spurious candidate
rejected and one concealed effect accepted, and the command line.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ilic_cli.diagnosis import DiagnoseSettings, diagnose
from ilic_cli.diagnosis.baseline import hold_s
from ilic_cli.diagnosis.core import _prepare, model_parameters
from ilic_cli.diagnosis.decide import replay_decide
from ilic_cli.diagnosis.null import (
    REPLAY_ALPHA,
    MonteCarloNull,
    NoiseModel,
    NullSettings,
    disturbance_std,
    estimate_noise,
    mc_p_value,
    min_replicates,
    replicate_seed,
    reproposed,
    synthetic_log,
)
from ilic_cli.diagnosis.select import Step, moving_rows, system
from ilic_cli.effects import EFFECTS
from ilic_cli.errors import ParameterError
from ilic_cli.idim_ls import LSSettings
from ilic_cli.io import write_log
from ilic_cli.lsq import lstsq
from ilic_cli.prepare import prepare_log
from ilic_cli.regressor import get_model
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import tau_sensor
from tests.clirun import run_cli
from tests.conftest import import_or_skip

import_or_skip("plant.closed_loop")
from tests.corpus import CASES, build_case  # noqa: E402

LS = LSSettings()
BASE = get_model("rigid-offset")
CLEAN_LOG, CLEAN_EFFECT = "clean-trapezoid-sensor-s1", "spring"
POWER_LOG, POWER_EFFECT = "asymmetric_friction-multisine-disturbance-s201", "asymmetric_friction"


# ---------------------------------------------------------------------------
# the p-value and the number of replicates
# ---------------------------------------------------------------------------
def test_p_value_counts_ties_and_failed_replicates_as_at_least_as_extreme() -> None:
    # 3 >= 2, the tie 2 >= 2 and the NaN (a replicate without a statistic) count; 1 does not
    assert mc_p_value(2.0, np.array([1.0, 3.0, np.nan, 2.0])) == pytest.approx(4 / 5)
    assert mc_p_value(10.0, np.full(19, 0.0)) == pytest.approx(0.05)  # the smallest p with B = 19
    assert mc_p_value(-10.0, np.full(19, 0.0)) == 1.0


def test_too_few_replicates_for_the_level_are_refused() -> None:
    assert min_replicates(0.05) == 19 and min_replicates(0.01) == 99 and min_replicates(0.1) == 9
    NullSettings("montecarlo", 19).check(0.05)
    NullSettings("dm", 1).check(0.01)  # the DM test has no replicates
    with pytest.raises(ParameterError, match="at least 99"):
        NullSettings("montecarlo", 98).check(0.01)
    with pytest.raises(ParameterError, match="at least 19"):
        tiny = RunLog({"t": np.arange(10.0), "q": np.zeros(10), "tau": np.zeros(10)})
        diagnose(tiny, settings=DiagnoseSettings(null=NullSettings("montecarlo", 18, 0, 0.05)))


def test_replicate_seeds_differ_and_repeat() -> None:
    seeds = [replicate_seed(0, b) for b in range(20)]
    assert len(set(seeds)) == 20 and seeds == [replicate_seed(0, b) for b in range(20)] and replicate_seed(1, 1) != seeds[1]


# ---------------------------------------------------------------------------
# the noise model and the replicates, on corpus logs
# ---------------------------------------------------------------------------
class _Prepared:
    """A corpus log prepared as ``diagnose`` prepares it, the rigid model's plant and the hook's preparation."""

    def __init__(self, name: str) -> None:
        self.log = prepare_log(build_case(CASES[name])).log
        self.data = self.prepare(self.log)
        self.rows = moving_rows(self.data)
        self.hold = hold_s(tau_sensor(self.log), self.log.fs_hz)
        W, y, names = system(self.data, BASE, [], self.rows)
        self.rigid, self.effects = self.plant_of([], names, lstsq(W, y)[0])

    @staticmethod
    def prepare(log: RunLog):  # type: ignore[no-untyped-def]
        return _prepare(prepare_log(log), BASE, LS)

    def plant_of(self, steps, names, theta):  # type: ignore[no-untyped-def]
        return model_parameters(steps, names, theta, np.zeros((len(theta), len(theta))), self.hold)

    def forced(self, eid: str, replicates: int, alpha: float, sensor_noise: bool = True):  # type: ignore[no-untyped-def]
        """The replay's verdict on effect ``eid`` forced as the first candidate, under the Monte-Carlo null of ``replicates``."""
        step = reproposed(self.data, BASE, [], Step(EFFECTS[eid]), self.rows)
        null = MonteCarloNull(replicates, 0, LS, self.prepare, sensor_noise) if replicates else None  # 0: the Diebold-Mariano test alone
        _, (v,) = replay_decide(self.log, self.data, BASE, [], [step], self.rows, self.plant_of, alpha=alpha, null=null, sensor_noise=sensor_noise)
        return v


@pytest.fixture(scope="module")
def disturbed() -> _Prepared:
    return _Prepared("clean-multisine-disturbance-s1")


def test_the_noise_model_recovers_the_corpus_noise(disturbed: _Prepared) -> None:
    """Truth: position noise 0.5 um, quantisation 0.2 um, a 1.5 N disturbance at 10 Hz.

    Measured on clean-multisine-disturbance-s1: 0.503 um (0.544 um before the closed-loop
    correction), 0.2 um, 1.42 N at 14.5 Hz. On eight clean logs of seed 1 and 2 (every
    trajectory and noise model): position noise 0.497-0.505 um, disturbance 1.36-1.50 N,
    bandwidth 12-18 Hz. Tolerances: 3 % on the position noise, 10 % on the disturbance's
    std, its bandwidth within 5-20 Hz (the rule is rough: see docs/diagnosis.md).
    """
    noise = estimate_noise(disturbed.log, disturbed.data, disturbed.rows, disturbed.rigid, disturbed.effects, LS)
    assert noise.resolution == pytest.approx(2e-7, rel=1e-6)
    assert noise.q_std == pytest.approx(5e-7, rel=0.03)
    assert noise.disturbance_std == pytest.approx(1.5, rel=0.10)
    assert 5.0 < noise.bandwidth_hz < 20.0
    assert set(noise.effects()) == {"noise", "quantization", "disturbance"}


def test_the_disturbance_is_only_what_the_position_noise_leaves() -> None:
    """The disturbance's std adds to the residual the position noise alone leaves; none when that is all of it."""
    rng = np.random.default_rng(0)
    r_noise, d_unit = rng.standard_normal(50000), 0.5 * rng.standard_normal(50000)
    assert disturbance_std(r_noise + 3.0 * d_unit, r_noise, d_unit) == pytest.approx(3.0, rel=0.02)
    assert disturbance_std(0.9 * r_noise, r_noise, d_unit) == 0.0


def test_a_replicate_is_bit_identical_for_the_same_seed(disturbed: _Prepared) -> None:
    noise = NoiseModel(5e-7, 2e-7, 1.5, 10.0, 0.0)
    a, b = (synthetic_log(disturbed.log, disturbed.rigid, disturbed.effects, noise, replicate_seed(0, 1)) for _ in range(2))
    c = synthetic_log(disturbed.log, disturbed.rigid, disturbed.effects, noise, replicate_seed(0, 2))
    assert set(a.channels) == set(disturbed.log.channels)
    assert all(np.array_equal(a[k], b[k]) for k in a.channels)
    assert not np.array_equal(a["q"], c["q"]) and not np.array_equal(a["tau"], c["tau"])
    assert np.array_equal(a["q_ref"], disturbed.log["q_ref"]) and a.meta["controller"] == disturbed.log.meta["controller"]
    # the recording's metadata, with the replicate's seed
    assert a.meta["source"] == disturbed.log.meta["source"] and a.meta["montecarlo_replicate"]["seed"] == replicate_seed(0, 1)


# ---------------------------------------------------------------------------
# the decision
# ---------------------------------------------------------------------------
def test_a_forced_spurious_candidate_on_a_clean_log_is_not_accepted() -> None:
    """A spring forced on a clean trapezoid log, replayed noise-free: the held-out replay error falls (1.906 % -> 1.878 %),
    and the Diebold-Mariano test calls it significant (p = 2.7e-12), but under the null the same candidate does as well
    on most replicates (T_obs 6.89; replicates 6.85-7.21, median 6.98): Monte-Carlo p = 0.9, rejected.

    (Replayed with the recording's sensor noise, the default, its error rises instead: ``tests/diagnose/test_sensor.py``.)
    """
    p = _Prepared(CLEAN_LOG)
    v = p.forced(CLEAN_EFFECT, 19, 0.05, sensor_noise=False)
    assert v.force_after < v.force_before and v.null is not None  # the error falls: the Monte-Carlo test decides
    assert v.null.dm_p_value < 0.01  # the asymptotic test would have kept it
    assert v.p_value > 0.05 and not v.accepted, v.reason
    assert "Monte-Carlo p" in v.reason and v.to_dict()["test"]["replicates"] == 19
    assert v.to_dict()["test"]["diebold_mariano_p_value"] == v.null.dm_p_value


def test_the_null_runs_only_where_the_diebold_mariano_test_passes() -> None:
    """A drive lag forced on a clean multisine log with a disturbance: the held-out error falls a little (2.926 % -> 2.921 %).

    The Monte-Carlo p alone was 0.05 there (T_obs 1.16; the replicates' statistic median -1.00, largest 0.49: the
    null's disturbance is rougher than the log's), the Diebold-Mariano p 0.12. Both must be significant: rejected,
    and no replicate is simulated. (Replayed noise-free, as measured then: with the recording's sensor noise, the
    default, the error does not fall at all, 3.047 % -> 3.050 %, and nothing would tell the two rules apart.)
    """
    v = _Prepared("clean-multisine-combined-s1").forced("delay", 19, 0.05, sensor_noise=False)
    assert v.force_after < v.force_before and v.null is None
    assert v.p_value is not None and v.p_value > 0.05 and not v.accepted and "not significantly" in v.reason, v.reason
    assert v.to_dict()["test"]["test"].startswith("Diebold-Mariano")


def test_a_concealed_effect_is_accepted() -> None:
    """Dv = 58 N s/m concealed (0.68 points of rigid error): T_obs 12.2, the 19 replicates' largest 0.64 (p = 0.05, the smallest there is).

    Power on the 28 concealed single-effect logs (docs/diagnosis.md): 24 accepted at B = 19.
    """
    p = _Prepared(POWER_LOG)
    v = p.forced(POWER_EFFECT, 19, 0.05)
    assert v.accepted and v.p_value == pytest.approx(0.05), v.reason
    assert v.null is not None and v.null.t_obs > np.nanmax(v.null.t_null)


# ---------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ripple_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tests.diagnose.test_diagnose_effects import simulated_log

    log, _ = simulated_log({"position_ripple": {"A": 1.5, "L": 0.012, "phase": -1.0}}, seed=21, traj_seed=31, duration_s=12.4)
    path = tmp_path_factory.mktemp("logs") / "ripple.csv"
    write_log(log, path)
    return path


def test_cli_montecarlo_names_the_test_and_its_null(ripple_csv: Path) -> None:
    """The Monte-Carlo null through the command line, with the replays noise-free (``--no-replay-noise``: its replicates draw the
    noise model all the same; the replays' sensor noise by default: tests/diagnose/test_diagnose_cli.py)."""
    args = ("diagnose", str(ripple_csv), "--effects", "position_ripple", "--format", "json", "--no-replay-noise")
    r = run_cli(*args, "--null", "montecarlo", "--replicates", "9", "--replay-alpha", "0.1", "--seed", "3")
    assert r.status == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["settings"]["replay_noise"] is False and doc["replay_sensor_noise"] is None
    assert doc["settings"]["replay_test"] == {"null": "montecarlo", "replicates": 9, "seed": 3, "alpha": 0.1}
    (d,) = doc["decisions"]
    assert d["test"]["test"].startswith("Monte-Carlo null") and d["test"]["replicates"] == 9
    null = d["test"]["null_distribution"]
    assert null["replicates"] == 9 and set(null["t_null_quantiles"]) == {"q05", "q25", "q50", "q75", "q95"} and null["t_obs"] > null["t_null_max"]
    assert d["accepted"] and d["test"]["p_value"] == pytest.approx(0.1)
    assert [f["effect"] for f in doc["findings"]] == ["position_ripple"]
    # the default, the Diebold-Mariano test named as such: tests/diagnose/test_diagnose_cli.py's run of the same log


def test_cli_refuses_too_few_replicates(ripple_csv: Path) -> None:
    r = run_cli("diagnose", str(ripple_csv), "--null", "montecarlo", "--replicates", "9")  # the default level, 0.05, needs 19
    assert r.status == 2 and r.stdout == ""
    assert "at least 19" in r.stderr and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    r = run_cli("diagnose", str(ripple_csv), "--null", "montecarlo", "--replicates", "19", "--replay-alpha", "0.01")
    assert r.status == 2 and "at least 99" in r.stderr and r.stdout == ""


def test_the_replay_decides_at_the_usual_level() -> None:
    """Issue 29 item 7, a replay test with the power its data has: a 0.71 ms drive lag on the 0.01 kg·m² joint's 500 Hz
    multisine under the 10 Hz force disturbance (robot corpus, seed 18410) lowers the held-out replay's force error by 2.8 %
    of itself at p = 0.018. At the former level, 0.01, it was rejected ("not significantly"); at 0.05
    (:data:`REPLAY_ALPHA`, planted 0.01: fails) it is kept, and sized within 5 %. The clean logs that keep it honest: 0 of
    480 robot-corpus logs with a finding at either level, and the forced calibration in docs/diagnosis.md."""
    from ilic_cli.diagnosis.core import diagnose
    from tests.corpus.robot import build, case_named

    built = build(case_named("rev0.01/multisine/500Hz/disturbance/delay/s410", 18410))
    diag = diagnose(built.log)
    (verdict,) = [v for v in diag.decisions if v.effect == "delay"]
    assert verdict.p_value is not None and 0.01 < verdict.p_value < REPLAY_ALPHA and verdict.accepted
    assert verdict.force_before is not None and verdict.force_after is not None and verdict.force_after < 0.99 * verdict.force_before
    (finding,) = diag.findings
    assert finding.effect.id == "delay" and finding.plant_effect is not None
    assert finding.plant_effect["delay"] == pytest.approx(built.effects["delay"]["delay"], rel=0.05)
