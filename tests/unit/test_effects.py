"""The effect definitions: ranges, values, columns, the fit -> plant mapping and back, words (exact cases)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ilic_cli import effects as fx
from ilic_cli.effects import EFFECTS, Estimate, Fit
from ilic_cli.errors import ParameterError
from ilic_cli.regressor import Kinematics


def test_registry_order_and_kinds() -> None:
    assert list(EFFECTS) == [
        "asymmetric_friction",
        "stribeck",
        "position_ripple",
        "spring",
        "gravity",
        "payload_change",
        "friction_drift",
        "coulomb_smoothing",
        "offset",
        "delay",
        "flexibility",
        "saturation",
        "quantization",
        "noise",
        "disturbance",
        "current_loop",
    ]
    assert fx.catalogue_ids() == ("asymmetric_friction", "stribeck", "position_ripple", "spring", "gravity", "payload_change", "offset", "delay", "flexibility")
    # gravity is proposed on a revolute joint only; friction drift is read from per-window estimates (ilic_cli.diagnosis.drift), no column
    assert "gravity" not in fx.catalogue_ids("prismatic") and "gravity" in fx.catalogue_ids("revolute") and "friction_drift" not in fx.catalogue_ids()
    assert "offset" not in fx.plant_ids() and "noise" in fx.plant_ids()
    assert {"disturbance", "current_loop", "coulomb_smoothing"} <= set(fx.plant_ids())  # plant effects diagnosis does not fit
    assert "coulomb_smoothing" not in fx.catalogue_ids()  # a friction law the diagnosis reads for its replays (ilic_cli.diagnosis.friction_law)
    assert [e for e in EFFECTS if EFFECTS[e].shift] == ["delay"]
    assert [e for e in EFFECTS if EFFECTS[e].nonlinear] == ["stribeck", "position_ripple", "payload_change", "delay", "flexibility"]
    with pytest.raises(ValueError, match="already defined"):
        fx.register(EFFECTS["spring"])
    with pytest.raises(ParameterError) as err:
        fx.get("warp")
    assert err.value.parameter == "effect"


@pytest.mark.parametrize(
    ("eid", "given", "label", "rule"),
    [
        ("stribeck", {"vs": 0.0}, "stribeck.vs", "> 0"),
        ("stribeck", {"vs": -0.01}, "stribeck.vs", "> 0"),
        ("position_ripple", {"L": 0.0}, "position_ripple.L", "> 0"),
        ("payload_change", {"t_change": -1.0}, "payload_change.t_change", ">= 0"),
        ("flexibility", {"stiffness": 0.0}, "flexibility.stiffness", "> 0"),
        ("flexibility", {"damping": -1.0}, "flexibility.damping", ">= 0"),
        ("flexibility", {"load_fraction": 1.0}, "flexibility.load_fraction", "in (0, 1)"),
        ("flexibility", {"load_fraction": 0.0}, "flexibility.load_fraction", "in (0, 1)"),
        ("delay", {"delay": 1.5}, "delay.delay", "within +-1 s"),
        ("delay", {"delay": -1.5}, "delay.delay", "within +-1 s"),
        ("saturation", {"force_max": 0.0}, "saturation.force_max", "> 0"),
        ("quantization", {"resolution": -1e-7}, "quantization.resolution", "> 0"),
        ("noise", {"tau_std": -0.1}, "noise.tau_std", ">= 0"),
        ("asymmetric_friction", {"Fc_neg": -0.5}, "asymmetric_friction.Fc_neg", ">= 0"),
        ("spring", {"k": math.nan}, "spring.k", "finite"),
        ("spring", {"stiffness": 1.0}, "spring.stiffness", "a parameter of 'spring' (k, q0)"),
        ("spring", {"k": "stiff"}, "spring.k", "a number"),
    ],
)
def test_values_break_their_rule(eid: str, given: dict, label: str, rule: str) -> None:
    with pytest.raises(ParameterError) as err:
        EFFECTS[eid].values(given)
    assert (err.value.parameter, err.value.rule) == (label, rule)


def test_values_accept_the_boundaries_and_fill_defaults() -> None:
    assert EFFECTS["delay"].values({"delay": -1.0}) == {"delay": -1.0}
    assert EFFECTS["payload_change"].values({"t_change": 0.0}) == {"dM": 10.0, "t_change": 0.0}
    assert EFFECTS["stribeck"].values({"Fs": -4.0}) == {"Fs": -4.0, "vs": 0.01}  # a negative level is a shape correction
    assert EFFECTS["noise"].values() == {"tau_std": 0.0, "q_std": 0.0}
    assert EFFECTS["flexibility"].values({"damping": 0.0})["damping"] == 0.0


def test_make_effects_and_its_json() -> None:
    eff = fx.make_effects({"spring": {"k": 3.0}, "noise": True, "delay": None, "stribeck": False})
    assert list(eff) == ["spring", "noise"] and eff["spring"].to_dict() == {"k": 3.0, "q0": 0.1}
    assert eff["spring"].vector().tolist() == [3.0, 0.1] and eff["spring"]["k"] == 3.0 and eff["spring"].id == "spring"
    assert fx.make_effects({"spring": eff["spring"]})["spring"] is eff["spring"]
    assert list(fx.effects_to_dict({"noise": eff["noise"], "spring": eff["spring"]})) == ["spring", "noise"]  # registry order
    with pytest.raises(ParameterError, match="a plant effect"):
        fx.make_effects({"offset": {}})
    with pytest.raises(ParameterError, match="an object of parameter -> value"):
        fx.make_effects({"spring": [1, 2]})


def test_force_terms() -> None:
    """The plant force of an effect is its columns times the coefficients of its linear form."""
    q = np.array([0.0, 0.0025, 0.005])
    qd = np.array([-0.02, 0.0, 0.01])
    kin = Kinematics(qd=qd, qdd=np.zeros(3), q=q, t=np.zeros(3))
    np.testing.assert_allclose(EFFECTS["stribeck"].plant_force({"Fs": 5.0, "vs": 0.01}, kin), [-5.0 * math.exp(-4.0), 0.0, 5.0 * math.exp(-1.0)], rtol=1e-15)
    np.testing.assert_allclose(EFFECTS["position_ripple"].plant_force({"A": 2.0, "L": 0.01, "phase": 0.0}, kin), [0.0, 2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(EFFECTS["spring"].plant_force({"k": 100.0, "q0": 0.0025}, kin), [-0.25, 0.0, 0.25], rtol=1e-15)


def test_columns() -> None:
    qd = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
    kin = Kinematics(qd=qd, qdd=np.array([1.0, 2.0, 3.0, 4.0, 5.0]), q=np.array([0.0, 0.25, 0.5, 0.75, 1.0]), t=np.arange(5.0))
    np.testing.assert_array_equal(EFFECTS["asymmetric_friction"].matrix(kin)[:, 0], [-2.0, -1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(EFFECTS["stribeck"].matrix(kin, 1.0)[:, 0], np.sign(qd) * np.exp(-(qd**2)), rtol=1e-15)
    ripple = EFFECTS["position_ripple"].matrix(kin, 1.0)
    np.testing.assert_allclose(ripple, np.c_[np.sin(2 * np.pi * kin.q), np.cos(2 * np.pi * kin.q)], atol=1e-15)
    np.testing.assert_array_equal(EFFECTS["spring"].matrix(kin)[:, 0], kin.q)
    np.testing.assert_array_equal(EFFECTS["payload_change"].matrix(kin, 2.0)[:, 0], [0.0, 0.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(EFFECTS["offset"].matrix(kin)[:, 0], np.ones(5))
    assert EFFECTS["delay"].matrix(kin, 0.001).shape == (5, 0)
    cols = EFFECTS["position_ripple"].regressor_columns(1.0)
    assert [c.name for c in cols] == ["ripple_sin", "ripple_cos"] and [c.unit for c in cols] == ["N", "N"]
    np.testing.assert_allclose(cols[1].build(kin), ripple[:, 1])
    assert fx.unit_of("dFv_neg") == "N·s/m" and fx.unit_of("M_load") == "kg" and fx.unit_of("Fv") == "N·s/m" and fx.unit_of("nothing") == ""


def test_applicable() -> None:
    assert fx.applicable(EFFECTS["asymmetric_friction"], ("M", "Fv", "Fc"))
    assert not fx.applicable(EFFECTS["asymmetric_friction"], ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"))
    assert not fx.applicable(EFFECTS["offset"], ("M", "Fv", "Fc", "offset"))
    assert fx.applicable(EFFECTS["offset"], ("M", "Fv", "Fc"))


def _fit(values: dict[str, float], value: object = None, value_std: float | None = None, hold_s: float = 0.0, std: float = 0.0) -> Fit:
    names = tuple(values)
    return Fit(names, np.array(list(values.values())), np.eye(len(names)) * std**2, value, value_std, hold_s)


def test_fit_combination_and_lookup() -> None:
    fit = Fit(("a", "b"), np.array([2.0, 3.0]), np.array([[4.0, 1.0], [1.0, 9.0]]))
    assert fit.combination({"a": 1.0, "b": -1.0}) == (-1.0, math.sqrt(4.0 + 9.0 - 2.0))
    assert fit.get("b") == 3.0 and fit.get("c", 7.0) == 7.0 and fit.has("a") and not fit.has("c")


def test_asymmetric_friction_to_plant() -> None:
    est, plant, note = EFFECTS["asymmetric_friction"].fit_to_plant(_fit({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0, "dFv_neg": 15.0}))
    assert plant == {"Fv_pos": 200.0, "Fv_neg": 215.0, "Fc_pos": 20.0, "Fc_neg": 20.0}
    assert (est["Fc_pos"].value, est["Fc_neg"].value) == (17.0, 23.0) and "cannot be told apart" in note
    est, plant, note = EFFECTS["asymmetric_friction"].fit_to_plant(_fit({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "dFv_neg": -15.0}))
    assert plant == {"Fv_pos": 200.0, "Fv_neg": 185.0, "Fc_pos": 20.0, "Fc_neg": 20.0} and "Fc_pos" not in est and note == ""


def test_stribeck_to_plant() -> None:
    effect = EFFECTS["stribeck"]
    _, plant, note = effect.fit_to_plant(_fit({"Fc": 20.0, "Fs": 3.0}, value=0.02))
    assert plant == {"Fs": 3.0, "vs": 0.02} and note == ""
    _, plant, note = effect.fit_to_plant(_fit({"Fc": 20.0, "Fs": -6.0}, value=0.02))
    assert plant == {"Fs": -6.0, "vs": 0.02} and "14 N" in note
    _, plant, note = effect.fit_to_plant(_fit({"Fc": 5.0, "Fs": -6.0}, value=0.02))
    assert plant is None and "below 0" in note
    _, plant, _ = effect.fit_to_plant(_fit({"Fc_pos": 4.0, "Fc_neg": 9.0, "Fs": -5.0}, value=0.02))
    assert plant is None  # the lower side decides
    assert (
        effect.describe({"Fs": Estimate(3.0, None, "N"), "vs": Estimate(0.02, None, "m/s")}) == "Stribeck friction (extra friction Fs = 3 N below vs = 20 mm/s)"
    )


def test_ripple_spring_payload_delay_to_plant() -> None:
    est, plant, _ = EFFECTS["position_ripple"].fit_to_plant(_fit({"ripple_sin": 3.0, "ripple_cos": 4.0}, value=0.01, std=0.1))
    assert plant == {"A": 5.0, "L": 0.01, "phase": math.atan2(4.0, 3.0)}
    assert est["A"].std == pytest.approx(0.1) and est["phase"].std == pytest.approx(0.1 / 5.0)
    _, plant, note = EFFECTS["spring"].fit_to_plant(_fit({"offset": 1.0, "k_spring": 12.0}))
    assert plant == {"k": 12.0, "q0": 0.0} and "absorbed by the offset" in note
    est, plant, _ = EFFECTS["payload_change"].fit_to_plant(_fit({"dM": 0.8}, value=11.7, value_std=0.2))
    assert plant == {"dM": 0.8, "t_change": 11.7} and est["t_change"].std == 0.2 and est["t_change"].unit == "s"
    _, plant, note = EFFECTS["delay"].fit_to_plant(_fit({}, value=-0.0006, hold_s=0.0005))
    assert plant == {"delay": -0.0006} and "beyond its 0.5 ms zero-order hold" in note and "drive lag" in note
    _, plant, note = EFFECTS["delay"].fit_to_plant(_fit({}, value=0.002))
    assert plant == {"delay": 0.002} and note == ""
    _, plant, _ = EFFECTS["offset"].fit_to_plant(_fit({"offset": -3.0}))
    assert plant is None


def test_flexibility_to_plant_and_back() -> None:
    effect = EFFECTS["flexibility"]
    M, frac, f_res, zeta = 95.0, 0.3, 30.0, 0.05
    est, plant, _ = effect.fit_to_plant(_fit({"M": M, "M_load": frac * M}, value=(f_res, zeta)))
    k = (2 * math.pi * f_res) ** 2 * frac * M
    assert plant == pytest.approx({"stiffness": k, "damping": 2 * zeta * math.sqrt(k * frac * M), "load_fraction": frac})
    back = effect.value_from_plant(effect.values(plant), M)
    assert back == pytest.approx((f_res, zeta))
    _, plant, note = effect.fit_to_plant(_fit({"M": M, "M_load": -1.0}, value=f_res))
    assert plant is None and "outside (0, 1)" in note
    assert effect.impossible is not None and effect.impossible(np.array([1.0]), f_res, "prismatic") is None
    assert effect.impossible(np.array([-1.0]), f_res, "prismatic") == "negative mass behind the flexibility (-1 kg)"
    assert effect.impossible(np.array([-1.0]), f_res, "revolute") == "negative mass behind the flexibility (-1 kg·m²)"


def test_value_from_plant_of_the_scanned_effects() -> None:
    assert EFFECTS["stribeck"].value_from_plant({"Fs": 1.0, "vs": 0.03}, 95.0) == 0.03
    assert EFFECTS["position_ripple"].value_from_plant({"A": 1.0, "L": 0.004, "phase": 0.0}, 95.0) == 0.004
    assert EFFECTS["delay"].value_from_plant({"delay": -0.001}, 95.0) == -0.001
    assert EFFECTS["spring"].value_from_plant({"k": 1.0, "q0": 0.0}, 95.0) is None


def test_definitions_match_the_reviewed_catalogue() -> None:
    """Every built-in definition as reviewed (fixtures/effects.json): words, units, ranges, defaults, search settings."""
    import json
    from pathlib import Path

    doc = json.loads((Path(__file__).resolve().parents[2] / "fixtures" / "effects.json").read_text())["effects"]
    builtin = {eid: e for eid, e in EFFECTS.items() if eid in doc}
    assert list(builtin) == list(doc)
    for eid, e in builtin.items():
        want = doc[eid]
        assert (e.title, e.explanation, e.form, e.signature, list(e.signature_kinds)) == (
            want["title"],
            want["explanation"],
            want["form"],
            want["signature"],
            want["signature_kinds"],
        ), eid
        got_params = {
            p.name: {
                "unit": p.unit,
                "default": p.default,
                "meaning": p.meaning,
                "low": None if p.low == -math.inf else p.low,
                "high": None if p.high == math.inf else p.high,
                "low_open": p.low_open,
            }
            for p in e.params
        }
        assert got_params == want["parameters"], eid
        assert [{"name": c.name, "unit": c.unit, "description": c.description} for c in e.columns] == want["columns"], eid
        scan = (
            None
            if e.scan is None
            else {"name": e.scan.name, "unit": e.scan.unit, "log": e.scan.log, "secondary": list(e.scan.secondary) if e.scan.secondary else None}
        )
        assert scan == want["scan"] and e.shift == want["shift"] and e.plant == want["plant"], eid
        d = e.to_dict()
        assert d["id"] == eid and d["title"] == e.title and d["parameters"] == want["columns"]
        assert d["nonlinear"] == (None if e.scan is None else {"name": e.scan.name, "unit": e.scan.unit})


def test_grids_follow_the_data() -> None:
    """Search grids from the data's own ranges, as documented."""
    n = 2001
    t = np.arange(n) / 1000.0
    qd = 0.2 * np.sin(2 * np.pi * t)
    q = 0.1 + 0.2 / (2 * np.pi) * (1 - np.cos(2 * np.pi * t))
    kin = Kinematics(qd=qd, qdd=np.gradient(qd, t), q=q, t=t)
    vmax = float(np.percentile(np.abs(qd), 99.5))
    np.testing.assert_allclose(EFFECTS["stribeck"].scan.grid(kin, 1000.0), np.geomspace(0.01 * vmax, 0.4 * vmax, 32), rtol=1e-15)
    change = EFFECTS["payload_change"].scan.grid(kin, 1000.0)
    assert len(change) == 200 and change[0] == pytest.approx(0.05 * 2.0) and change[-1] == pytest.approx(2.0 - 0.05 * 2.0)
    delay = EFFECTS["delay"].scan.grid(kin, 1000.0)
    assert delay[0] == -0.025 and delay[-1] == pytest.approx(0.025) and np.allclose(np.diff(delay), 0.0005)
    resonance = EFFECTS["flexibility"].scan.grid(kin, 1000.0)
    assert len(resonance) == 40 and resonance[0] == 2.0 and resonance[-1] == pytest.approx(40.0)
    ripple = EFFECTS["position_ripple"].scan.grid(kin, 1000.0)
    stroke = float(np.ptp(q))
    moving = np.abs(qd) > 0.05 * vmax
    assert ripple[0] == pytest.approx(max(float(np.median(np.abs(qd[moving]))) / 40.0, stroke / 2000.0))
    assert ripple[-2] < stroke <= ripple[-1]  # one cycle over the range visited, the longest period the log shows whole
    # the phase over the stroke moves by a tenth of a cycle per step
    np.testing.assert_allclose(stroke / ripple[:-1] - stroke / ripple[1:], 0.1, rtol=1e-9)
    still = Kinematics(qd=np.zeros(10), qdd=np.zeros(10), q=np.zeros(10), t=np.arange(10.0))
    np.testing.assert_allclose(EFFECTS["stribeck"].scan.grid(still, 1000.0), np.geomspace(0.01, 0.4, 32))  # no motion: a unit speed
    assert EFFECTS["position_ripple"].scan.grid(Kinematics(qd=np.ones(10), qdd=np.zeros(10), q=None), 10.0)[0] > 0


