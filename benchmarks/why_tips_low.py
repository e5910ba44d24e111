"""Issue #47 item 3: why the rotary rig's tips are low, one cause at a time.

The 4/27 and 5/2 training runs (``../shared/data/rotary-rig``) are fitted together once
(``flexarm fit ... --sessions 0,0,1,1``, the README's data sheet, default options); then
each run is predicted by its session's written scenario (the one prediction, as
``flexarm validate`` does) with one cause of the model removed at a time, and the hub /
tip fit % printed beside the fitted model's. A cause whose removal lowers the tips is
one the data support.

Run: python benchmarks/why_tips_low.py [FOLDER]   (FOLDER: where rig.toml and
rig.session1.toml of an earlier fit lie; without it the fit runs first, ~1.5 min)
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "rotary-rig"
FORMAT = ROOT / "examples" / "quanser-rotflex.toml"
RUNS = [
    ("flexarm_K1_6", 0),
    ("flexarm_K1K2_6_-5", 0),
    ("flexarm_K1K2K3_6_-3_213", 1),
    ("flexarm_K1K2K3k4_6_-3_213_4", 1),
]
SHEET = "--drive voltage --gear-ratio 48.4 --motor-constant 0.0107 --armature-resistance 3.29"
SHEET += " --link-length 0.45"


def main() -> int:
    if not DATA.is_dir():
        print(f"skipped: {DATA} not found (../shared is absent)")
        return 0
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict
    from flexarm.io.logformat import load_log
    from flexarm.specs import load_scenario
    from flexarm.specs.paths import get, scenario_with

    folder = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
    toml = folder / "rig.toml"
    if not toml.is_file():
        cmd = [sys.executable, "-m", "flexarm", "fit", *(str(DATA / n) for n, _ in RUNS)]
        cmd += ["--sessions", "0,0,1,1", "--log-format", str(FORMAT), *SHEET.split()]
        cmd += ["--scenario-out", str(toml)]
        print("fitting:", " ".join(cmd[2:]), flush=True)
        subprocess.run(cmd, check=True, capture_output=True)
    scen = [load_scenario(toml), load_scenario(folder / "rig.session1.toml")]
    logs = [load_log(DATA / n, FORMAT) for n, _ in RUNS]

    def run(label, change=None, initial=None, log_change=None):
        row = []
        for (_name, s), g in zip(RUNS, logs, strict=True):
            sc = scen[s]
            if change is not None:
                sc = scenario_with(sc, change(sc))
            lg = log_change(g) if log_change is not None else g
            pr = predict(sc, [lg], PredictOptions(initial=initial))
            fp = next(iter(pr.fit_percent.values()))
            row.append((fp["motor_angle"], fp["tip_deflection"]))
        cells = "  ".join(f"{h:6.1f} / {t:6.1f}" for h, t in row)
        mean_t = sum(t for _, t in row) / len(row)
        print(f"{label:<46} {cells}   mean tip {mean_t:5.1f}", flush=True)

    print(f"{'cause removed (hub / tip %)':<46} " + "  ".join(f"{n[:15]:>15}" for n, _ in RUNS))
    run("none: the fitted model, start estimated")
    run("the link's start estimated (read off the log)", initial="log")
    run("the link's start (at rest)", initial="rest")
    run("the pushed clamp's stiffening", lambda sc: {"arm.friction.pushed_stiffening": 0.0})

    def same_delay(sc):
        d = sc.model_dump()
        return {"sensors.tip_deflection.delay": get(d, "sensors.motor_angle.delay")}

    run("the tip channel's own delay (as the hub's)", same_delay)

    def rigid_friction(sc):  # session 1 with session 0's friction and bias
        d = scen[0].model_dump()
        paths = ("coulomb", "static", "bias")
        out = {f"arm.friction.{p}": get(d, f"arm.friction.{p}") for p in paths}
        out["arm.motor.viscous"] = get(d, "arm.motor.viscous")
        return out

    run("friction and bias per session (4/27's for all)", rigid_friction)
    run(
        "the logged gain schedule (declared gains)",
        log_change=lambda g: dataclasses.replace(g, gains=None),
    )
    run("the link's damping (x 3)", lambda sc: {
        "arm.beam.damping_ratio": 3 * get(sc.model_dump(), "arm.beam.damping_ratio")
    })  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
