"""Each compiled kernel is compiled for one set of argument types.

numba compiles a function anew for every set of argument types its callers give it: a literal ``0`` where a variable
integer goes elsewhere, a strided array where a contiguous one goes elsewhere. Each extra compile costs seconds of CPU in
every fresh process (the CSV writer's float text 3 s, the arm's decimation 1.9 s). The signatures are read from numba's
on-disk cache index, which keeps every one compiled since the source last changed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tests.conftest import import_or_skip


def _signatures(dispatcher: Any) -> list[str]:
    """The argument types of every compile of ``dispatcher``'s current code in its on-disk cache (numba's index of it).

    The index is kept while the source file is unchanged; its keys carry the machine and the function's bytecode, so
    compiles of other code (a mutant, ``tools/mutation.py``) are told apart.
    """
    cache = dispatcher._cache
    current = cache._index_key(None, dispatcher.targetctx.codegen())[1:]
    return [str(key[0]) for key in cache._cache_file._load_index() if key[1:] == current]


def _one(dispatcher: Any) -> None:
    sigs = _signatures(dispatcher)
    # (a tree that ran tools/mutation.py before its mutants had caches of their own may keep theirs: remove __pycache__/*.nbi)
    assert len(sigs) == 1 and "Literal" not in sigs[0], sigs


def test_the_csv_writers_float_text() -> None:
    from ilic_cli.io import floattext

    floattext.texts(np.array([1.5, -2.0e-7]))
    floattext.csv_rows([np.arange(3.0), np.array([0.5, 0.5, 0.25])], 0, 3)
    for kernel in (floattext.put, floattext._rows, floattext._texts):
        _one(kernel)


def test_the_plants_loop_with_the_pd_law_inside_the_dynamics() -> None:
    from ilic_cli.effects import make_effects
    from plant.closed_loop import simulate_loop
    from plant.controllers import PDSettings
    from plant.dynamics import RigidParameters
    from plant.kernel import _continuous_period, run_periods

    q_r = np.linspace(0.0, 0.01, 50)
    zero = np.zeros(50)
    pd = PDSettings(velocity="exact", delay_samples=0.0, continuous=True)
    simulate_loop(q_r=q_r, qd_r=zero, qdd_r=zero, params=RigidParameters(95.0, 200.0, 20.0, 0.0), effects=make_effects({}), controller=pd)
    _one(_continuous_period)
    _one(run_periods)


def test_the_arms_decimation_for_both_layouts() -> None:
    import_or_skip("pinocchio")
    from ilic_cli.robot.idim import decimate_columns
    from ilic_cli.robot.kernel import filtfilt_kept

    x = np.random.default_rng(3).standard_normal((400, 4))
    whole = decimate_columns(x.copy(), 4)  # (N, C): one page
    parts = decimate_columns(np.stack([x[:, :2], x[:, 2:]]), 4)  # (2, N, 2): a page a thread
    assert np.array_equal(whole, parts)
    _one(filtfilt_kept)
