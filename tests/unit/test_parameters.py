"""The parameter vocabulary: names, units, structures, the mapping to the plant and its rules (exact cases)."""

from __future__ import annotations

import math

import pytest

from ilic_cli import parameters as P
from ilic_cli.errors import ParameterError
from ilic_cli.runlog import joint_type


def test_every_parameter_has_prismatic_and_revolute_units() -> None:
    assert list(P.PARAMETERS) == ["M", "Fv", "Fc", "offset", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"]
    assert [P.unit(n) for n in P.PARAMETERS] == ["kg", "N·s/m", "N", "N", "N·s/m", "N", "N·s/m", "N"]
    assert [P.unit(n, "revolute") for n in P.PARAMETERS] == ["kg·m²", "N·m·s/rad", "N·m", "N·m", "N·m·s/rad", "N·m", "N·m·s/rad", "N·m"]
    assert P.unit("ripple_sin") == "" and P.PARAMETERS["Fc_neg"].unit_for("revolute") == "N·m"
    assert all(p.meaning for p in P.PARAMETERS.values())


def test_structures_and_their_lookup() -> None:
    assert P.STRUCTURES == {
        "rigid": ("M", "Fv", "Fc"),
        "rigid-offset": ("M", "Fv", "Fc", "offset"),
        "asymmetric": ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"),
    }
    assert P.structure_names("asymmetric") == ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg")
    assert P.structure_of(("M", "Fv", "Fc")) == "rigid"
    assert P.structure_of(["offset", "Fc", "M", "Fv", "k_spring"]) == "rigid-offset"
    assert P.structure_of({"M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg"}) == "asymmetric"
    assert P.structure_of(("M", "Fv")) is None
    with pytest.raises(ParameterError) as err:
        P.structure_names("rigid_offset")
    assert (err.value.parameter, err.value.value) == ("structure", "rigid_offset")


def test_joint_type_from_the_position_unit() -> None:
    assert joint_type("rad") == "revolute" and joint_type(" Radians ") == "revolute"
    assert joint_type("m") == "prismatic" and joint_type(None) == "prismatic" and joint_type("") == "prismatic"


@pytest.mark.parametrize(
    ("values", "parameter", "rule"),
    [
        ({"M": 0.0}, "M", "> 0"),
        ({"M": -1.0}, "M", "> 0"),
        ({"M": 95.0, "Fc": -0.02}, "Fc", ">= 0"),
        ({"M": 95.0, "Fc_pos": -1.0}, "Fc_pos", ">= 0"),
        ({"M": 95.0, "Fc_neg": -1.0}, "Fc_neg", ">= 0"),
        ({"M": 95.0, "Fv": math.inf}, "Fv", "finite"),
        ({"M": math.nan}, "M", "finite"),
    ],
)
def test_rigid_rules(values: dict[str, float], parameter: str, rule: str) -> None:
    with pytest.raises(ParameterError) as err:
        P.check_rigid(values)
    assert (err.value.parameter, err.value.rule) == (parameter, rule)


def test_rigid_rules_accept_the_boundaries() -> None:
    P.check_rigid({"M": 1e-9, "Fv": -5.0, "Fc": 0.0, "offset": -3.0, "Fc_pos": 0.0, "Fc_neg": 0.0})


def test_to_plant_of_every_structure() -> None:
    assert P.to_plant({"M": 95.0, "Fv": 200.0, "Fc": 20.0}) == ({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0}, None)
    assert P.to_plant({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}) == ({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": -3.0}, None)
    rigid, asym = P.to_plant({"M": 95.0, "Fv_pos": 160.0, "Fc_pos": 19.0, "Fv_neg": 240.0, "Fc_neg": 21.0})
    assert rigid == {"M": 95.0, "Fv": 0.0, "Fc": 0.0, "offset": 0.0}
    assert asym == {"Fv_pos": 160.0, "Fc_pos": 19.0, "Fv_neg": 240.0, "Fc_neg": 21.0}


@pytest.mark.parametrize(
    ("values", "parameter"),
    [
        ({"Fv": 200.0}, "M"),
        ({"M": 95.0, "k_spring": 3.0}, "k_spring"),
        ({"M": 95.0, "Fv_pos": 1.0, "Fc_pos": 1.0, "Fv_neg": 1.0}, "Fc_neg"),
        ({"M": 95.0, "Fv_neg": 1.0}, "Fv_pos"),
    ],
)
def test_to_plant_refuses(values: dict[str, float], parameter: str) -> None:
    with pytest.raises(ParameterError) as err:
        P.to_plant(values)
    assert err.value.parameter == parameter


def test_from_plant_inverts_to_plant_for_every_structure() -> None:
    for structure, names in P.STRUCTURES.items():
        values = {n: float(i + 1) * 3.25 for i, n in enumerate(names)}
        assert P.from_plant(*P.to_plant(values), structure) == values
    # a symmetric plant seen as the asymmetric structure
    assert P.from_plant({"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0}, None, "asymmetric") == {
        "M": 95.0,
        "Fv_pos": 200.0,
        "Fc_pos": 20.0,
        "Fv_neg": 200.0,
        "Fc_neg": 20.0,
    }
    with pytest.raises(ParameterError, match="'asymmetric' for a plant with asymmetric friction"):
        P.from_plant({"M": 95.0, "Fv": 0.0, "Fc": 0.0, "offset": 0.0}, {"Fv_pos": 1.0, "Fc_pos": 1.0, "Fv_neg": 2.0, "Fc_neg": 2.0}, "rigid")


def test_parameter_error_wording() -> None:
    assert ParameterError("Fc", -0.02, ">= 0").message() == "Fc = -0.02 must be >= 0"
    assert ParameterError("structure", "x", "one of a, b").message() == "structure = 'x' must be one of a, b"
    assert ParameterError("M", None, "given").message() == "M must be given"
    moved = ParameterError("Fc", -1.0, ">= 0").at("--param")
    assert moved.message() == "--param: Fc = -1 must be >= 0" and moved.parameter == "Fc"


def test_defaults_are_the_papers_simulated_axis_and_records_are_frozen() -> None:
    import dataclasses

    assert P.DEFAULTS == {"M": 95.0, "Fv": 200.0, "Fc": 20.0, "offset": 0.0}  # paper section VI-E
    assert joint_type("radian") == "revolute"
    with pytest.raises(dataclasses.FrozenInstanceError):
        P.PARAMETERS["M"].unit = "g"  # type: ignore[misc]


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: P.structure_names("flexible"), "structure = 'flexible' must be one of rigid, rigid-offset, asymmetric"),
        (lambda: P.to_plant({"M": 1.0, "x": 2.0}), "x = 2 must be a parameter of the axis (M, Fv, Fc, offset, Fv_pos, Fc_pos, Fv_neg, Fc_neg)"),
        (lambda: P.to_plant({"Fv": 1.0}), "M must be given (the model has no mass)"),
        (lambda: P.to_plant({"M": 1.0, "Fv_pos": 1.0}), "Fc_pos must be given with the other asymmetric friction parameters (Fv_pos, Fc_pos, Fv_neg, Fc_neg)"),
        (
            lambda: P.from_plant({"M": 1.0, "Fv": 0.0, "Fc": 0.0, "offset": 0.0}, {"Fv_pos": 1.0, "Fc_pos": 1.0, "Fv_neg": 1.0, "Fc_neg": 1.0}, "rigid"),
            "structure = 'rigid' must be 'asymmetric' for a plant with asymmetric friction",
        ),
    ],
)
def test_messages(call, message: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParameterError) as err:
        call()
    assert err.value.message() == message
