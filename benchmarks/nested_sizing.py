"""Benchmark (issue #46): the nested design's move sizing on a rig with long sensor delays.

The built-in rotary rig with every sensor's delay set to DELAY samples at 1 kHz (default
80; the fitted unit 7 rig has 86). One ``design_nested`` call, timed whole and its
``_size_quasi_parabolic`` on its own; then the same sizing, from the same inputs, with the
loops and the feedforward simulated the old way (``control.forced_response`` on every
trial). Prints both sizing times, their ratio, the sizing's share of the whole call, and
both results (the same A; tests/test_design_nested__sizing.py checks it to 1e-12).

The machine may be shared: compare figures from one run only.

Run:  .venv/bin/python benchmarks/nested_sizing.py [DELAY]
"""

from __future__ import annotations

import sys
import time

import control
import numpy as np

import flexarm.control.wiener as wiener
import flexarm.design.nested as nested
from flexarm.specs import load_scenario


def long_delay_rig(delay: int):
    """The rotary rig with every sensor ``delay`` samples late."""
    sc = load_scenario("rotary-flexible-link")
    sensors = {k: s.model_copy(update={"delay": delay}) for k, s in sc.sensors.items()}
    return sc.model_copy(update={"sensors": sensors})


def old_response(sys_, t, u):
    """The simulation before issue #46: python-control's per-sample loop, every call."""
    return np.asarray(control.forced_response(sys_, t, u).outputs, float)


def main(delay: int) -> None:
    sc = long_delay_rig(delay)
    sizing = nested._size_quasi_parabolic
    seen: dict = {}

    def timed(*a, **kw):
        t0 = time.perf_counter()
        out = sizing(*a, **kw)
        seen.update(args=a, kw=kw, time=time.perf_counter() - t0, out=out)
        return out

    nested._size_quasi_parabolic = timed
    try:
        t0 = time.perf_counter()
        design = nested.design_nested(sc)
        whole = time.perf_counter() - t0
    finally:
        nested._size_quasi_parabolic = sizing
    t_inner = seen["args"][8]
    print(f"rotary rig, sensor delays {delay} samples at 1 kHz")
    print(f"  T_in order {len(t_inner.den[0][0]) - 1}, move {design.info['trajectory']}")
    print(f"design_nested (ours): {whole:.2f} s")
    ours = seen["time"]
    print(f"  sizing (ours):      {ours:.3f} s = {100 * ours / whole:.1f} % of the call")

    new = (wiener.linear_response, nested.linear_response)
    wiener.linear_response = nested.linear_response = old_response
    try:
        t0 = time.perf_counter()
        old_out = sizing(*seen["args"], **seen["kw"])
        old = time.perf_counter() - t0
    finally:
        wiener.linear_response, nested.linear_response = new
    print(f"  sizing (old path):  {old:.3f} s = {100 * old / (whole - ours + old):.1f} % of it")
    print(f"  ratio old/ours:     {old / ours:.1f}x")
    a_new, a_old = seen["out"][0].max_acceleration, old_out[0].max_acceleration
    print(f"  A ours {a_new!r} rad/s², old {a_old!r} (relative {abs(a_new / a_old - 1):.1e})")
    print(f"  peak deflection ours {seen['out'][2]!r} rad, old {old_out[2]!r}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 80)
