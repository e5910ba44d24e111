"""The README's fit → design → C chain, run exactly as the README writes it, on the two
flexible rotary rigs of ``../shared/data/rotary-rig`` (issue #25: the design table must be
reproducible from the README's commands).

For each rig: ``flexarm fit LOG --log-format examples/quanser-rotflex.toml <data sheet>
--window 0:5 --validate-window 5:10 --json fit.json --scenario-out rig.toml`` (the README's
window; ``--window whole``: the whole log; every other default: the amplifier limit
from the log format, the computation delay from the controller check, the encoder count
from the log), then ``flexarm design rig.toml --method M --out out/M --fit-json fit.json
--plants 200`` for M in lqr, nested, tune, then ``flexarm export-c out/M`` for each. Prints
each step's exit code, each design's verdict and unstable count, and the README's table
(median over the 200 plants, worst in brackets) as Markdown.

    .venv/bin/python benchmarks/readme_design_chain.py [--out DIR] [--plants N] [--window 0:5]

Takes about 15-25 min on 2 cores (two fits, six designs of 200 plants).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("FLEXARM_DATA") or ROOT.parent / "shared" / "data") / "rotary-rig"
SHEET = [
    "--gear-ratio",
    "48.4",
    "--motor-constant",
    "0.0107",
    "--armature-resistance",
    "3.29",
    "--link-length",
    "0.45",
]
RIGS = {"unit 6": "4PM_Group37_FlexArm_Unit6", "unit 7": "Unit7_Flex_trial1.csv"}
METHODS = ("lqr", "nested", "tune")


def flexarm(*args: str, cwd: Path) -> tuple[int, float, str]:
    """Run ``flexarm ARGS`` (this interpreter's); exit code, seconds, its last lines."""
    t0 = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-m", "flexarm", *args], cwd=cwd, text=True, capture_output=True
    )
    tail = "\n".join((p.stdout + p.stderr).strip().splitlines()[-3:])
    return p.returncode, time.perf_counter() - t0, tail


def fmt(x, digits=3) -> str:
    if x is None:
        return "never"
    return f"{x:.{digits}g}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "readme-chain")
    ap.add_argument("--plants", type=int, default=200)
    ap.add_argument(
        "--window",
        default="0:5",
        help="the fit's --window, as the README's (0:5, held out 5:10); 'whole': whole logs",
    )
    a = ap.parse_args()
    win = [] if a.window == "whole" else ["--window", a.window]
    if a.window == "0:5":
        win += ["--validate-window", "5:10"]
    if not DATA.is_dir():
        print(f"the rotary-rig logs are not at {DATA} (set FLEXARM_DATA)")
        return 1
    a.out.mkdir(parents=True, exist_ok=True)
    steps, table = [], []
    for rig, name in RIGS.items():
        d = a.out / rig.replace(" ", "")
        d.mkdir(exist_ok=True)
        code, s, tail = flexarm(
            "fit",
            str(DATA / name),
            "--log-format",
            str(ROOT / "examples" / "quanser-rotflex.toml"),
            *SHEET,
            *win,
            "--json",
            "fit.json",
            "--scenario-out",
            "rig.toml",
            "--overwrite",
            cwd=d,
        )
        steps.append((rig, "fit", code, s, ""))
        print(f"{rig}: fit exit {code} in {s:.0f} s", flush=True)
        if code != 0:
            print(tail)
            continue
        for m in METHODS:
            code, s, tail = flexarm(
                "design",
                "rig.toml",
                "--method",
                m,
                "--out",
                f"out/{m}",
                "--fit-json",
                "fit.json",
                "--plants",
                str(a.plants),
                "--overwrite",
                cwd=d,
            )
            dj = d / "out" / m / "design.json"
            verdict = json.loads(dj.read_text()).get("verdict") if dj.exists() else None
            steps.append((rig, f"design {m}", code, s, verdict))
            print(f"{rig}: design {m} exit {code} in {s:.0f} s, verdict {verdict}", flush=True)
            cj = d / "out" / m / "compare.json"
            if cj.exists():
                rows = json.loads(cj.read_text())["rows"]
                for ctrl, r in rows.items():
                    if ctrl != m and (rig, ctrl) in {(t[0], t[1]) for t in table}:
                        continue
                    table.append((rig, ctrl, r))
            code, s, tail = flexarm("export-c", f"out/{m}", "--out", f"c/{m}", "--overwrite", cwd=d)
            steps.append((rig, f"export-c {m}", code, s, tail.splitlines()[-1] if code else ""))
            print(f"{rig}: export-c {m} exit {code}", flush=True)
    print("\n| rig | step | exit | seconds | verdict / message |\n|---|---|---|---|---|")
    for rig, step, code, s, v in steps:
        print(f"| {rig} | {step} | {code} | {s:.0f} | {v or ''} |")
    print(
        "\n| rig | controller | hub error [counts] | tip settling 2 % [s] | tip overshoot [%]"
        " | peak [V] | unstable |\n|---|---|---|---|---|---|---|"
    )
    for rig, ctrl, r in table:
        med, worst = r["median"], r["worst"]
        print(
            f"| {rig} | {ctrl} | {fmt(med['hub_error_counts'])} "
            f"({fmt(worst['hub_error_counts'])}) | {fmt(med['tip_settling_s'])} "
            f"({fmt(worst['tip_settling_s'])}) | {fmt(med['tip_overshoot_pct'])} | "
            f"{fmt(worst['peak_command_V'])} | {r['unstable']}/{r['n_plants']} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
