"""Shared fixtures: the command-line binary the Python results are compared with."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def crosscal_bin() -> str:
    """The `crosscal` binary: $CROSSCAL_BIN, or the repository's target/release or
    target/debug build, or one on PATH; built with cargo when there is none."""
    candidates = [os.environ.get("CROSSCAL_BIN"), ROOT / "target/release/crosscal", ROOT / "target/debug/crosscal",
                  shutil.which("crosscal")]
    for c in candidates:
        if c and Path(c).is_file():
            return str(c)
    subprocess.run(["cargo", "build", "--release", "--bin", "crosscal"], cwd=ROOT, check=True)
    return str(ROOT / "target/release/crosscal")


def run(bin_: str, *args: str, cwd=None, check=True) -> subprocess.CompletedProcess:
    """Runs the binary, returning the completed process (text output)."""
    return subprocess.run([bin_, *map(str, args)], cwd=cwd, capture_output=True, text=True, check=check)
