"""The README runs as written (issue #46 item 2): every ```console / ``` shell command and
every ```python block of README.md, in order, in a fresh folder (exit 0 each). The
repository's `examples/` is linked into the folder, as a fresh clone has it; the logs come
from `flexarm example-logs`, not the lab's data. Commands run through this interpreter's
`python -m flexarm` (`flexarm` on the PATH of a user's venv)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
#: block kinds that hold shell commands; the plain ``` blocks are shell too except the
#: Makefile targets (make demo / make test run for minutes: the suite checks them elsewhere)
SHELL = {"console", "", "sh", "bash", "shell"}


def blocks(text: str) -> list[tuple[str, str]]:
    """(kind, code) of each runnable block: ("shell", one command with its continuation
    lines joined) or ("python", the block)."""
    out = []
    for lang, body in FENCE.findall(text):
        if lang == "python":
            out.append(("python", body))
        elif lang in SHELL:
            joined = re.sub(r"\\\n\s*", " ", body)
            for line in joined.splitlines():
                line = re.sub(r"^\$ ", "", line.split("  #")[0]).strip()
                if line and not line.startswith("make "):
                    out.append(("shell", line))
    return out


def test_the_readme_blocks_are_found():
    """The extraction sees the chain: fit, design, export-c, the Python block."""
    found = blocks((ROOT / "README.md").read_text())
    cmds = [c for k, c in found if k == "shell"]
    assert any(c.startswith("flexarm fit example-logs/") for c in cmds), cmds
    assert any(c.startswith("flexarm design rig.toml") for c in cmds), cmds
    assert any(c.startswith("flexarm export-c out/lqr") for c in cmds), cmds
    assert sum(k == "python" for k, _ in found) >= 1


@pytest.mark.slow
def test_the_readme_runs_as_written_in_a_fresh_folder(tmp_path):
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    env = dict(os.environ, MPLBACKEND="Agg")
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    ran = []
    for kind, code in blocks((ROOT / "README.md").read_text()):
        if kind == "shell":
            argv = shlex.split(code)
            if argv[0] == "flexarm":
                argv = [sys.executable, "-m", "flexarm", *argv[1:]]
        else:
            argv = [sys.executable, "-c", code]
        r = subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True)
        assert r.returncode == 0, f"{code}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
        ran.append(code)
    assert (tmp_path / "target" / "rig.h").is_file() and (tmp_path / "arm.png").is_file()
    assert (tmp_path / "out" / "lqr" / "design.toml").is_file()
    # the Python block runs a second time (nothing it writes blocks it)
    py = [c for k, c in blocks((ROOT / "README.md").read_text()) if k == "python"]
    for code in py:
        r = subprocess.run(
            [sys.executable, "-c", code], cwd=tmp_path, env=env, text=True, capture_output=True
        )
        assert r.returncode == 0, r.stderr[-3000:]
