"""Model files: every accepted layout parses, bad ones give one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ilic_cli.errors import IlicError
from ilic_cli.modelfile import load_model_file, model_document, parse_model


def test_model_document_round_trip(tmp_path: Path) -> None:
    doc = model_document("rigid-offset", {"M": 95.1, "Fv": 203.5, "Fc": 20.4, "offset": -3.2}, method="IDIM-LS", effects={"spring": {"k": 50.0, "q0": 0.1}})
    p = tmp_path / "model.json"
    p.write_text(json.dumps(doc))
    parsed = load_model_file(p)
    assert parsed == {
        "model": "rigid-offset",
        "parameters": {"M": 95.1, "Fv": 203.5, "Fc": 20.4, "offset": -3.2},
        "effects": {"spring": {"k": 50.0, "q0": 0.1}},
    }


def test_identify_json_output_uses_idim_ls_section() -> None:
    parsed = parse_model({"model": "rigid", "ls": {"model": "rigid", "parameters": {"M": {"value": 95.0, "std": 0.1}}}, "ilic": None})
    assert parsed["parameters"] == {"M": 95.0}


def test_flat_layout_with_effects() -> None:
    parsed = parse_model({"M": 95, "Fv": 200, "Fc": 20, "effects": {"stribeck": {"Fs": 5, "vs": 0.01}}})
    assert parsed["parameters"] == {"M": 95.0, "Fv": 200.0, "Fc": 20.0}
    assert parsed["effects"] == {"stribeck": {"Fs": 5, "vs": 0.01}}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("{", "not valid JSON"),
        ("[1, 2]", "must hold a JSON object"),
        ('{"parameters": {"M": "heavy"}}', "parameter 'M' has no numeric value"),
        ('{"note": "nothing"}', "no 'parameters'"),
        ('{"M": 95, "effects": [1]}', "'effects' must be an object"),
    ],
)
def test_bad_model_files(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(IlicError) as err:
        load_model_file(p)
    assert message in err.value.message()
    assert err.value.message().startswith(str(p))


def test_missing_model_file(tmp_path: Path) -> None:
    with pytest.raises(IlicError, match="no such file"):
        load_model_file(tmp_path / "none.json")
