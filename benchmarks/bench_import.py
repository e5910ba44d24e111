"""How long ``import flexarm`` takes (issue #26: under 2 s on 2 cores), each in a fresh
Python process, best and median of N; and what the first use of a public name then costs
(``flexarm.load_scenario``, ``flexarm.simulate``: their modules, JAX and SciPy load then).

Run:  PYTHONPATH=src python benchmarks/bench_import.py [N]
Compare with an older commit:  PYTHONPATH=src python benchmarks/compare_commits.py \\
          --commit ddef651 bench_import.py
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time


def timed(code: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", code], check=True)
    return time.perf_counter() - t0


def main(n: int = 5) -> None:
    base = [timed("pass") for _ in range(n)]
    imp = [timed("import flexarm") for _ in range(n)]
    use = [
        timed("import flexarm; flexarm.load_scenario('feliu-single-mass'); flexarm.simulate")
        for _ in range(n)
    ]
    b = min(base)
    print(f"python start-up alone: {1e3 * b:.0f} ms (best of {n})")
    print(
        f"import flexarm: {1e3 * (min(imp) - b):.0f} ms best, "
        f"{1e3 * (statistics.median(imp) - b):.0f} ms median (start-up subtracted)"
    )
    print(f"import + first use of load_scenario and simulate: {1e3 * (min(use) - b):.0f} ms best")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5)
