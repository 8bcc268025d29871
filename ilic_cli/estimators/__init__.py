"""The estimators behind one interface (issue 32): ``Estimator.fit(prepared, model, settings) -> Fit``.

- :mod:`~ilic_cli.estimators.base`: :class:`~ilic_cli.estimators.base.Fit` (the shared result),
  :class:`~ilic_cli.estimators.base.ModelSpec` (which parameters), the :class:`~ilic_cli.estimators.base.Estimator`
  protocol and the :class:`~ilic_cli.estimators.base.LoopSimulator` the closed-loop methods are handed;
- :mod:`~ilic_cli.estimators.inverse`: IDIM-LS and IDIM-ILIC (inverse model, open loop);
- :mod:`~ilic_cli.estimators.closed_loop`: DIDIM and IDIM-IV (iterated on replays of the loop);
- :mod:`~ilic_cli.estimators.output`: OE and CLOE (output error).

The numerics stay pure functions on arrays (:mod:`ilic_cli.idim_ls`, :mod:`ilic_cli.idim_ilic`,
:mod:`ilic_cli.closed_loop_id`, :mod:`ilic_cli.output_error`); the estimators are thin adapters over them.
The method names, their estimators and settings types live in one registry, :mod:`ilic_cli.methods`.
"""

from ilic_cli.estimators.base import Estimator, Fit, LoopSimulator, ModelSpec, with_effects

__all__ = ["Estimator", "Fit", "LoopSimulator", "ModelSpec", "with_effects"]
