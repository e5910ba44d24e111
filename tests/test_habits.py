"""The code habits of issue #26, run by ``make test``: ruff (lint and format) and pyright
(basic, on src/) are clean. Each tool is the one installed beside the running Python (the
versions pinned in requirements/lock.txt), else the one on PATH; without it the test skips
and says so. Configuration: pyproject.toml ([tool.ruff], [tool.pyright]) and typings/."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the trees ruff checks and formats
TREES = ["src", "tests", "benchmarks"]


def _tool(name: str) -> str:
    """The executable ``name`` next to this Python (the project's .venv), else on PATH;
    the test skips without it."""
    here = Path(sys.executable).parent / name
    if here.is_file():
        return str(here)
    found = shutil.which(name)
    if found is None:
        pytest.skip(
            f"{name} is not installed (neither beside {sys.executable} nor on PATH): "
            "install the [test] extra (make test does)"
        )
    return found


def _run(cmd: list[str], timeout: float) -> None:
    """Run ``cmd`` from the repository root; fail with its output unless it exits 0."""
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, f"{' '.join(cmd)} exited {p.returncode}:\n{p.stdout}\n{p.stderr}"


def test_ruff_check_is_clean():
    _run([_tool("ruff"), "check", *TREES], timeout=300)


def test_ruff_format_is_clean():
    """ruff format leaves every file as it is (run `ruff format src tests benchmarks`)."""
    _run([_tool("ruff"), "format", "--check", *TREES], timeout=300)


@pytest.mark.slow  # about a minute on two cores
def test_pyright_is_clean():
    """pyright in basic mode on src/ ([tool.pyright]) with this Python's packages."""
    _run([_tool("pyright"), "--pythonpath", sys.executable], timeout=900)
