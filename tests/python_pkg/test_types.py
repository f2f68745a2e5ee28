"""The package's types (issue 30): mypy finds no error in python/tortwin,
with the configuration of python/pyproject.toml ([tool.mypy]: checked as
Python 3.10) and the extension's stubs, tortwin/_native.pyi. It checks the
source tree, not the installed package."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import REPO

PYTHON = REPO / "python"


def test_mypy_finds_no_error_in_the_package(tmp_path: Path):
    done = subprocess.run(
        [
            sys.executable, "-m", "mypy",
            "--config-file", str(PYTHON / "pyproject.toml"),
            # The cache outside the repository: a clean tree, a full check.
            "--cache-dir", str(tmp_path / "mypy-cache"),
            "tortwin",
        ],
        cwd=PYTHON,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, f"mypy exit status {done.returncode}:\n{done.stdout}{done.stderr}"
