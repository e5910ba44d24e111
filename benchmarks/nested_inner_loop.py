"""Benchmark (issue #46): ``design_nested`` on the rotary rig with long sensor delays, its
inner-loop search before and after the evaluator's second speed-up.

For each DELAY (default 2 40 80 samples at 1 kHz; every sensor DELAY samples late, as in
benchmarks/nested_sizing.py): one ``design_nested`` call with this tree's
``control/inner_loop.py`` ("after"), then one with the module as it was at commit
``BEFORE`` ("before": read with ``git show``, its ``design_inner_loop`` put in
``design/nested.py``'s place). Prints both times, their ratio, the time in the inner-loop
search (the ``design_inner_loop`` calls: every G_cm1(1) tried), and both designs' zeros and
poles, settling time and move acceleration A. A first untimed call at 2 samples warms up
the imports and the simulator's compilation.

The machine may be shared: compare figures from one run only.

Run:  PYTHONPATH=src .venv/bin/python benchmarks/nested_inner_loop.py [DELAY ...]
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import flexarm.design.nested as nested
from flexarm.specs import load_scenario

#: the commit before the change (the evaluator of f481384 and 4576d22)
BEFORE = "1ee883f"
ROOT = Path(__file__).resolve().parents[1]


def long_delay_rig(delay: int):
    """The rotary rig with every sensor ``delay`` samples late."""
    sc = load_scenario("rotary-flexible-link")
    sensors = {k: s.model_copy(update={"delay": delay}) for k, s in sc.sensors.items()}
    return sc.model_copy(update={"sensors": sensors})


def old_inner_loop():
    """control/inner_loop.py at ``BEFORE``, as a module."""
    text = subprocess.run(
        ["git", "show", f"{BEFORE}:src/flexarm/control/inner_loop.py"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    path = Path(tempfile.mkdtemp()) / "inner_loop_before.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("inner_loop_before", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["inner_loop_before"] = mod
    spec.loader.exec_module(mod)
    return mod


def timed_design(sc, design_inner_loop):
    """(seconds of design_nested, seconds in design_inner_loop, calls, result)."""
    spent = [0.0, 0]

    def timed(*a, **kw):
        t0 = time.perf_counter()
        try:
            return design_inner_loop(*a, **kw)
        finally:
            spent[0] += time.perf_counter() - t0
            spent[1] += 1

    saved = nested.design_inner_loop
    nested.design_inner_loop = timed
    try:
        t0 = time.perf_counter()
        res = nested.design_nested(sc)
        whole = time.perf_counter() - t0
    finally:
        nested.design_inner_loop = saved
    return whole, spent[0], spent[1], res


def main(delays: list[int]) -> None:
    old = old_inner_loop()
    nested.design_nested(long_delay_rig(2))  # warm-up: imports, the simulator's compilation
    rows = []
    for delay in delays:
        sc = long_delay_rig(delay)
        after = timed_design(sc, nested.design_inner_loop)
        before = timed_design(sc, old.design_inner_loop)
        print(f"rotary rig, sensor delays {delay} samples at 1 kHz")
        for name, (whole, search, calls, res) in (("before", before), ("after", after)):
            inner, traj = res.info["inner"], res.info["trajectory"]
            print(
                f"  {name:6s} design_nested {whole:7.2f} s, inner-loop search {search:7.2f} s "
                f"({calls} G_cm1(1) tried); zeros/poles {inner['zeros_poles']}, "
                f"settling {inner['settling_linear_s']!r} s, G_cm1(1) {inner['dc_gain']!r}, "
                f"A {traj['acceleration']!r} rad/s²"
            )
        print(
            f"  ratio before/after: whole {before[0] / after[0]:.2f}x, search "
            f"{before[1] / after[1]:.2f}x"
        )
        rows.append((delay, before, after))
    print(
        "\n| delay | design_nested before [s] | after [s] | ratio | search before [s] | after [s] |"
    )
    print("|---|---|---|---|---|---|")
    for delay, b, a in rows:
        print(
            f"| {delay} | {b[0]:.2f} | {a[0]:.2f} | {b[0] / a[0]:.2f}x | {b[1]:.2f} | {a[1]:.2f} |"
        )


if __name__ == "__main__":
    main([int(v) for v in sys.argv[1:]] or [2, 40, 80])