def test_record_defaults() -> None:
    p = fx.PlantParam("x", "u", 1.0)
    assert (p.meaning, p.low, p.high, p.low_open) == ("", -math.inf, math.inf, False)
    p.check("e", -1e300)
    p.check("e", 1e300)
    fx.PlantParam("x", "u", 1.0, low=0.0).check("e", 0.0)
    with pytest.raises(ParameterError, match=r"<= 2"):
        fx.PlantParam("x", "u", 1.0, high=2.0).check("e", 2.5)
    fx.PlantParam("x", "u", 1.0, high=2.0).check("e", 2.0)
    assert fx.Scan("s", "u", lambda k, f: np.ones(1)).log is True and fx.Scan("s", "u", lambda k, f: np.ones(1)).secondary is None
    fit = Fit(("a",), np.array([1.0]), np.eye(1))
    assert (fit.value, fit.value_std, fit.hold_s) == (None, None, 0.0) and fit.get("b") == 0.0
    assert Estimate(1.0, None).to_dict() == {"value": 1.0, "std": None, "unit": "", "determined": True}
    assert Estimate(math.inf, 2.0, "N").to_dict() == {"value": None, "std": 2.0, "unit": "N", "determined": False}
    assert (fx.EffectColumn("c", "N").description, fx.EffectColumn("c", "N").of) == ("", None)
    e = fx.Effect("x", "t", "e.")
    assert (e.coefficients, e.replaces, e.strategy, e.linear_form({})) == (None, (), None, None)
    assert (e.params, e.plant, e.check, e.form, e.signature, e.signature_kinds, e.columns, e.build, e.scan, e.shift) == (
        (),
        True,
        None,
        "",
        "",
        (),
        (),
        None,
        None,
        False,
    )
    assert e.matrix(Kinematics(qd=np.zeros(3), qdd=np.zeros(3))).shape == (3, 0) and not e.identifiable and not e.nonlinear
    assert e.describe({"a": Estimate(1.5, None)}) == "t (a = 1.5)"
    assert fx.EffectParams(EFFECTS["spring"]).params == {}
    import dataclasses

    for record in (p, fit, Estimate(1.0, None), fx.EffectColumn("c", "N"), e, EFFECTS["stribeck"].scan):
        with pytest.raises(dataclasses.FrozenInstanceError):
            record.unit = "x"  # type: ignore[misc,union-attr]


