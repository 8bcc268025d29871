"""Arms of n joints from their URDF (issue 30): model, base parameters, IDIM-LS, simulator.

- :mod:`ilic_cli.robot.model`: the URDF through pinocchio, the standard parameters
  (10 inertial per link, then Ia, Fv, Fc, offset per joint) and the regressor
  (:mod:`ilic_cli.robot.kernel`: its compiled inertial columns);
- :mod:`ilic_cli.robot.base`: base parameters by QR with column pivoting, and their regrouping;
- :mod:`ilic_cli.robot.idim`: n-joint IDIM-LS (Gautier's weighted least squares);
- :mod:`ilic_cli.robot.consistency`: does a physically consistent standard set exist (log-Cholesky fit);
- :mod:`ilic_cli.robot.simulate`: forward dynamics with friction, PD tracking, sensors.

pinocchio is an optional dependency (``pip install 'ilic[robot]'``): nothing
here imports it at module level, so ``import ilic_cli.robot`` costs nothing.
"""
