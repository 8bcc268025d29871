"""The regressor columns (paper eq. 2 and the benchmark's asymmetric model) on hand-made kinematics."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.errors import ParameterError
from ilic_cli.regressor import MODELS, Column, Kinematics, Model, get_model

QD = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
QDD = np.array([5.0, 6.0, 7.0, 8.0, 9.0])


def test_rigid_columns() -> None:
    kin = Kinematics(qd=QD, qdd=QDD)
    W = get_model("rigid").matrix(kin)
    assert W.shape == (5, 3) and W.dtype == np.float64
    np.testing.assert_array_equal(W[:, 0], QDD)
    np.testing.assert_array_equal(W[:, 1], QD)
    np.testing.assert_array_equal(W[:, 2], [-1, -1, 0, 1, 1])
    W = get_model("rigid-offset").matrix(kin)
    np.testing.assert_array_equal(W[:, 3], np.ones(5))
    assert get_model("rigid-offset").names == ("M", "Fv", "Fc", "offset")
    assert get_model("rigid").units == ("kg", "N·s/m", "N")


def test_asymmetric_columns_split_by_the_sign_of_the_velocity() -> None:
    kin = Kinematics(qd=QD, qdd=QDD)
    m = get_model("asymmetric")
    assert m.names == ("M", "Fv_pos", "Fc_pos", "Fv_neg", "Fc_neg")
    W = dict(zip(m.names, m.matrix(kin).T, strict=True))
    np.testing.assert_array_equal(W["M"], QDD)
    np.testing.assert_array_equal(W["Fv_pos"], [0, 0, 0, 1, 2])
    np.testing.assert_array_equal(W["Fc_pos"], [0, 0, 0, 1, 1])
    np.testing.assert_array_equal(W["Fv_neg"], [-2, -1, 0, 0, 0])
    np.testing.assert_array_equal(W["Fc_neg"], [-1, -1, 0, 0, 0])
    # together they are the symmetric columns
    rigid = get_model("rigid").matrix(kin)
    np.testing.assert_array_equal(W["Fv_pos"] + W["Fv_neg"], rigid[:, 1])
    np.testing.assert_array_equal(W["Fc_pos"] + W["Fc_neg"], rigid[:, 2])


def test_smooth_sign_replaces_the_sign() -> None:
    """The CTC law's (2/pi) atan(alpha qd) in place of sign(qd)."""
    sgn = 2 / np.pi * np.arctan(10 * QD)
    kin = Kinematics(qd=QD, qdd=QDD, sign_qd=sgn)
    np.testing.assert_array_equal(kin.sgn, sgn)
    np.testing.assert_array_equal(get_model("rigid").matrix(kin)[:, 2], sgn)
    W = get_model("asymmetric").matrix(kin)
    np.testing.assert_allclose(W[:, 2], sgn * (1 + sgn) / 2)
    np.testing.assert_allclose(W[:, 4], sgn * (1 - sgn) / 2)
    np.testing.assert_array_equal(Kinematics(qd=QD, qdd=QDD).sgn, np.sign(QD))


def test_stacked_windows_and_broadcast_columns() -> None:
    kin = Kinematics(qd=np.stack([QD, -QD]), qdd=np.stack([QDD, QDD]))
    W = get_model("rigid-offset").matrix(kin)
    assert W.shape == (2, 5, 4)
    np.testing.assert_array_equal(W[1, :, 1], -QD)
    const = Model("c", (Column("k", "N", lambda k: 2.0),))
    np.testing.assert_array_equal(const.matrix(Kinematics(qd=QD, qdd=QDD))[:, 0], np.full(5, 2.0))
    ints = Kinematics(qd=np.array([1, -1]), qdd=np.array([0, 3]))
    assert get_model("rigid").matrix(ints).dtype == np.float64


def test_extend() -> None:
    base = get_model("rigid")
    spring = Column("k", "N/m", lambda k: k.q)
    ext = base.extend(spring)
    assert ext.names == ("M", "Fv", "Fc", "k") and ext.name == "rigid"
    assert base.extend(spring, name="with-spring").name == "with-spring"
    q = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    np.testing.assert_array_equal(ext.matrix(Kinematics(qd=QD, qdd=QDD, q=q))[:, 3], q)
    with pytest.raises(ValueError, match=r"^columns already in the model: \['Fv'\]$"):
        base.extend(Column("Fv", "N", lambda k: k.qd))
    assert base.names == ("M", "Fv", "Fc")  # unchanged


def test_units_of_every_parameter() -> None:
    units = {n: u for m in MODELS.values() for n, u in zip(m.names, m.units, strict=True)}
    assert units == {"M": "kg", "Fv": "N·s/m", "Fc": "N", "offset": "N", "Fv_pos": "N·s/m", "Fc_pos": "N", "Fv_neg": "N·s/m", "Fc_neg": "N"}


def test_records_are_immutable_with_empty_defaults() -> None:
    import dataclasses

    kin = Kinematics(qd=QD, qdd=QDD)
    assert kin.q is None and kin.t is None and kin.sign_qd is None and dict(kin.extra) == {}
    col = Column("k", "N/m", lambda k: k.qd)
    assert col.description == ""
    for obj, attr in ((kin, "qd"), (col, "name"), (get_model("rigid"), "name")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(obj, attr, None)


def test_model_names() -> None:
    assert set(MODELS) == {"rigid", "rigid-offset", "asymmetric"}
    for name in MODELS:
        assert get_model(name).name == name
    with pytest.raises(ParameterError, match=r"^structure = 'flexible' must be one of rigid, rigid-offset, asymmetric$"):
        get_model("flexible")
