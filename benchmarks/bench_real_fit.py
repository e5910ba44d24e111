"""Issue #11 speed: the full default fit pipeline (estimates, delay search over 0-150 ms,
global and local stages, friction polish) on real 10 s logs of ../shared/data/rotary-rig,
read with examples/quanser-rotflex.toml, data-sheet values only. Target (issue #23): a
rotary session of two 10 s logs in at most 30 s on 2 quiet cores; the hard session of 4/27
(heavy gear friction, two runs fitted together) is timed beside the easier ones. Baseline
printed beside it: the same fit with the guesses-only search (``estimates=False``) over the same
delay range, which the earlier default could not do in time (the issue measured ~160 s per
session at max_delay=90).

Run: python benchmarks/bench_real_fit.py [CASE ...]   (CASE: a word of a case's name)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from flexarm.identification.time_domain import load_rig_log
from flexarm.identification.time_domain.fit import fit

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "rotary-rig"
FORMAT = ROOT / "examples" / "quanser-rotflex.toml"
SHEET = dict(
    drive="voltage",
    gear_ratio=48.4,
    motor_constant=0.0107,
    armature_resistance=3.29,
    link_length=0.45,
    computation_delay=1,
)


def run(names, **kw):
    logs = [load_rig_log(DATA / n, log_format=FORMAT) for n in names]
    t = time.perf_counter()
    res = fit(logs, **SHEET, **kw)
    return time.perf_counter() - t, res


def main() -> int:
    if not DATA.is_dir():
        print(f"skipped: {DATA} not found (../shared is absent)")
        return 0
    cases = {
        "flexible unit 6, one 10 s log": ["4PM_Group37_FlexArm_Unit6"],
        "rigid session 4/25, two 10 s logs": ["rigidarm_K1_6", "rigidarm_K1_8"],
        "hard session 4/27, two 10 s logs": ["flexarm_K1_6", "flexarm_K1K2_6_-5"],
        # issue #47: both sessions of that rig, mechanics shared, friction, bias and the
        # gauge's sign per session (target <= 60 s)
        "sessions 4/27 + 5/2, four 10 s logs": [
            "flexarm_K1_6",
            "flexarm_K1K2_6_-5",
            "flexarm_K1K2K3_6_-3_213",
            "flexarm_K1K2K3k4_6_-3_213_4",
        ],
    }
    only = sys.argv[1:]  # e.g. "sessions": the cases whose name contains it
    for what, names in cases.items():
        if only and not any(o in what for o in only):
            continue
        kw = {"sessions": [0, 0, 1, 1]} if what.startswith("sessions") else {}
        run(names[:1])  # compile once (JIT), as a second fit in one process would
        sec, res = run(names, **kw)
        fp = {k: {s: v for s, v in d.items() if v is not None} for k, d in res.fit_percent.items()}
        target = 60 if kw else 30
        print(f"{what}: {sec:.1f} s (target <= {target} s), delays {res.delays}, fit % {fp}")
    if only:
        return 0
    sec0, res0 = run(cases["flexible unit 6, one 10 s log"], estimates=False, max_delay=150)
    print(
        f"baseline, guesses-only search over 0-150 ms (unit 6): {sec0:.1f} s, delays "
        f"{res0.delays}, fit % {res0.fit_percent}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