def test_flexibility_columns_use_the_sample_rate() -> None:
    t = np.arange(400) / 1000.0
    qdd = np.sin(2 * np.pi * 5 * t)
    kin = Kinematics(qd=np.zeros(400), qdd=qdd, q=np.zeros(400), t=t)
    flex = EFFECTS["flexibility"]
    at_1k = flex.matrix(kin, (20.0, 0.1), 1000.0)
    np.testing.assert_array_equal(flex.matrix(kin, (20.0, 0.1)), at_1k)  # 1 kHz by default
    assert not np.allclose(flex.matrix(kin, (20.0, 0.1), 500.0), at_1k)
    np.testing.assert_allclose(flex.matrix(kin, 20.0, 1000.0), flex.matrix(kin, (20.0, fx.FLEX_DAMPING), 1000.0))
    # a slow motion moves the load with the motor: the column (load minus motor acceleration) is small
    assert np.abs(at_1k[200:]).max() < 0.2 * np.abs(qdd).max()


def test_flexible_acceleration_is_the_loads_response() -> None:
    """Steady state of a sinusoid: the load's acceleration is H(j w) times the motor's, H = (2 z w0 s + w0^2)/(s^2 + 2 z w0 s + w0^2)."""
    fs, f0, zeta, f = 1000.0, 30.0, 0.1, 20.0
    t = np.arange(20000) / fs
    x = np.sin(2 * np.pi * f * t)
    y = fx.flexible_acceleration(x, f0, fs, zeta)
    s, w0 = 2j * np.pi * f, 2 * np.pi * f0
    H = (2 * zeta * w0 * s + w0**2) / (s**2 + 2 * zeta * w0 * s + w0**2)
    tail = slice(10000, None)
    z = np.exp(1j * 2 * np.pi * f * t[tail])
    fitted = np.linalg.lstsq(np.c_[z.real, z.imag], y[tail], rcond=None)[0]  # y = Re(c z): c = a - j b
    assert abs(complex(fitted[0], -fitted[1]) / (-1j) - H) < 5e-3 * abs(H)  # sin = Re(-j z); the bilinear transform warps a little near f0
    assert fx.flexible_acceleration(np.full(50, 2.0), f0, fs, zeta) == pytest.approx(np.full(50, 2.0))  # starts in the steady state


