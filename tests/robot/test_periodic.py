"""robot-sim's periodic reference and its window system made once (:class:`Periodic`, :func:`same_system`)."""

from __future__ import annotations

import numpy as np

from ilic_cli.robot.scenario import same_system
from ilic_cli.robot.simulate import Periodic, exciting_trajectory

FS = 1000.0


def test_a_periodic_reference_repeats_its_bits_and_is_the_trajectory_to_roundoff() -> None:
    traj = exciting_trajectory(np.zeros(3), np.full(3, 1.5), seed=2, f0_hz=0.5)
    t = np.arange(5000) * (1.0 / FS)  # simulate_loop's grid
    direct = traj.at(t)
    tiled = Periodic(traj, 2.0, FS).at(t)
    for a, b in zip(tiled, direct, strict=True):
        assert a.shape == b.shape == (5000, 3)
        assert np.array_equal(a[:2000], a[2000:4000]) and np.array_equal(a[:1000], a[4000:])
        assert np.array_equal(a[:2000], b[:2000])  # the first period is evaluated as given
        assert np.allclose(a, b, rtol=0.0, atol=1e-11 * max(1.0, np.abs(b).max()))
    # not a period of the trajectory (f0 = 0.5 Hz: 1.5 s holds 0.75 of a cycle), or off the grid: every time as given
    for other, times in ((Periodic(traj, 1.5, FS), t), (Periodic(traj, 2.0, FS), t + 0.25e-3)):
        for a, b in zip(other.at(times), traj.at(times), strict=True):
            assert np.array_equal(a, b)


def test_the_window_system_is_made_again_when_any_of_the_reference_differs() -> None:
    known: list[tuple[tuple[np.ndarray, ...], np.ndarray]] = []
    made: list[int] = []

    def make() -> np.ndarray:
        made.append(1)
        return np.full(2, float(len(made)))

    ref = tuple(np.arange(6.0).reshape(3, 2) + i for i in range(3))
    first = same_system(known, ref, make)
    again = same_system(known, tuple(a.copy() for a in ref), make)
    assert again is first and len(made) == 1
    changed = (ref[0], ref[1], ref[2] + 1e-9 * (np.arange(6.0).reshape(3, 2) == 5))
    assert same_system(known, changed, make)[0] == 2.0 and len(made) == 2
