"""Error classes shared by every module.

Every error a user can cause (bad file, bad option value, unusable data) is an
:class:`IlicError`; the command line prints it as one line
``ilic: error: FILE: problem`` and exits with status 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class IlicError(Exception):
    """A problem with the user's input; printed as one line, exit status 2.

    Parameters
    ----------
    where : str or Path or None
        The file (or option) the problem is about; ``None`` when it has none.
    problem : str
        What is wrong and, where possible, what to do about it.
    """

    def __init__(self, where: str | Path | None, problem: str) -> None:
        self.where = None if where is None else str(where)
        self.problem = problem
        super().__init__(self.message())

    def __reduce__(self) -> tuple[object, ...]:
        """Pickle by the state, whatever the subclass's arguments (an error raised in a worker process reaches the parent whole)."""
        return (Exception.__new__, (type(self),), self.__dict__)

    def __setstate__(self, state: dict[str, Any] | None) -> None:
        self.__dict__.update(state or {})
        Exception.__init__(self, self.message())

    def message(self) -> str:
        """Return the one-line message without the ``ilic: error:`` prefix."""
        text = " ".join(self.problem.split())
        return f"{self.where}: {text}" if self.where else text


class LogError(IlicError):
    """A log file cannot be read or written, or its samples are unusable."""


class IdentificationError(IlicError):
    """Identification cannot proceed on the given data."""


class SimulationError(IlicError):
    """A simulation request is inconsistent (bad parameter, unknown scenario)."""


class DivergedError(SimulationError):
    """A simulation's state became non-finite: the plant is unstable in its loop (or on its open-loop segment).

    A candidate plant of the diagnosis whose replay diverges where the recording did not is refuted by it
    (:meth:`ilic_cli.diagnosis.heldout_replay.HeldoutReplays.fold_replay`); a replay the user asked for is an error.
    """


class ParameterError(IlicError):
    """A value breaks the rule of a parameter: the parameter, the value and the rule.

    A domain error: it names no command-line option. The command line says
    which option (or file) the value came from (:func:`ilic_cli.cli.main`
    prints it as it is when it came from a file or a fit).

    Parameters
    ----------
    parameter : str
        Its name (``Fc``, ``stribeck.vs``, ``structure``, ``effect``).
    value : object
        The offending value (``None`` when it is missing).
    rule : str
        What it must be (``>= 0``, ``one of rigid, asymmetric``).
    where : str or Path, optional
        The file the value came from.
    """

    def __init__(self, parameter: str, value: object, rule: str, where: str | Path | None = None) -> None:
        self.parameter = parameter
        self.value = value
        self.rule = rule
        shown = "" if value is None else f" = {value!r}" if isinstance(value, str) else f" = {value:g}" if isinstance(value, (int, float)) else f" = {value}"
        super().__init__(where, f"{parameter}{shown} must be {rule}")

    def at(self, where: str | Path | None) -> ParameterError:
        """The same error about ``where`` (an option or a file)."""
        return ParameterError(self.parameter, self.value, self.rule, where)


class ChoiceError(LogError):
    """A log holds several of something (joints, topics) and the reader must be told which one.

    ``choice`` names what to choose (``joint``, ``topic``); the command line
    adds the option that makes the choice.
    """

    def __init__(self, where: str | Path | None, problem: str, choice: str, candidates: tuple[str, ...] = ()) -> None:
        self.choice = choice
        self.candidates = candidates
        """What there is to choose from (the joints of a topic, the topics), when the log names them."""
        super().__init__(where, problem)
