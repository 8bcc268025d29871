"""Runs of same-layout CDR messages (:mod:`ilic_cli.io.cdrcols`, issue 33): the word-at-a-time comparison of aligned messages is the byte-by-byte one."""

from __future__ import annotations

import numpy as np
import pytest

from ilic_cli.io import cdrcols
from ilic_cli.io.rosschema import JOINT_STATE, ROS2, STRING, TRAJECTORY_POINT, typestore


def _messages() -> list[tuple[str, bytes]]:
    ts = typestore(ROS2)
    Time, Header, Duration = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"], ts.types["builtin_interfaces/msg/Duration"]
    state = ts.types[JOINT_STATE]
    point = ts.types[TRAJECTORY_POINT]
    out = []
    for names in (["axis"], ["t_s", "Fc_hat", "Fv_hat", "M_hat", "qd_plant", "qdd_plant"], ["a", "bb", "ccc"]):
        n = len(names)
        out.append(
            (
                JOINT_STATE,
                bytes(ts.serialize_cdr(state(Header(Time(1, 2), "frame"[: n + 1]), names, np.ones(n), np.ones(n) * (n > 1), np.ones(n)), JOINT_STATE)),
            )
        )
    out.append((TRAJECTORY_POINT, bytes(ts.serialize_cdr(point(np.ones(1), np.ones(1), np.ones(1), np.empty(0), Duration(3, 4)), TRAJECTORY_POINT))))
    out.append((STRING, bytes(ts.serialize_cdr(ts.types[STRING]("hello"), STRING))))
    return out


def _bytewise(buf: np.ndarray, base: int, stride: int, count: int, lay: cdrcols.Layout) -> int:
    rows = cdrcols.rows_view(buf, base, stride, count, lay.size)
    fixed = np.flatnonzero(~lay.varying)
    same = (rows[:, fixed] == rows[0, fixed]).all(axis=1)
    bad = np.flatnonzero(~same)
    return int(bad[0]) if len(bad) else count


@pytest.mark.parametrize(("msgtype", "data"), _messages(), ids=lambda x: str(len(x)) if isinstance(x, bytes) else x)
def test_aligned_runs_compare_as_byte_by_byte(msgtype: str, data: bytes) -> None:
    lay = cdrcols.layout(data, msgtype)
    assert lay is not None
    rng = np.random.default_rng(len(data))
    padded = -(-len(data) // 8) * 8
    for _ in range(300):
        count = int(rng.integers(1, 40))
        stride = padded + 8 * int(rng.integers(0, 2))
        buf = rng.integers(0, 256, size=count * stride + 8, dtype=np.uint8)  # values and padding at random
        template = np.frombuffer(data, dtype=np.uint8)
        fixed = ~lay.varying
        for i in range(count):
            np.copyto(buf[i * stride : i * stride + len(data)], template, where=fixed)
        for _ in range(int(rng.integers(0, 3))):  # a structural byte changed in some message
            i, k = int(rng.integers(count)), int(rng.integers(len(data)))
            buf[i * stride + k] ^= np.uint8(1 << int(rng.integers(8)))
        assert buf.ctypes.data % 8 == 0  # NumPy's arrays are aligned: the word-at-a-time path
        assert cdrcols.matching_rows(buf, 0, stride, count, lay) == _bytewise(buf, 0, stride, count, lay)
        shifted = np.empty(len(buf) + 3, dtype=np.uint8)[3:]  # unaligned: byte by byte
        shifted[:] = buf
        assert cdrcols.matching_rows(shifted, 0, stride, count, lay) == _bytewise(buf, 0, stride, count, lay)
