"""The names of the identification methods, without their estimators: what a command's ``--help`` lists.

:mod:`ilic_cli.methods` binds each name to its estimator, importing numpy and the numerics; the help of ``ilic
batch`` needs only the names and imports none of them.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Composite:
    """A ``--method`` value that runs several methods; the model file takes ``model_from``'s estimate."""

    name: str
    methods: tuple[str, ...]
    model_from: str
    description: str


COMPOSITES: dict[str, Composite] = {
    c.name: c
    for c in (
        Composite("both", ("ls", "ilic"), "ls", "IDIM-LS and IDIM-ILIC per window"),
        Composite("all", ("ls", "ilic", "didim", "iv"), "didim", "every inverse-model and closed-loop method (IDIM-ILIC when usable)"),
    )
}
"""Names that run several methods."""

CHOICES: tuple[str, ...] = ("ls", "ilic", "both", "didim", "iv", "all", "oe", "cloe")
"""Values of ``--method`` and of ``identify(method=...)``: the methods and the composites, in the help's order
(every name of :data:`ilic_cli.methods.METHODS` and of :data:`COMPOSITES`, checked by tests/identify/test_methods.py)."""


OUTPUT_ERROR: tuple[str, ...] = ("oe", "cloe")
"""The output-error methods (:attr:`ilic_cli.methods.Method.output_error`, checked by tests/identify/test_methods.py)."""


def choices(*, output_error: bool = True) -> tuple[str, ...]:
    """:data:`CHOICES`, without the output-error methods unless ``output_error`` (``ilic batch`` runs none)."""
    return tuple(c for c in CHOICES if output_error or not set(COMPOSITES[c].methods if c in COMPOSITES else (c,)) & set(OUTPUT_ERROR))
