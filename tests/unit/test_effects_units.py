"""A catalogue unit on a revolute joint (:func:`ilic_cli.effects.unit_on`, :func:`ilic_cli.effects.unit_of`)."""

from __future__ import annotations

import pytest

from ilic_cli.effects import EFFECTS, Estimate, unit_of, unit_on


@pytest.mark.parametrize(
    ("prismatic", "revolute"),
    [
        ("N·s/m", "N·m·s/rad"),
        ("N", "N·m"),
        ("m/s", "rad/s"),
        ("m", "rad"),
        ("N/m", "N·m/rad"),
        ("kg", "kg·m²"),
        ("N/s", "N·m/s"),
        ("s", "s"),
        ("Hz", "Hz"),
        ("rad", "rad"),
        ("", ""),
    ],
)
def test_each_factor_turns(prismatic: str, revolute: str) -> None:
    assert unit_on(prismatic, "revolute") == revolute and unit_on(prismatic, "prismatic") == prismatic


def test_a_column_s_unit_by_the_joint_and_gravity_in_its_own() -> None:
    assert (unit_of("Fs", "revolute"), unit_of("k_spring", "revolute"), unit_of("M_load", "revolute")) == ("N·m", "N·m/rad", "kg·m²")
    assert (unit_of("Fs"), unit_of("k_spring"), unit_of("M_load")) == ("N", "N/m", "kg")
    assert unit_of("MX", "revolute") == "kg·m"  # gravity is a revolute joint's, written in its units


def test_a_finding_s_sentence_reads_the_joint_s_units() -> None:
    stribeck = EFFECTS["stribeck"]
    prismatic = {"Fs": Estimate(0.3, None, "N"), "vs": Estimate(0.02, None, "m/s")}
    assert stribeck.describe(stribeck.on_joint(prismatic, "revolute")) == "Stribeck friction (extra friction Fs = 0.3 N·m below vs = 20 mrad/s)"
    assert stribeck.on_joint(prismatic, "prismatic") == prismatic and stribeck.describe(prismatic).endswith("Fs = 0.3 N below vs = 20 mm/s)")


def test_the_joint_option_offers_the_joint_types() -> None:
    """``--load-joint``'s choices are written out (the commands' module stays free of numpy); they are the joint types' units' keys."""
    from ilic_cli.commands.common import JOINTS
    from ilic_cli.jointlog import UNITS

    assert sorted(JOINTS) == sorted(UNITS)
