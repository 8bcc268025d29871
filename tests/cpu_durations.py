"""The tests' CPU time, for the suite's budget on a shared machine: ``pytest -p tests.cpu_durations --cpu-durations=N``.

Wall time (``--durations``) moves with the machine's other load; the CPU a test costs does not. Each phase (setup, call,
teardown) is measured as user + system time of the process running it and of the children it waited for (a CLI run,
mypy), in the worker under pytest-xdist, and carried to the controller with the report (``user_properties``). The
terminal summary lists the N tests that cost most and the total.
"""

from __future__ import annotations

import resource
from collections.abc import Generator
from typing import Any

import pytest

PROPERTY = "cpu_s"
_START = pytest.StashKey[float]()
_SPENT = pytest.StashKey[dict[str, float]]()
_totals: dict[str, float] = {}


def cpu_seconds() -> float:
    """User + system time of this process and of its waited-for children (s)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.getgroup("terminal reporting").addoption(
        "--cpu-durations", type=int, default=None, metavar="N", help="list the N tests with the most CPU time (with their children's)"
    )


def _measured(item: pytest.Item, when: str) -> Generator[None, Any, None]:
    start = cpu_seconds()
    yield
    item.stash.setdefault(_SPENT, {})[when] = cpu_seconds() - start


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item: pytest.Item) -> Generator[None, Any, None]:
    yield from _measured(item, "setup")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Generator[None, Any, None]:
    yield from _measured(item, "call")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item) -> Generator[None, Any, None]:
    yield from _measured(item, "teardown")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, Any, None]:
    outcome = yield
    spent = item.stash.get(_SPENT, {}).get(call.when)
    if spent is not None:
        outcome.get_result().user_properties.append((PROPERTY, spent))


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    for name, value in report.user_properties:
        if name == PROPERTY:
            _totals[report.nodeid] = _totals.get(report.nodeid, 0.0) + float(value)


def pytest_terminal_summary(terminalreporter: Any, config: pytest.Config) -> None:
    n = config.getoption("cpu_durations")
    if n is None or hasattr(config, "workerinput"):
        return
    terminalreporter.write_sep("=", f"most CPU time: {n} of {len(_totals)} tests (user + system, with children)")
    for nodeid, seconds in sorted(_totals.items(), key=lambda kv: -kv[1])[:n]:
        terminalreporter.write_line(f"{seconds:8.2f}s cpu {nodeid}")
    terminalreporter.write_line(f"{sum(_totals.values()):8.2f}s cpu in all")
