"""Growing columns of :mod:`ilic_cli.io.roscolumns` (issue 33).

An int64 column whose values go up by one step is held as its first value,
step and length until it is asked for: the values it gives back are the ones
given to it, bit for bit, whatever the blocks and single items they came in.
"""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.io.roscolumns import Numbers

BIG = 2**63 - 1
SMALL = -(2**63)


def _fed(pieces: list[object], reserve: int = 0) -> Numbers:
    """A column fed ``pieces`` in order: an ndarray is a block, an int an item."""
    column = Numbers(np.int64)
    if reserve:
        column.reserve(reserve)
    for piece in pieces:
        if isinstance(piece, np.ndarray):
            column.block(piece)
        else:
            column.items.append(piece)
    return column


def _straight(pieces: list[object]) -> np.ndarray:
    return np.array([v for p in pieces for v in (p.tolist() if isinstance(p, np.ndarray) else [p])], dtype=np.int64)


CASES = {
    "clock": [np.arange(0, 5_000_000, 1_000_000, dtype=np.int64), np.arange(5_000_000, 9_000_000, 1_000_000, dtype=np.int64), 9_000_000, 10_000_000],
    "a step then another": [np.arange(0, 50, 5, dtype=np.int64), np.arange(50, 70, 2, dtype=np.int64)],
    "one jitter": [np.array([0, 10, 20, 31, 40], dtype=np.int64)],
    "gap between blocks": [np.arange(0, 50, 10, dtype=np.int64), np.arange(60, 100, 10, dtype=np.int64)],
    "single items": [7, 7, 7, 7],
    "items then a break": [1, 2, 3, 5, np.arange(6, 9, dtype=np.int64)],
    "going down": [np.arange(100, 0, -3, dtype=np.int64)],
    "empty blocks": [np.empty(0, dtype=np.int64), 4, np.empty(0, dtype=np.int64), np.array([5, 6], dtype=np.int64)],
    "int64's ends": [np.array([SMALL, 0, BIG - 1], dtype=np.int64) // 2 * 2, np.array([BIG], dtype=np.int64)],
    "a step past int64": [np.array([SMALL, BIG], dtype=np.int64), np.array([SMALL], dtype=np.int64)],
    "wrapping differences": [np.array([BIG - 5, SMALL + 5], dtype=np.int64)],
    "not int64": [np.arange(3, dtype=np.int64), np.arange(3, 6, dtype=np.int32)],
    "nothing": [],
}


@pytest.mark.parametrize("reserve", [0, 4, 1000])
@pytest.mark.parametrize("name", list(CASES))
def test_a_column_gives_back_its_values(name: str, reserve: int) -> None:
    pieces = CASES[name]
    got = _fed(pieces, reserve).array()
    want = _straight(pieces) if name != "not int64" else np.concatenate([np.arange(3), np.arange(3, 6)]).astype(np.int64)
    assert got.dtype == np.int64
    assert got.tolist() == want.tolist()


def test_random_columns_give_back_their_values() -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        start, step = int(rng.integers(-(2**40), 2**40)), int(rng.choice([0, 1, 1000, 10**6, -7]))
        values = start + step * np.arange(int(rng.integers(1, 400)), dtype=np.int64)
        if rng.random() < 0.5:
            values[int(rng.integers(len(values)))] += int(rng.choice([-1, 1]))
        pieces: list[object] = []
        at = 0
        while at < len(values):
            size = int(rng.integers(1, 50))
            pieces.extend(values[at : at + size].tolist() if rng.random() < 0.3 else [values[at : at + size].copy()])
            at += size
        assert _fed(pieces, int(rng.integers(0, 500))).array().tolist() == values.tolist()


def test_a_clock_is_held_as_three_numbers() -> None:
    column = _fed([np.arange(0, 10**9, 10**6, dtype=np.int64) for _ in range(1)] + [np.arange(10**9, 2 * 10**9, 10**6, dtype=np.int64)], reserve=2000)
    assert column.affine == (0, 10**6, 2000)
    assert not column.blocks.done and not column.blocks.recent and column.blocks.filled == 0


def test_the_ros2_type_store_is_humbles() -> None:
    """:func:`ilic_cli.io.rosschema.typestore` registers a few of Humble's types in an empty store: the same definitions, texts, hashes and bytes."""
    from rosbags.typesys import Stores, get_typestore

    from ilic_cli.io import rosschema

    ours, humble = rosschema.typestore(rosschema.ROS2), get_typestore(Stores.ROS2_HUMBLE)
    assert set(ours.fielddefs) == set(rosschema.ros2_types())
    for name in ours.fielddefs:
        assert ours.fielddefs[name] == humble.fielddefs[name], name
        assert ours.generate_msgdef(name, ros_version=2) == humble.generate_msgdef(name, ros_version=2), name
        assert ours.hash_rihs01(name) == humble.hash_rihs01(name), name
    Time, Header = humble.types["builtin_interfaces/msg/Time"], humble.types["std_msgs/msg/Header"]
    state = humble.types[rosschema.JOINT_STATE](Header(Time(3, 4), "f"), ["a", "b"], np.array([1.5, -2.0]), np.array([]), np.array([0.25, 1e300]))
    raw = bytes(humble.serialize_cdr(state, rosschema.JOINT_STATE))
    back = ours.deserialize_cdr(raw, rosschema.JOINT_STATE)
    assert bytes(ours.serialize_cdr(back, rosschema.JOINT_STATE)) == raw
    assert back.name == ["a", "b"] and back.position.tolist() == [1.5, -2.0] and back.effort.tolist() == [0.25, 1e300]
