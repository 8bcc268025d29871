"""IDIM-LS's column-at-a-time system is bit for bit the straightforward one (issue 33: the memory of a 1-hour log).

:func:`ilic_cli.idim_ls.lsq_rows` builds, decimates and lets go one regressor column at a time from kinematics
differentiated for it alone; the reference here holds every full-rate signal and decimates the whole observation
matrix at once, as the procedure reads. Any change of a bit fails.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli import idim_ilic
from ilic_cli.derivatives import central_difference
from ilic_cli.filtering import butter_lowpass_zero_phase, lowpass_decimate
from ilic_cli.idim_ilic import tracking_error_ratio
from ilic_cli.idim_ls import LSSettings, _columns, _decimate, decimated_systems, held, lsq_rows, part_valid
from ilic_cli.regressor import GRAVITY_COLUMNS, Column, Kinematics, Model, get_model
from ilic_cli.row_spans import valid_rows
from tests.unit.synth import FS, motion, rigid_force


def straightforward(
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    model: Model,
    settings: LSSettings,
    valid: np.ndarray | None = None,
    shift_s: float = 0.0,
    extra: dict[str, np.ndarray] | None = None,
) -> tuple[Kinematics, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(kin, W, y, rows)``: every full-rate signal held, the matrix and the force decimated together."""
    settings = settings.at_rate(FS)
    qf = butter_lowpass_zero_phase(q, settings.cutoff_hz, FS, settings.order, matlab=settings.matlab)
    qd = central_difference(qf, 1.0 / FS)
    qdd = central_difference(qd, 1.0 / FS)
    s = slice(settings.trim, None)
    ts = t[s]
    kin = Kinematics(qd=qd[s], qdd=qdd[s], q=qf[s], t=ts, extra={k: v[s] for k, v in (extra or {}).items()})
    built = kin
    if shift_s:

        def later(x: np.ndarray) -> np.ndarray:
            return np.interp(ts + shift_s, ts, x)

        built = Kinematics(qd=later(kin.qd), qdd=later(kin.qdd), q=later(qf[s]), t=ts, extra={k: later(v) for k, v in kin.extra.items()})
    Wy = _decimate(np.column_stack([model.matrix(built), tau[s]]), settings, FS)
    rows = None if valid is None else valid_rows(valid[s], settings.decimation)
    if rows is not None:
        Wy = Wy[rows]
    return kin, Wy[:, :-1], Wy[:, -1], rows


@pytest.fixture(scope="module")
def log() -> tuple[np.ndarray, ...]:
    t, q, qd, qdd = motion(6_000)
    tau = rigid_force(qd, qdd) + 0.3 * np.sin(7.0 * t)
    return t, q, tau


def _models() -> list[Model]:
    """Views of the kinematics (M, Fv), new arrays (Fc, offset, the sides), the position (gravity), time and a channel, a constant."""
    odd = (Column("u_t", "", lambda k: k.extra["u"] * k.t), Column("two", "", lambda k: np.asarray(2.0)))
    return [get_model("rigid-offset"), get_model("asymmetric"), get_model("rigid").extend(*GRAVITY_COLUMNS.values(), *odd)]


@pytest.mark.parametrize("matlab", [True, False])
def test_lsq_rows_is_the_straightforward_system(log: tuple[np.ndarray, ...], matlab: bool) -> None:
    t, q, tau = log
    valid = np.ones(len(t), dtype=bool)
    valid[2000:2007] = False
    extra = {"u": np.cos(3.0 * t)}
    settings = LSSettings(matlab=matlab)
    for model in _models():
        for v in (None, valid):
            data = lsq_rows(t, q, tau, FS, model, settings, extra=extra, valid=v)
            kin, W, y, rows = straightforward(t, q, tau, model, settings, v, extra=extra)
            assert np.array_equal(data.W, W) and np.array_equal(data.y, y)
            assert data.W.flags.c_contiguous and data.y.flags.c_contiguous
            assert (data.rows is None and rows is None) or np.array_equal(data.rows, rows)
            for name in ("q", "qd", "qdd", "t"):
                assert np.array_equal(getattr(data.kin, name), getattr(kin, name)), name
            assert np.array_equal(data.kin.extra["u"], kin.extra["u"])


