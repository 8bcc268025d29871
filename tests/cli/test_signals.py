"""Interrupted runs: SIGTERM -> exit 143, SIGINT (Ctrl-C) -> exit 130, and no partial output.

A real ``python -m ilic_cli convert big.mat OUT`` is started; once its temporary
output (``.OUT.*.tmp`` beside the target) exists and is being written, the
signal is sent. Neither the output nor the temporary file may remain.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ilic_cli.io import write_log
from tests.conftest import make_synthetic_log

ROOT = Path(__file__).parents[2]
SAMPLES = 500_000  # a .mat that takes about a second to write as MCAP or a bag


@pytest.fixture(scope="module")
def big_mat(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(make_synthetic_log(samples=SAMPLES), tmp_path_factory.mktemp("big") / "big.mat")


def _default_sigint() -> None:
    # a background shell starts children with SIGINT ignored; Ctrl-C must reach ilic
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize(("sig", "status", "word"), [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")], ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("target", ["out.mcap", "out_bag"])
def test_interrupted_convert_leaves_nothing(tmp_path: Path, big_mat: Path, sig: int, status: int, word: str, target: str) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "ilic_cli", "convert", str(big_mat), str(out_dir / target)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
        env=env,
        preexec_fn=_default_sigint,
    )
    try:
        deadline = time.monotonic() + 60
        started = False
        while time.monotonic() < deadline and proc.poll() is None:
            temps = list(out_dir.glob(f".{target}.*.tmp"))
            if temps and any((p.is_file() and p.stat().st_size > 0) or (p.is_dir() and any(p.rglob("*"))) for p in temps):
                started = True
                break
            time.sleep(0.01)
        assert started, f"the temporary output never appeared (status {proc.poll()})"
        time.sleep(0.05)  # well inside the write (MCAP: ~0.5 s for these samples)
        assert proc.poll() is None, "the conversion finished before the signal; use a bigger log"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = err.decode("utf-8", "replace")
    assert proc.returncode == status, text
    assert text.strip().splitlines()[-1] == f"ilic: {word}", text
    assert "Traceback" not in text
    assert list(out_dir.iterdir()) == []  # neither OUT nor the temporary file or folder
    assert big_mat.exists()
