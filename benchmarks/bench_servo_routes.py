"""Issue #43: the rotary servo's two routes from one run, the default (``--local servo``:
the pipeline's own local stage and friction polish) as the baseline beside the general
engine after the pipeline's estimates and global stage (``--local general``), on the real
logs of ../shared/data/rotary-rig read with examples/quanser-rotflex.toml, the README's data
sheet. Per case: seconds of ``flexarm.fit`` and hub / tip fit % through ``flexarm.validate``
of the written scenario (held-out windows where the case has them, else the fitted runs).
The options are the documented commands' (no computation delay given: the declared law's
best, as `flexarm fit` finds it).

Run: python benchmarks/bench_servo_routes.py [CASE ...]   (CASE: a word of a case's name)
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import flexarm
from flexarm.identification.time_domain.logs import load_rig_logs
from flexarm.identification.time_domain.options import FitOptions, PredictOptions, ServoRig
from flexarm.identification.time_domain.presets import DataSheet, servo_rig

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "rotary-rig"
FORMAT = ROOT / "examples" / "quanser-rotflex.toml"
SHEET = DataSheet(
    drive="voltage",
    gear_ratio=48.4,
    motor_constant=0.0107,
    armature_resistance=3.29,
    link_length=0.45,
)
RIGID = ["rigidarm_K1_6", "rigidarm_K1_8", "rigidarm_k1k3_6", "rigidarm_k1k3_8"]
#: name -> (fitted logs, fitted window, held-out logs, held-out window, sessions)
CASES = {
    "unit 6, held out 5:10 s": (["4PM_Group37_FlexArm_Unit6"], (0, 5), None, (5, 10), None),
    "unit 7, held out 5:10 s": (["Unit7_Flex_trial1.csv"], (0, 5), None, (5, 10), None),
    "rigid session 4/25, held-out runs": (
        RIGID,
        None,
        ["rigidarm_K1_7", "rigidarm_K1_9", "rigidarm_k1k3_7", "rigidarm_k1k3_9"],
        None,
        None,
    ),
    "hard session 4/27, fitted runs": (["flexarm_K1_6", "flexarm_K1K2_6_-5"], None, [], None, None),
    "sessions 4/27 + 5/2, fitted runs": (
        ["flexarm_K1_6", "flexarm_K1K2_6_-5"]
        + ["flexarm_K1K2K3_6_-3_213", "flexarm_K1K2K3k4_6_-3_213_4"],
        None,
        [],
        None,
        [0, 0, 1, 1],
    ),
}


def _figures(fp: dict) -> str:
    return ", ".join(
        f"{d.get('motor_angle') or 0:.1f} / {d['tip_deflection']:.1f}"
        if d.get("tip_deflection") is not None
        else f"{d.get('motor_angle') or 0:.1f}"
        for d in fp.values()
    )


def run(what: str, local: str, tmp: Path) -> str:
    names, win, held, hwin, sessions = CASES[what]
    logs = load_rig_logs([DATA / n for n in names], FORMAT)
    rig = ServoRig(local=local, sessions=sessions)
    opts = FitOptions(servo_rig=rig, windows=[win] * len(logs) if win else None)
    t = time.perf_counter()
    res = flexarm.fit(servo_rig(SHEET), logs, options=opts)
    sec = time.perf_counter() - t
    paths = res.session_paths(tmp / f"{local}.toml")
    res.write_scenario(paths[0], overwrite=True)
    if held is None:  # the fitted log's held-out window
        pred = flexarm.validate(str(paths[0]), logs, PredictOptions(windows=[hwin] * len(logs)))
        fp = pred.fit_percent
    elif held:
        fp = flexarm.validate(str(paths[0]), load_rig_logs([DATA / n for n in held], FORMAT))
        fp = fp.fit_percent
    else:  # the fitted runs, each session's by its own scenario
        fp = {}
        of = sessions or [0] * len(logs)
        for s_, p in enumerate(paths):
            mine = [g for g, k in zip(logs, of, strict=True) if k == s_]
            fp.update(flexarm.validate(str(p), mine).fit_percent)
    return f"{sec:6.1f} s  {_figures(fp)}"


def main() -> int:
    if not DATA.is_dir():
        print(f"skipped: {DATA} not found (../shared is absent)")
        return 0
    only = sys.argv[1:]
    with tempfile.TemporaryDirectory() as tmp:
        for what in CASES:
            if only and not any(w in what for w in only):
                continue
            for local in ("servo", "general"):
                print(f"{what:38s} --local {local:8s} {run(what, local, Path(tmp))}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
