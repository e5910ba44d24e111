"""The documentation site (mkdocs.yml, docs/): it builds with warnings as errors, every
repository path its pages name exists, and every ``flexarm ...`` command they show is a
command whose ``--help`` lists each option used."""

from __future__ import annotations

import glob
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import DATA, ROOT

pytest.importorskip("mkdocs", reason="the docs extra is not installed")

DOCS = ROOT / "docs"
PAGES = sorted(DOCS.rglob("*.md"))
NOTEBOOKS = sorted((DOCS / "notebooks").glob("*.ipynb"))

#: a repository path: known top folders, or a module path under src/flexarm (architecture
#: map), or the shared data; ends in a file name with an extension, or a folder "/"
_PATH = re.compile(
    r"(?<![\w./-])((?:\.\./shared/|examples/|src/|docs/|tools/|tests/|"
    r"benchmarks/|requirements/|[a-z_]+/)[\w*.\-/]*\.(?:py|toml|md|txt|mat|"
    r"csv|yaml|yml|ipynb))(?![\w/])"
)
_CODE_SPAN = re.compile(r"`([^`\n]+)`")
_FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)


def _texts() -> list[tuple[str, str]]:
    """(name, text) of every page and of every notebook cell's source."""
    out = [(str(p.relative_to(ROOT)), p.read_text()) for p in PAGES]
    for nb in NOTEBOOKS:
        cells = json.loads(nb.read_text())["cells"]
        out += [(f"{nb.relative_to(ROOT)}#{c['id']}", "".join(c["source"])) for c in cells]
    return out


def _resolve(token: str) -> list[Path] | None:
    """Where a named path may live; None when it is on the absent shared data."""
    if token.startswith("../shared/data/"):
        if not DATA.is_dir():
            return None
        return [DATA / token.removeprefix("../shared/data/")]
    if token.startswith(("shared/", "../shared/")):  # the project's shared folder
        shared = ROOT.parent / "shared"
        return [shared / token.split("shared/", 1)[1]] if shared.is_dir() else None
    return [ROOT / token, ROOT / "src" / token, ROOT / "src" / "flexarm" / token, DOCS / token]


def _exists(p: Path) -> bool:
    return bool(glob.glob(str(p))) if "*" in str(p) else p.exists()


def test_every_named_path_exists():
    missing = []
    for name, text in _texts():
        for token in sorted(set(_PATH.findall(text))):
            where = _resolve(token)
            if where is not None and not any(_exists(p) for p in where):
                missing.append(f"{name}: {token}")
    assert not missing, "paths named in the docs that do not exist:\n" + "\n".join(missing)


def commands() -> list[tuple[str, str]]:
    """(where, command line) of every ``flexarm ...`` in a code block or a code span."""
    out = []
    for name, text in _texts():
        blocks = [b.replace("\\\n", " ") for b in _FENCE.findall(text)]
        lines = [ln.strip().removeprefix("$ ") for b in blocks for ln in b.splitlines()]
        prose = _FENCE.sub("", text)
        lines += [s.strip() for s in _CODE_SPAN.findall(prose)]
        out += [(name, ln) for ln in lines if re.match(r"flexarm [a-z]", ln)]
    return out


def test_docs_name_commands():
    assert len(commands()) >= 10


@pytest.fixture(scope="module")
def cli_help():
    """``flexarm SUB --help`` as text, whitespace and box drawing removed (so that a
    wrapped table still holds each option name whole)."""
    from typer.testing import CliRunner

    from flexarm.cli import app

    runner, cache = CliRunner(), {}

    def get(sub: str) -> tuple[int, str]:
        if sub not in cache:
            r = runner.invoke(
                app, [sub, "--help"], terminal_width=250, env={"COLUMNS": "250", "NO_COLOR": "1"}
            )
            cache[sub] = (r.exit_code, re.sub(r"[\s│╭╮╰╯─]+", "", r.output))
        return cache[sub]

    return get


def test_every_command_parses(cli_help):
    bad = []
    for where, line in commands():
        words = shlex.split(line.replace("...", ""), comments=True)
        sub = words[1]
        code, text = cli_help(sub)
        if code != 0:
            bad.append(f"{where}: `{line}`: no command {sub!r}")
            continue
        for w in words[2:]:
            opt = w.split("=", 1)[0]
            if re.fullmatch(r"--[a-z][\w-]*", opt) and opt not in text:
                bad.append(f"{where}: `{line}`: flexarm {sub} has no option {opt}")
    assert not bad, "\n".join(bad)


def test_site_builds_strict(tmp_path):
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(
            [str(ROOT / "src")]
            + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        ),
        "NO_MKDOCS_2_WARNING": "1",
        "FLEXARM_DOCS_EXECUTE": "false",
    }
    site = tmp_path / "site"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(ROOT / "mkdocs.yml"),
            "-d",
            str(site),
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-4000:]
    assert "WARNING" not in r.stderr
    # the generated pages hold what they are generated from
    scen = (site / "scenarios" / "index.html").read_text()
    assert (
        "[arm.motor] drive = &quot;voltage&quot;" in scen or '[arm.motor] drive = "voltage"' in scen
    )
    sim = (site / "api" / "sim" / "index.html").read_text()
    assert "flexarm.sim.result.SimulationResult" in sim
    assert ":class:`" not in sim and ":func:`" not in sim  # Sphinx roles shown as code
    top = (site / "api" / "index.html").read_text()
    for name in ("simulate", "load_scenario", "tfest"):
        assert f"flexarm.{name}" in top
    for nb in NOTEBOOKS:
        assert (site / "notebooks" / nb.stem / "index.html").is_file()
    assert "Unreleased" in (site / "changelog" / "index.html").read_text()
    # the build helpers beside the pages are not pages (mkdocs-jupyter reads .py as notebooks)
    assert not (site / "make_notebooks").exists() and not (site / "hooks").exists()