def test_estimate_keys_units_and_boundaries() -> None:
    est, _, _ = EFFECTS["asymmetric_friction"].fit_to_plant(_fit({"Fv": 200.0, "Fc": 20.0, "offset": 1.0, "dFv_neg": 5.0}))
    assert {k: v.unit for k, v in est.items()} == {"Fv_pos": "N·s/m", "Fv_neg": "N·s/m", "Fc_pos": "N", "Fc_neg": "N"}
    _, plant, _ = EFFECTS["asymmetric_friction"].fit_to_plant(_fit({"Fv": 200.0, "dFv_neg": 5.0}))
    assert plant == {"Fv_pos": 200.0, "Fv_neg": 205.0, "Fc_pos": 0.0, "Fc_neg": 0.0}  # no Coulomb column: none
    est, plant, note = EFFECTS["stribeck"].fit_to_plant(_fit({"Fc": 20.0, "Fs": -20.0}, value=0.02, value_std=0.001))
    assert plant == {"Fs": -20.0, "vs": 0.02} and "static friction level Fc + Fs is 0 N" in note  # the level may reach 0
    assert {k: (v.unit, v.std) for k, v in est.items()} == {"Fs": ("N", 0.0), "vs": ("m/s", 0.001)}
    _, plant, note = EFFECTS["stribeck"].fit_to_plant(_fit({"Fc": 20.0, "Fs": 0.0}, value=0.02))
    assert plant == {"Fs": 0.0, "vs": 0.02} and note == ""
    _, _, note = EFFECTS["stribeck"].fit_to_plant(_fit({"Fc": 0.5, "Fs": -0.75}, value=0.02))
    assert note == "Fs = -0.75 N would put the static friction level Fc + Fs below 0: not in the model file"
    words = EFFECTS["stribeck"].describe({"Fs": Estimate(-2.0, None, "N"), "vs": Estimate(0.005, None, "m/s")})
    assert words.startswith("Stribeck friction (extra friction Fs = -2 N below vs = 5 mm/s; negative: friction is lower at low speed")
    assert EFFECTS["spring"].describe({"k": Estimate(12.0, None, "N/m")}) == "spring force (stiffness 12 N/m)"
    assert fx.Effect("x", "thing", "e.").describe({"a": Estimate(1.0, None), "b": Estimate(2.0, None)}) == "thing (a = 1, b = 2)"
    est, plant, _ = EFFECTS["position_ripple"].fit_to_plant(_fit({"ripple_sin": 0.0, "ripple_cos": 0.0}, value=0.01, std=1.0))
    assert plant["A"] == 0.0 and est["A"].std == 0.0 and est["phase"].std == 0.0 and {k: v.unit for k, v in est.items()} == {"A": "N", "L": "m", "phase": "rad"}
    est, _, _ = EFFECTS["flexibility"].fit_to_plant(_fit({"M": 100.0, "M_load": 20.0}, value=(10.0, 0.1), value_std=0.5, std=2.0))
    k = (2 * math.pi * 10.0) ** 2 * 20.0
    assert est["stiffness"].std == pytest.approx(k * math.sqrt((2 * 0.5 / 10.0) ** 2 + (2.0 / 20.0) ** 2))
    assert est["load_fraction"].value == 0.2 and est["load_fraction"].std == pytest.approx(0.02)


