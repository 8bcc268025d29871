"""The friction law's smoothing speed and the Stribeck friction beside it, fitted at once on the closed loop (issue 29).

The friction law near zero speed (:mod:`ilic_cli.diagnosis.friction_law`) is read before any effect is proposed, with the model
the loop's timing was read with. A Stribeck friction the simulator has beside it is then not in that model, and the law's
smoothing speed ``vc`` takes part of it: more friction at low speed reads as a steeper ``tanh``. On the independent simulator's
12 kg trapezoid at 1 kHz (``Fc tanh(v/vc)`` with ``vc`` = 2.5 mm/s, a Stribeck peak 2 N above Coulomb's 4 N at ``vs`` = 10
mm/s) the law was read at 0.99 mm/s, and the Stribeck friction named at that law came out at 0.45 N and 20 mm/s; with the
law at its true speed the same diagnosis finds 1.95 N and 11 mm/s. The two couple along a valley of the closed-loop output
error (a lower ``vc``, a lower and wider peak), so neither is fitted well alone.

So once the replay has kept a Stribeck friction and the replays run a smoothed law, :func:`refit_with_the_law` fits the
linear parameters, every searched value of the kept effects and ``vc`` at once on the closed-loop output error
(:func:`~ilic_cli.diagnosis.oe_fit.output_error_refit`, ``vc`` an :class:`~ilic_cli.diagnosis.oe_fit.ExtraValue` within
the law's grid), from the refit's estimate when it has one, else the inverse model's (a level held at the dwells joins as
a column). Unlike at a stick/slip dwell, the creep there is the law's, which the noise-free replays have
(:func:`ilic_cli.diagnosis.refit.refit`'s reason not to refit a Stribeck friction found at the dwells does not hold).
The fit is kept on the terms of every output-error refit (it lowers the output error by the settings' ``refit_round_gain``
of it, ends inside every range and is a plant of its effects) and when its replay's position error is no higher (the law
was read on it); the law then runs at the ``vc`` found. Measured there: the output error 0.298 % -> 0.191 % (5 iterations,
51 replays), ``vc`` 2.17 mm/s, Fs 1.75 N, ``vs`` 10.7 mm/s. On the independent simulator's 12 Stribeck logs with tanh
friction (``benchmarks/corpus_independent.py``): 11 within 15 %, the 12 kg trapezoid at 500 Hz 20 % (before: 50-100 % off).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ilic_cli.diagnosis.closed_loop_refit import ReplayLoop
from ilic_cli.diagnosis.decide import Decision
from ilic_cli.diagnosis.fits import Refit
from ilic_cli.diagnosis.friction_law import SMOOTHING, FrictionLaw, smoothing_grid, speed_text, with_friction_law
from ilic_cli.diagnosis.oe_fit import ExtraValue, output_error_refit
from ilic_cli.diagnosis.propose import Proposal
from ilic_cli.diagnosis.refit import FinalFit, columns_held, value_grids
from ilic_cli.diagnosis.settings import DiagnosisSettings
from ilic_cli.diagnosis.system import extended
from ilic_cli.diagnosis.verdicts import RefitOutcome
from ilic_cli.effects import unit_on
from ilic_cli.lsq import norm_pct
from ilic_cli.runlog import RunLog
from ilic_cli.simulation.replay import relative_errors, replay

COUPLED = ("stribeck",)
"""The kept effects whose values couple with the law's ``vc`` (friction that acts near zero speed)."""


def refit_with_the_law(
    log: RunLog, prop: Proposal, decision: Decision, final: FinalFit, refit: Refit | None, law: FrictionLaw, settings: DiagnosisSettings, replayed: bool
) -> tuple[Refit | None, FrictionLaw, RunLog]:
    """The refit, the law and the log its replays run, with ``vc`` and the kept effects fitted at once (module docstring); the
    ones given when the law is stick/slip, no effect of :data:`COUPLED` is kept, a friction drift is found (the refit's plant
    has none), or the fit is not kept (the refit's reason then says why)."""
    kept, known = decision.kept, prop.known
    drift = refit is not None and refit.outcome in (RefitOutcome.DRIFT, RefitOutcome.DRIFT_VALUES)
    if law.vc is None or not replayed or drift or not any(st.effect.id in COUPLED for st in kept):
        return refit, law, log
    if refit is not None and refit.accepted and refit.theta is not None:
        steps, theta0 = list(refit.steps), refit.theta
    else:
        steps, theta0 = columns_held(kept, final)
    data, ls = prop.data, settings.ls
    model = [*known, *steps]
    names = extended(prop.base, model, data.fs_hz).names
    grids = value_grids(data, steps)
    loop = ReplayLoop(log, prop.prepared, prop.base, ls, lambda params, effects: replay(log, params, effects), prop.hold)
    start = loop.replayed(model, names, theta0, law.effects())
    if start is None:
        return refit, law, log
    error0 = norm_pct(float(np.linalg.norm(loop.residual(start))), loop.y_norm)
    grid = smoothing_grid(data.kin)
    vc = ExtraValue(SMOOTHING, "vc", unit_on("m/s", law.joint), law.vc, (float(grid[0]), float(grid[-1])))
    oe = output_error_refit(
        known,
        model,
        names,
        theta0,
        grids,
        lambda s, th, extra: loop.residual_of(s, names, th, {SMOOTHING: {"vc": extra[0]}}),
        error0,
        loop.y_norm,
        settings.refit_round_gain,
        loop.joint,
        lead="with the friction law's smoothing speed, refitted by",
        extra=[vc],
    )
    why = "the friction law's smoothing speed and the effects beside it not refitted at once"
    if isinstance(oe, str):
        return _noted(refit, f"{why}: {oe}"), law, log
    found = float(oe.searches[-1].value)
    final_sim = loop.replayed([*known, *oe.steps], names, oe.theta if oe.theta is not None else theta0, {SMOOTHING: {"vc": found}})
    before, after = relative_errors(log, start, ls), None if final_sim is None else relative_errors(log, final_sim, ls)
    if after is None or after["position"] > before["position"]:
        moved = "it does not replay" if after is None else f"its replay's position error rises ({before['position']:.3g} % -> {after['position']:.3g} %)"
        return _noted(refit, f"{why}: {moved}"), law, log
    oe.error_inverse_pct, oe.simulated = error0, final_sim
    moved = f"vc {speed_text(law.vc, law.joint)} -> {speed_text(found, law.joint)}"
    new_law = replace(law, vc=found, after=after, reason=f"{law.reason}; refitted at once with the Stribeck friction beside it on the closed loop: {moved}")
    return oe, new_law, with_friction_law(log, new_law)


def _noted(refit: Refit | None, why: str) -> Refit | None:
    """``refit`` with ``why`` added to its reason (``None`` stays ``None``)."""
    return None if refit is None else replace(refit, reason=f"{refit.reason}; {why}")
