"""Benchmark: identification from 10 sinusoidal experiments of 20 periods each.

Generates the experiments (5 ω0/3ω0 pairs, 1.6 to 39 rad/s, sampled at 1 kHz) with the
independent simulation of the test suite (tests/_frb_sim.py) into a temporary folder, then
times :func:`flexarm.identification.frequency_domain.identify.identify` on them (reading the CSVs,
harmonic analysis, Coulomb estimate, corrections, both fits, J/V/C).  Target: under 1 s.

Run: ``python benchmarks/bench_identify.py`` (from the repository root).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "src"))

import _frb_sim as sim  # noqa: E402 - after the sys.path entries above
from flexarm.identification.frequency_domain.identify import identify  # noqa: E402 - after the sys.path entries above

TARGET_S = 1.0
REPEATS = 5


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="flexarm_bench_ident_") as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        files = sim.write_experiments(folder, sim.PAPER_ARM, sim.PAPER_PAIRS, periods=20)
        t_gen = time.perf_counter() - t0
        rows = sum(sum(1 for _ in open(f)) - 3 for f in files)
        print(
            f"generated {len(files)} experiments of 20 periods ({rows} samples at 1 kHz) "
            f"in {t_gen:.1f} s"
        )
        times = []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            res = identify(folder, sim.PAPER_ARM.K)
            times.append(time.perf_counter() - t0)
    best, med = min(times), statistics.median(times)
    print(
        f"identify(): best {best:.3f} s, median {med:.3f} s over {REPEATS} runs "
        f"(target < {TARGET_S:g} s: {'met' if best < TARGET_S else 'NOT met'})"
    )
    print(
        f"  C_f = {res.coulomb_current:.5f} A (simulated 0.132 A), "
        f"J = {res.parameters['inertia']:.4e} kg m^2, C = {res.parameters['stiffness']:.4f} "
        "N m/rad"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
