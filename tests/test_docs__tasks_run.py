"""The task pages run as written (issue #46 item 2): every ```console / ``` shell command
and ```python block of each page, in order, in a fresh folder (exit 0 each), as
tests/test_docs__readme_runs.py does for the README. The repository's `examples/` is
linked into the folder as a fresh clone has it; a page that reads `../shared/data/...`
gets the lab's data linked beside the folder where this checkout has it (FLEXARM_DATA,
default ../shared/data), and skips otherwise. Where a page draws 200 plants for a design
(minutes each), the test draws 5: the same commands, cheaper.

Not covered (real-data fits of minutes each): docs/tasks/fit-rotary-rig.md and
docs/tasks/fit-two-link-rig.md."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from test_docs__readme_runs import blocks

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("FLEXARM_DATA", ROOT.parent / "shared" / "data")).resolve()
PAGES = [
    "docs/getting-started.md",
    "docs/tasks/simulate.md",
    "docs/tasks/reproduce.md",
    "docs/tasks/design-export.md",
    "docs/tasks/frequency-domain.md",
]


def _run(code: str, kind: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    if kind == "shell":
        argv = shlex.split(code.replace("--plants 200", "--plants 5"))
        if argv[0] == "flexarm":
            argv = [sys.executable, "-m", "flexarm", *argv[1:]]
    else:
        argv = [sys.executable, "-c", code]
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True)


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_the_page_runs_as_written_in_a_fresh_folder(page, tmp_path):
    text = (ROOT / page).read_text()
    clone = tmp_path / "clone"
    clone.mkdir()
    (clone / "examples").symlink_to(ROOT / "examples")
    if "../shared/data" in text:
        if not DATA.is_dir():
            pytest.skip(f"{page} reads ../shared/data: not in this checkout ({DATA})")
        (tmp_path / "shared").mkdir()
        (tmp_path / "shared" / "data").symlink_to(DATA)
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    found = blocks(text)
    assert found, page
    for kind, code in found:
        r = _run(code, kind, clone, env)
        assert r.returncode == 0, f"{page}: {code}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
