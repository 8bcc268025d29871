"""The error classes survive pickling: an error raised in a worker process (the corpus benchmark's pool) reaches the parent whole."""

from __future__ import annotations

import pickle

import pytest

from ilic_cli.errors import ChoiceError, IdentificationError, IlicError, ParameterError


@pytest.mark.parametrize(
    "error",
    [
        IlicError("log.csv", "the column tau is missing"),
        IdentificationError(None, "only 12 usable rows"),
        ParameterError("Fc", -1.0, ">= 0", "model.json"),
        ChoiceError("run.bag", "it holds 2 joints", "--joint"),
    ],
)
def test_errors_pickle_whole(error: IlicError) -> None:
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error)
    assert back.message() == error.message() and str(back) == str(error)
    assert back.__dict__ == error.__dict__
