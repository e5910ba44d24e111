"""Time the one fit (flexarm.fit on the two-link preset) of the real two-link rig
(issue #17's must-show split): fit on the first 50 s of the 102 s run with the staircase
steps to 5°, −10°, 20°, −30°; validate on the last 52 s and on the other steps (−5°, 10°,
−20°, 30°, return to 0°).

    PYTHONPATH=src python benchmarks/bench_two_link_fit.py [--no-friction] [--json OUT]

Prints the fit's wall time (target: <= 5 min on 2 cores), the fitted values with their
standard deviations, the warnings, and fit % per signal held out."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

import flexarm  # noqa: E402 - after the sys.path entries above
from flexarm.identification.time_domain import presets  # noqa: E402 - after the sys.path entries above
from flexarm.identification.time_domain.two_link import (  # noqa: E402 - after the sys.path entries above
    held_out_report,
    split_fit_inputs,
)

DATA = ROOT.parents[0] / "shared" / "data" / "two-link-rig"
EXAMPLES = ROOT / "examples"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-friction", action="store_true", help="fit without joint friction")
    ap.add_argument(
        "--json",
        type=Path,
        default=None,
        help="write the figures as JSON (and overlay figures beside it)",
    )
    ap.add_argument(
        "--scenario-out",
        type=Path,
        default=None,
        help="write the fitted scenario TOML (for flexarm validate --refit friction)",
    )
    a = ap.parse_args()
    if not DATA.exists():
        sys.exit(f"no rig data at {DATA}")
    t0 = time.perf_counter()
    logs, opts = split_fit_inputs(DATA, EXAMPLES)
    preset = presets.two_link(not a.no_friction)
    res = flexarm.fit(preset, logs, options=opts, progress=print)
    t_fit = time.perf_counter() - t0
    print(f"fit: {t_fit:.1f} s wall ({res.message}; {res.nfev} evaluations)")
    for p in res.free:
        print(f"  {p:45s} {res.template[p]:12.5g} -> {res.params[p]:12.5g} ± {res.std[p]:.3g}")
    for w in res.warnings:
        print("  warning:", w)
    rep = held_out_report(
        res.scenario, DATA, EXAMPLES, plots=None if a.json is None else a.json.with_suffix("")
    )
    for k, v in rep.items():
        print(k, v)
    if a.scenario_out is not None:
        res.write_scenario(a.scenario_out, overwrite=True)
    if a.json is not None:
        from flexarm.io.write import write_json

        write_json(
            a.json, {"seconds": t_fit, "fit": res.to_dict(), "held_out": rep}, overwrite=True
        )


if __name__ == "__main__":
    main()
