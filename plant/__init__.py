"""Simulated plant: the EMPS-like 1-DOF prismatic axis in closed loop.

Modules
-------
``plant.dynamics``      rigid parameters, the plant vector, :func:`~plant.dynamics.force_model` (inverse dynamics);
                        the effects themselves are defined in :mod:`ilic_cli.effects`
``plant.trajectories``  exciting trajectories (trapezoidal velocity profiles, multisines)
``plant.controllers``   CTC (paper eqs. 11-16) and the benchmark PD loop settings
``plant.kernel``        the compiled inner loop (controller per period, RK4, stick/slip; ``plant.kernel_linear``:
                        the force of the linear effects from their columns)
``plant.blocks``        the stateful blocks: flexible load, drive lag, current loop
``plant.generic``       the loop compiled for effects without a compiled form
``plant.sensors``       the logged force (held, delayed, noisy) and the noise
``plant.closed_loop``   :func:`~plant.closed_loop.simulate_loop` (with the CTC's online update it is handed) and the run log
``plant.replay``        :func:`~plant.replay.simulate_replay`: a recorded log's reference through the plant

The named scenarios (``paper-sim``, ``paper-payload``, ``emps-benchmark``), which read a recorded log and hand
the loop IDIM-ILIC, are :mod:`ilic_cli.simulation.scenarios`: the plant imports no estimator and no I/O.
The corpus of simulated logs with known truth, which calibrates and tests the diagnosis, is ``tests/corpus/``.

Importing ``plant`` is cheap, and imports none of its modules (numba's import and the compiled loop
cost about a second, paid by the first module that needs them); the loop is compiled once and cached.
"""
