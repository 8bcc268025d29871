"""Independent work on the machine's cores (``ilic_cli/parallel.py``): order, errors, and replays identical in threads."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from ilic_cli.errors import ParameterError
from ilic_cli.parallel import PREFIX, THREADS_ENV, ordered_map, threads


def test_results_come_back_in_order_from_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "3")
    names: set[str] = set()

    def slow_square(x: int) -> int:
        names.add(threading.current_thread().name)
        threading.Event().wait(0.01 * (5 - x))  # the first items finish last
        return x * x

    assert ordered_map(slow_square, range(5)) == [0, 1, 4, 9, 16]
    assert names and all(n.startswith(PREFIX) for n in names)


def test_only_the_outermost_call_shares_work_out(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "2")

    def inner(_: int) -> list[str]:
        return ordered_map(lambda _: threading.current_thread().name, range(3))

    outer = ordered_map(inner, range(2))
    assert all(len(set(names)) == 1 and names[0].startswith(PREFIX) for names in outer)  # each inner call in its own thread


def test_one_thread_runs_in_the_caller(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "1")
    assert threads() == 1
    assert ordered_map(lambda _: threading.current_thread() is threading.main_thread(), range(3)) == [True] * 3


def test_a_cap_of_one_runs_in_the_caller_and_a_cap_above_shares_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """``most``: the caller's own bound on the threads (the filters' 8; 1 for rows that must go one at a time)."""
    monkeypatch.setenv(THREADS_ENV, "3")
    in_caller = lambda _: threading.current_thread() is threading.main_thread()  # noqa: E731
    assert ordered_map(in_caller, range(3), most=1) == [True] * 3
    assert ordered_map(in_caller, range(3), most=2) == [False] * 3


def test_the_first_error_in_order_is_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(THREADS_ENV, "2")

    def fail_odd(x: int) -> int:
        if x % 2:
            raise KeyError(x)
        return x

    with pytest.raises(KeyError) as err:
        ordered_map(fail_odd, range(6))
    assert err.value.args == (1,)


def test_an_error_does_not_wait_for_the_rest(monkeypatch: pytest.MonkeyPatch) -> None:
    """The items not yet started are cancelled, and the running ones are not waited for (a Ctrl-C returns at once)."""
    monkeypatch.setenv(THREADS_ENV, "2")
    ran: list[int] = []
    release = threading.Event()

    def work(x: int) -> int:
        if x == 0:
            raise KeyError(x)
        if x == 1:
            release.wait(5.0)  # busy until the test releases it
        else:
            threading.Event().wait(0.05)
        ran.append(x)
        return x

    with pytest.raises(KeyError):
        ordered_map(work, range(12))
    try:
        assert 1 not in ran  # returned while item 1 still ran
        threading.Event().wait(0.8)  # time for items 2-11 to run, had they not been cancelled
        assert len(ran) <= 3, ran  # at most those a free thread had started
    finally:
        release.set()


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_a_bad_thread_count_is_refused(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv(THREADS_ENV, value)
    with pytest.raises(ParameterError, match="ILIC_THREADS .* must be a whole number of threads, at least 1"):
        threads()


def test_default_is_the_cores_available(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(THREADS_ENV, raising=False)
    assert threads() >= 1


def test_replays_in_threads_equal_replays_one_after_another(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled loop is pure and releases the GIL: the same logs, bit for bit, whatever the threads (Stribeck: its general path)."""
    from ilic_cli.simulation.replay import replay
    from tests.corpus import CASES, PLANT, simulate_case

    log = simulate_case(CASES["clean-trapezoid-sensor-s1"])
    sensor = {"noise": {"q_std": 5e-7}, "quantization": {"resolution": 2e-7}}

    def one(vs: float) -> np.ndarray:
        return np.asarray(replay(log, dict(PLANT), {**sensor, "stribeck": {"Fs": 2.0, "vs": vs}}, seed=3)["tau"])

    values = [0.006, 0.009, 0.012, 0.015]
    monkeypatch.setenv(THREADS_ENV, "1")
    alone = ordered_map(one, values)
    monkeypatch.setenv(THREADS_ENV, "2")
    side_by_side = ordered_map(one, values)
    assert all(np.array_equal(a, b) for a, b in zip(alone, side_by_side, strict=True))
    assert not np.array_equal(alone[0], alone[1])  # the values differ, so do the logs
