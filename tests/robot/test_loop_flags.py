"""The arm's per-step kernels are compiled without numba's reference counting (``ilic_cli.robot.loop``'s docstring: 6.0-6.6 -> 4.1-4.4 us a step)."""

from __future__ import annotations

from ilic_cli.robot import dynamics, loop

PER_STEP = (loop._directions, loop._accel, loop._rk4, loop._period, loop._command, dynamics.rnea_at, dynamics.crba_at)


def test_the_per_step_functions_count_no_references_raise_on_no_division_and_only_fuse_products() -> None:
    for function in PER_STEP:
        options = function.targetoptions
        assert options.get("_nrt") is False, f"{function.__name__}: numba's reference counting on (an atomic pair per array argument and view)"
        assert options.get("error_model") == "numpy", function.__name__
        assert options.get("fastmath") == {"contract"}, f"{function.__name__}: fused multiply-adds only, no other fast-math license"
