"""The code habits of issue #26, run by ``make test``: ruff (lint and format) and pyright
(basic, on src/) are clean, and every noqa comment names its codes and says why. Each tool
is the one installed beside the running Python (the versions pinned in
requirements/lock.txt), else the one on PATH; without it the test skips and says so.
Configuration: pyproject.toml ([tool.ruff], [tool.pyright]) and typings/."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the trees ruff checks and formats
TREES = ["src", "tests", "benchmarks", "tools"]


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
    """ruff format leaves every file as it is (run `ruff format src tests benchmarks tools`)."""
    _run([_tool("ruff"), "format", "--check", *TREES], timeout=300)


@pytest.mark.slow  # about a minute on two cores
def test_pyright_is_clean():
    """pyright in basic mode on src/ ([tool.pyright]) with this Python's packages."""
    _run([_tool("pyright"), "--pythonpath", sys.executable], timeout=900)


#: the trees whose noqa comments must say why
NOQA_TREES = ["src", "tests", "benchmarks", "tools"]
#: a noqa comment as ruff finds one (a hash, maybe spaces, the word)
_NOQA = re.compile("#" + r"\s*noqa\b(?P<rest>.*)$", re.IGNORECASE)
#: what must follow the word: the codes, then a dash and the reason (ruff reads the codes and
#: stops at the dash; RUF100 in [tool.ruff.lint] flags a directive that suppresses nothing)
_REASONED = re.compile(r"^:\s*[A-Z]+[0-9]+(?:\s*,\s*[A-Z]+[0-9]+)*\s+-\s+\S")


def test_every_noqa_names_its_codes_and_says_why():
    """Each noqa comment in src/, tests/, benchmarks/ and tools/ names its codes and says
    why after a dash (``noqa: F401 - only whether it imports``, after the hash): a
    suppression is a decision, and its line says what it suppresses and why. Most are
    better fixed than excused (a ``def`` for a named lambda, E731; the import moved to the
    top, E402)."""
    bad = []
    for tree in NOQA_TREES:
        for path in sorted((ROOT / tree).rglob("*.py")):
            for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                m = _NOQA.search(line)
                if m and not _REASONED.match(m.group("rest")):
                    bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not bad, "noqa comments without their codes and a reason (noqa: E402 - why):\n" + (
        "\n".join(bad)
    )


# ------------------------------------------------------------------ test files' names
#: what a test file may be named after besides a module of flexarm: the documentation
#: (docs/, README.md, the notebooks) and the code habits of every tree (this file)
OUTSIDE_THE_PACKAGE = {"docs", "habits"}


def _module_names() -> tuple[set[str], dict[str, set[str]]]:
    """(full, tails): every module and subpackage of flexarm as its dotted path below
    flexarm with ``_`` for ``.`` (``identification_frequency_domain_harmonics``; the package
    itself ``flexarm``), and each tail of those paths (``frequency_domain_harmonics``,
    ``harmonics``) → the full names that end with it."""
    pkg = ROOT / "src" / "flexarm"
    full, tails = {"flexarm"}, {}
    for path in pkg.rglob("*.py"):
        parts = path.relative_to(pkg).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if not parts or parts[-1] == "__main__":
            continue
        name = "_".join(parts)
        full.add(name)
        for i in range(len(parts)):
            tails.setdefault("_".join(parts[i:]), set()).add(name)
    return full, tails


def test_every_test_file_is_named_after_what_it_tests():
    """The rule: ``tests/test_<name>.py`` or ``tests/test_<name>__<topic>.py``, where
    <name> is a module or subpackage of flexarm, its dotted path below flexarm with ``_``
    for ``.`` (``design_gate`` for flexarm.design.gate; ``flexarm`` for the package's
    public face), or a tail of that path that no other module shares (``harmonics`` for
    identification.frequency_domain.harmonics; ``io_logs``, not ``logs``, which
    identification.time_domain.logs shares), or ``docs`` / ``habits``
    (:data:`OUTSIDE_THE_PACKAGE`). ``__<topic>``, after a double underscore, names a
    further file about the same module (``test_io_logs__properties.py``). A test that
    runs through several modules (an acceptance run, the CLI on a real rig) is named after
    the module it mainly exercises. Helpers without tests keep a leading underscore
    (``_helpers.py``)."""
    full, tails = _module_names()
    bad = []
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        name, sep, topic = path.stem.removeprefix("test_").partition("__")
        if sep and (not topic or "__" in topic):
            bad.append(f"{path.name}: one __<topic> after the name")
        elif name in full or name in OUTSIDE_THE_PACKAGE:
            continue
        elif len(tails.get(name, ())) == 1:
            continue
        elif name in tails:
            bad.append(f"{path.name}: {name!r} is shared by {', '.join(sorted(tails[name]))}")
        else:
            bad.append(f"{path.name}: no module of flexarm is named {name!r}")
    assert not bad, "test files not named after a module (tests/test_habits.py):\n" + (
        "\n".join(bad)
    )
