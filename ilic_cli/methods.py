"""The one registry of identification methods: name -> estimator, settings type, description.

The command line's ``--method`` choices, :func:`ilic_cli.identify.identify`'s composites (``both``, ``all``), the
reports' order and the docs read the names from here. The closed-loop estimators are bound to the plant's loop
simulation (:data:`ilic_cli.simulation.loop.PLANT_LOOP`) here, which ranks this module in the simulation layer;
the plant itself is imported only when a replay runs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ilic_cli.closed_loop_id import METHODS as CLOSED_LOOP_LABELS
from ilic_cli.estimators.base import Estimator, LoopSimulator
from ilic_cli.estimators.closed_loop import ClosedLoop, ClosedLoopFitSettings
from ilic_cli.estimators.inverse import IDIMILIC, IDIMLS
from ilic_cli.estimators.output import OutputError, OutputErrorFitSettings
from ilic_cli.idim_ilic import ILICSettings
from ilic_cli.idim_ls import LSSettings
from ilic_cli.method_names import CHOICES, COMPOSITES, OUTPUT_ERROR, Composite, choices
from ilic_cli.output_error import METHODS as OUTPUT_ERROR_LABELS
from ilic_cli.simulation.loop import PLANT_LOOP


@dataclass(frozen=True)
class Method:
    """One identification method.

    Attributes
    ----------
    name : str
        The ``--method`` value and the report's key (``ls``, ``ilic``, ``didim``, ``iv``, ``oe``, ``cloe``).
    label : str
        The name reports use (``IDIM-LS``, ...).
    description : str
        One line for the help and the docs.
    settings : type
        The settings type its ``fit`` takes.
    estimator : callable
        ``(loop) -> Estimator``: the estimator, handed the loop simulation where the method simulates the plant
        (:meth:`bind`: the plant's by default).
    closed_loop : bool
        It simulates the loop that ran: the log must record its controller and reference.
    takes_effects : bool
        Effects' columns may join its model (IDIM-ILIC's windows identify the structure's own parameters only).
    starts_from_ls : bool
        It starts from the IDIM-LS estimate, which is run and reported beside it.
    output_error : bool
        An output-error fit: one contiguous recording; its standard deviations go to the model file, and each
        validation log gets the benchmark's open-loop figure.
    runs_last : bool
        It runs after the others (IDIM-ILIC: its warnings follow theirs).
    """

    name: str
    label: str
    description: str
    settings: type
    estimator: Callable[[LoopSimulator], Estimator[Any]]
    closed_loop: bool = False
    takes_effects: bool = True
    starts_from_ls: bool = False
    output_error: bool = False
    runs_last: bool = False

    def bind(self, loop: LoopSimulator = PLANT_LOOP) -> Estimator[Any]:
        """The estimator, its loop simulation ``loop`` (the plant's by default)."""
        return self.estimator(loop)


METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method(
            "ls", "IDIM-LS", "inverse model, least squares on the filtered, differentiated position (paper section III)", LSSettings, lambda _loop: IDIMLS()
        ),
        Method(
            "ilic",
            "IDIM-ILIC",
            "inverse model per window on the reference trajectory (paper section V)",
            ILICSettings,
            lambda _loop: IDIMILIC(),
            takes_effects=False,
            runs_last=True,
        ),
        Method(
            "didim",
            CLOSED_LOOP_LABELS["didim"],
            "closed-loop output error of the force, Gauss-Newton on replays of the loop, from IDIM-LS",
            ClosedLoopFitSettings,
            lambda loop: ClosedLoop("didim", loop),
            closed_loop=True,
            starts_from_ls=True,
        ),
        Method(
            "iv",
            CLOSED_LOOP_LABELS["iv"],
            "instrumental variables from replays of the loop, from IDIM-LS",
            ClosedLoopFitSettings,
            lambda loop: ClosedLoop("iv", loop),
            closed_loop=True,
            starts_from_ls=True,
        ),
        Method(
            "oe",
            OUTPUT_ERROR_LABELS["oe"],
            "open-loop output error of the position, the recorded drive command in (docs/output-error.md)",
            OutputErrorFitSettings,
            lambda loop: OutputError("oe", loop),
            starts_from_ls=True,
            output_error=True,
        ),
        Method(
            "cloe",
            OUTPUT_ERROR_LABELS["cloe"],
            "closed-loop output error of the position (and force), the log's reference through its controller",
            OutputErrorFitSettings,
            lambda loop: OutputError("cloe", loop),
            closed_loop=True,
            starts_from_ls=True,
            output_error=True,
        ),
    )
}
"""Every method, in the order reports list them (the names and the composites: :mod:`ilic_cli.method_names`)."""

__all__ = ["CHOICES", "COMPOSITES", "METHODS", "OUTPUT_ERROR", "Composite", "Method", "choices", "effect_methods", "label", "methods_of", "model_method"]


def methods_of(choice: str) -> tuple[str, ...]:
    """The methods a ``--method`` value runs, in the order they run: IDIM-LS first when another starts from it, IDIM-ILIC last."""
    asked = COMPOSITES[choice].methods if choice in COMPOSITES else (choice,)
    runs = (["ls"] if "ls" not in asked and any(METHODS[m].starts_from_ls for m in asked) else []) + list(asked)
    return tuple(sorted(runs, key=lambda m: METHODS[m].runs_last))


def model_method(choice: str) -> str:
    """The method whose estimate the model file takes for a ``--method`` value (a composite's choice, or the method itself)."""
    return COMPOSITES[choice].model_from if choice in COMPOSITES else choice


def effect_methods() -> str:
    """The methods whose model effects' columns may join, as an error message lists them (``'ls', 'didim', ... or 'cloe'``)."""
    names = [f"'{m}'" for m, entry in METHODS.items() if entry.takes_effects]
    return ", ".join(names[:-1]) + " or " + names[-1]


def label(name: str) -> str:
    """The name reports use for method ``name``."""
    return METHODS[name].label
