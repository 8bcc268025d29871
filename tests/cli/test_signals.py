"""Interrupted runs: SIGTERM -> exit 143, SIGINT (Ctrl-C) -> exit 130, and no partial output.

A real ``python -m ilic_cli convert big.mat OUT`` is started; once its temporary
output (``.OUT.*.tmp`` beside the target) exists and is being written, the
signal is sent. Neither the output nor the temporary file may remain.
"""

from __future__ import annotations

import os
import shutil
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


def _being_written(temps: list[Path]) -> bool:
    """Whether a temporary output holds something yet; one renamed or removed since it was listed holds nothing."""
    try:
        return any((p.is_file() and p.stat().st_size > 0) or (p.is_dir() and any(p.rglob("*"))) for p in temps)
    except FileNotFoundError:  # the conversion renamed its temporary output between the listing and this look
        return False


def _caught_writing(big_mat: Path, out: Path) -> subprocess.Popen[bytes] | None:
    """``ilic convert big_mat out`` started and seen writing its temporary output; ``None`` when it finished before it was
    seen (its output then removed): on a loaded machine this polling can miss the whole write."""
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "ilic_cli", "convert", str(big_mat), str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=ROOT,
        env=env,
        preexec_fn=_default_sigint,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if _being_written(list(out.parent.glob(f".{out.name}.*.tmp"))):
            time.sleep(0.05)  # well inside the write (MCAP: ~0.5 s for these samples)
            if proc.poll() is None:
                return proc
            break
        time.sleep(0.01)
    if proc.poll() is None:
        proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode in (0, -signal.SIGKILL), proc.returncode
    for p in out.parent.iterdir():  # a finished conversion's output, for the next attempt
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    return None


@pytest.mark.parametrize(("sig", "status", "word"), [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")], ids=["SIGTERM", "SIGINT"])
@pytest.mark.parametrize("target", ["out.mcap", "out_bag"])
def test_interrupted_convert_leaves_nothing(tmp_path: Path, big_mat: Path, sig: int, status: int, word: str, target: str) -> None:
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    proc = None
    for _ in range(3):
        proc = _caught_writing(big_mat, out_dir / target)
        if proc is not None:
            break
    assert proc is not None, "three conversions finished before their temporary output was seen being written; use a bigger log"
    try:
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
