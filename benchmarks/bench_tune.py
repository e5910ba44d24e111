"""Benchmark: ``--method tune`` on 200 plants × 2 s runs at 1 kHz (issue #14): the time per
cost evaluation (one vmapped batch of the nominal + 200 drawn plants through the one
sampled-data loop, metrics and cost included) and for a whole short tuning (Nelder–Mead,
K1..K4 + friction compensation level and rest deadband).

The plants are drawn from unit 6's fit on its whole log (../shared/data/rotary-rig) when
the data are there, else from the built-in rotary-flexible-link scenario with 10-20 %
spreads on friction, inertia, link damping and gauge gain.

    PYTHONPATH=src python benchmarks/bench_tune.py [--plants 200] [--maxfev 150]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import flexarm
from flexarm.design import plants as pl
from flexarm.design.tune import TuneCost, design_tune

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
FORMAT = Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml"
SHEET = dict(
    drive="voltage",
    gear_ratio=48.4,
    motor_constant=0.0107,
    armature_resistance=3.29,
    link_length=0.45,
    computation_delay=1,
)


def batch(n: int):
    if DATA.is_dir():
        from flexarm.identification.time_domain import load_rig_log
        from flexarm.identification.time_domain.fit import fit

        t = time.perf_counter()
        res = fit([load_rig_log(DATA / "4PM_Group37_FlexArm_Unit6", log_format=FORMAT)], **SHEET)
        print(f"unit 6 fitted on its whole log in {time.perf_counter() - t:.1f} s")
        return pl.from_fit(res, n, seed=0), 1e-3, "unit 6 fit"
    sc = flexarm.load_scenario("rotary-flexible-link")
    spread = {
        "arm.friction.coulomb": (0.03, 0.006),
        "arm.motor.inertia": (2.08e-3, 2e-4),
        "arm.beam.damping_ratio": (0.03, 0.006),
        "sensors.tip_deflection.gain": (1.0, 0.1),
    }
    return pl.from_paths(sc, spread, n, seed=0), None, "rotary-flexible-link (no real data)"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plants", type=int, default=200)
    ap.add_argument("--maxfev", type=int, default=150)
    ap.add_argument("--repeat", type=int, default=10)
    a = ap.parse_args()
    print(
        f"cores: {os.cpu_count()} (os.cpu_count); jax devices: "
        f"{[d.platform for d in __import__('jax').devices()]}"
    )
    b, count, what = batch(a.plants)
    sc = b.nominal
    t = time.perf_counter()
    cost = TuneCost(
        sc,
        b,
        ["controller.k1", "controller.k2", "controller.k3", "controller.k4"],
        step=None,
        start=0.1,
        duration=2.0,
        band=0.02,
        quantile=0.9,
        weights={},
        hub_error_max=1.0,
        count=count,
        seed=0,
    )
    prep = time.perf_counter() - t
    p0 = [sc.controller.k1, sc.controller.k2, sc.controller.k3, sc.controller.k4]
    t = time.perf_counter()
    cost.evaluate(p0)
    first = time.perf_counter() - t
    times = []
    rng = np.random.default_rng(0)
    for _ in range(a.repeat):
        p = np.asarray(p0) * (1 + 0.1 * rng.standard_normal(4))
        t = time.perf_counter()
        cost.evaluate(p)
        times.append(time.perf_counter() - t)
    n_roll = cost.base.size
    med = float(np.median(times))
    print(
        f"\nplants: {what}; {a.plants} drawn + the nominal = {n_roll} rollouts x 2.0 s at "
        f"1 kHz ({len(cost.base.time)} samples, {sc.simulation.substeps} RK4 substeps)"
    )
    print(f"  prepare and stack the {n_roll} loops: {prep:.2f} s (once per tuning)")
    print(f"  first cost evaluation (compiles): {first:.2f} s")
    print(
        f"  cost evaluation: median {med:.3f} s, min {min(times):.3f} s over {a.repeat} "
        f"({1e6 * med / n_roll / len(cost.base.time):.2f} us per plant-sample)"
    )
    t = time.perf_counter()
    des = design_tune(sc, b, count=count, maxfev=a.maxfev)
    wall = time.perf_counter() - t
    i = des.info
    print(
        f"  whole tuning (Nelder-Mead, {len(i['parameters'])} parameters, maxfev "
        f"{a.maxfev}): {wall:.1f} s wall, {i['evaluations']} evaluations, "
        f"{i['seconds_per_evaluation']:.3f} s per evaluation; cost (0.9 quantile) "
        f"{i['cost']['start']:.3f} -> {i['cost']['tuned']:.3f}"
    )
    print("  tuned:", {k.split(".")[-1]: round(v["tuned"], 4) for k, v in i["parameters"].items()})


if __name__ == "__main__":
    main()
