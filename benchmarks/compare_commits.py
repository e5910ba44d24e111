"""Run benchmarks on an old commit and on the working tree, side by side, in one run.

The old commit's tree is exported with ``git archive`` into a temporary folder (no worktree
is registered, nothing in the repository changes); each benchmark is then run as that
commit's own script on that commit's code, and as the working tree's script on the working
tree's code, alternating (old, new, old, new, ...) so that both see the same machine load.
The figures each script prints are shown one after the other, and the lines both print
with a number in ms are put in a table with the ratio new/old (best of the repeats).

Run:  PYTHONPATH=src python benchmarks/compare_commits.py [--commit 2e2a450]
          [--repeat 2] [bench_single_link.py bench_multilink.py]

(2e2a450 is the last commit before the redesign of issue #13; docs/performance.md has the
figures measured with this script.)
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def export(commit: str, dest: Path) -> Path:
    """The tree of ``commit`` under ``dest`` (git archive | tar)."""
    archive = dest / "tree.tar"
    with open(archive, "wb") as fh:
        subprocess.run(["git", "-C", str(ROOT), "archive", commit], stdout=fh, check=True)
    with tarfile.open(archive) as tar:
        tar.extractall(dest / "tree", filter="data")
    shared = ROOT.parent / "shared"
    if shared.is_dir():  # the real data beside the old tree too (bench_real_fit.py)
        (dest / "shared").symlink_to(shared)
    return dest / "tree"


def run(tree: Path, script: str) -> str:
    env = dict(os.environ, PYTHONPATH=str(tree / "src"))
    out = subprocess.run(
        [sys.executable, str(tree / "benchmarks" / script)],
        env=env,
        capture_output=True,
        text=True,
        cwd=tree,
    )
    if out.returncode != 0:
        return out.stdout + out.stderr + f"\n[exit {out.returncode}]"
    return out.stdout


def figures(text: str) -> dict[str, float]:
    """label → value in ms of every printed line that holds a time (first number)."""
    found = {}
    for line in text.splitlines():
        m = re.match(
            r"^\s{2,}(?P<label>[A-Za-z][^:]*?(?::[^\d]*?)?)\s+(?P<value>\d+(?:\.\d+)?)\s*"
            r"(?P<unit>ms|s)\b(?P<rest>.*)$",
            line,
        )
        if not m:
            continue
        label, value = m["label"].strip(), float(m["value"])
        value *= 1e3 if m["unit"] == "s" else 1.0
        per = re.search(r"(\d+(?:\.\d+)?) ms per rollout", m["rest"])
        cpu = re.search(r"\(CPU (\d+(?:\.\d+)?) ms", m["rest"])
        found[label] = value
        if per:
            found[label + " (per rollout)"] = float(per.group(1))
        if cpu:  # CPU time of the process: less sensitive to other jobs on the machine
            found[label + (" (per rollout, CPU)" if per else " (CPU)")] = float(cpu.group(1))
    return found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--commit", default="2e2a450", help="the old commit (default 2e2a450)")
    ap.add_argument("--repeat", type=int, default=2, help="runs of each side (default 2)")
    ap.add_argument("scripts", nargs="*", default=["bench_single_link.py", "bench_multilink.py"])
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        old_tree = export(args.commit, Path(tmp))
        head = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        for script in args.scripts:
            best = {"old": {}, "new": {}}
            for k in range(args.repeat):
                for side, tree in (("old", old_tree), ("new", ROOT)):
                    text = run(tree, script)
                    which = args.commit if side == "old" else head + " + working tree"
                    print(
                        f"===== {script}, {side} ({which}), "
                        f"run {k + 1}/{args.repeat}, load {os.getloadavg()[0]:.1f}\n{text}"
                    )
                    for label, v in figures(text).items():
                        best[side][label] = min(v, best[side].get(label, float("inf")))
            print(f"----- {script}: best of {args.repeat} (ms), new / old")
            for label in best["old"]:
                if label in best["new"]:
                    o, n = best["old"][label], best["new"][label]
                    print(f"  {label:55s} {o:10.4g} {n:10.4g}  {n / o:6.2f}")


if __name__ == "__main__":
    main()