def test_the_held_system_is_the_straightforward_one(log: tuple[np.ndarray, ...]) -> None:
    """With the regressor evaluated half a period later: as :func:`held` rebuilds it from :func:`lsq_rows`' kinematics."""
    t, q, tau = log
    valid = np.ones(len(t), dtype=bool)
    valid[3000:3004] = False
    shift = 0.5 / FS
    settings = LSSettings()
    for model in _models()[:2]:
        for v in (None, valid):
            W, y, td, kept = decimated_systems(t, q, tau, FS, model, settings, v, None, shift)
            _, W0, y0, _ = straightforward(t, q, tau, model, settings, v, shift)
            assert np.array_equal(W, W0) and np.array_equal(y, y0)
            data = held(lsq_rows(t, q, tau, FS, model, settings, valid=v), model, shift)
            assert np.array_equal(W, data.W) and np.array_equal(y, data.y) and np.array_equal(td, data.t_dec)
            assert (kept is None) == (v is None)


def test_segments_are_the_parts_stacked(log: tuple[np.ndarray, ...]) -> None:
    t, q, tau = log
    model = get_model("rigid-offset")
    W, y, td, kept = decimated_systems(t, q, tau, FS, model, LSSettings(), None, ((0, 2500), (2600, 6000)), 0.0)
    # the first part ends at a gap: its last trim samples, the filters' edge, are left out (part_valid)
    spans = ((0, 2500), (2600, 6000))
    parts = [
        lsq_rows(t[a:b], q[a:b], tau[a:b], FS, model, valid=part_valid(None, b - a, i > 0, i == 0, LSSettings().at_rate(FS))) for i, (a, b) in enumerate(spans)
    ]
    assert np.array_equal(W, np.concatenate([p.W for p in parts])) and np.array_equal(y, np.concatenate([p.y for p in parts]))
    assert np.array_equal(td, np.concatenate([p.t_dec for p in parts])) and kept is not None and (~kept).sum() == 6  # rows within 49 + 9 samples of the end


@pytest.mark.parametrize("n", [2, 3, 4, 1001])
def test_central_difference_of_a_signal_is_numpy_s_gradient(n: int) -> None:
    """The 1-D path (differenced in place, no temporary) gives ``np.gradient``'s bits."""
    x = np.random.default_rng(n).normal(size=n).cumsum()
    for dt in (1e-3, 1.0 / 3.0, 0.25):
        d = central_difference(x, dt)
        assert np.array_equal(d, np.gradient(x, dt)) and d.dtype == np.float64


def test_tracking_error_ratio_is_numpy_s_norms() -> None:
    """IDIM-ILIC's tracking error ratio squares its temporaries in place: the bits of ``np.linalg.norm(..., axis=-1)``."""
    rng = np.random.default_rng(33)
    for shape in ((5001,), (7, 620), (1, 3)):
        q = rng.normal(size=shape).cumsum(axis=-1)
        q_ref = q + 1e-3 * rng.normal(size=shape)
        e = np.linalg.norm(q_ref - q, axis=-1)
        spread = np.linalg.norm(q - q.mean(axis=-1, keepdims=True), axis=-1)
        assert np.array_equal(tracking_error_ratio(q_ref, q), np.where(spread > 0, e / spread, np.inf))
    ints = np.arange(12).reshape(3, 4)
    spread = np.linalg.norm(ints - ints.mean(axis=-1, keepdims=True), axis=-1)
    assert np.array_equal(tracking_error_ratio(ints + 1, ints), np.linalg.norm(np.ones((3, 4)), axis=-1) / spread)


@pytest.mark.parametrize("chunk", [None, 5 * 620])
def test_ilic_columns_by_groups_of_windows_are_all_windows_at_once(monkeypatch: pytest.MonkeyPatch, chunk: int | None) -> None:
    """IDIM-ILIC builds the rigid columns a group of windows at a time (the filter's blocks of rows, or smaller): the same bits."""
    if chunk is not None:
        monkeypatch.setattr(idim_ilic, "CHUNK_ELEMENTS", chunk)
    K, n = (400, 6200) if chunk is None else (23, 620)  # 2.48M samples: two of the filter's blocks, as on a 1-hour log
    t, q, qd, qdd = motion(K * n)
    kin = Kinematics(qd=qd.reshape(K, n), qdd=qdd.reshape(K, n), q=q.reshape(K, n), t=t.reshape(K, n))
    settings = idim_ilic.ILICSettings()
    r = settings.factor(FS)
    for model in (get_model("rigid-offset"), get_model("asymmetric")):
        every = [lowpass_decimate(np.asarray(c, dtype=np.float64), r, settings.cutoff_hz, FS, settings.filter_order, axis=1) for c in _columns(model, kin)]
        grouped = idim_ilic._decimated_columns(model, kin, r, FS, settings)
        assert len(grouped) == len(every) and all(np.array_equal(a, b) for a, b in zip(grouped, every, strict=True))