def test_words_of_the_errors() -> None:
    with pytest.raises(ValueError, match=r"^effect 'spring' is already defined$"):
        fx.register(EFFECTS["spring"])
    bad = fx.Effect("twin", "t", "e.", columns=(fx.EffectColumn("a", ""), fx.EffectColumn("a", "")))
    with pytest.raises(ValueError, match=r"^effect 'twin': column names repeat$"):
        fx.register(bad)
    with pytest.raises(ParameterError) as err:
        fx.get("warp")
    assert err.value.rule == f"one of {', '.join(fx.plant_ids())}"
    with pytest.raises(ParameterError) as err:
        fx.make_effects({"offset": {}})
    assert (err.value.parameter, err.value.rule) == ("effect", f"a plant effect ({', '.join(fx.plant_ids())})")
    with pytest.raises(ParameterError) as err:
        fx.make_effects({"spring": 3})
    assert (err.value.parameter, err.value.rule) == ("spring", "an object of parameter -> value")
    with pytest.raises(ParameterError) as err:
        fx.Effect("bare", "t", "e.").values({"a": 1})
    assert err.value.rule == "a parameter of 'bare' (none)"
    with pytest.raises(ParameterError) as err:
        fx.PlantParam("x", "u", 1.0, high=2.0).check("e", 3.0)
    assert err.value.rule == "<= 2"


def test_grids_without_positions_or_times() -> None:
    qd = 0.2 * np.sin(np.linspace(0, 6 * np.pi, 3000))
    with_q = Kinematics(qd=qd, qdd=np.zeros(3000), q=np.cumsum(qd) / 1000.0, t=np.arange(3000) / 1000.0)
    without = Kinematics(qd=qd, qdd=np.zeros(3000))
    np.testing.assert_array_equal(EFFECTS["position_ripple"].scan.grid(without, 1000.0), EFFECTS["position_ripple"].scan.grid(with_q, 1000.0))
    np.testing.assert_array_equal(EFFECTS["payload_change"].scan.grid(without, 1000.0), EFFECTS["payload_change"].scan.grid(with_q, 1000.0))
    np.testing.assert_allclose(EFFECTS["payload_change"].scan.grid(without, 500.0)[[0, -1]], [0.05 * 5.998, 0.95 * 5.998])
    tiny = Kinematics(qd=np.full(10, 1e-3), qdd=np.zeros(10), q=np.linspace(0, 1e-4, 10))
    assert len(EFFECTS["position_ripple"].scan.grid(tiny, 1000.0)) >= 1
