"""The servo-rig engine's sample loop (``sim/rig_loop.py``) against
the one simulator (``sim.sampled.simulate_batch``) on the same rig and the same parameter
points: is the fast backend (issue #23 item 2: "only where measurably faster and equal to
the simulator") faster, and equal?

    PYTHONPATH=src python benchmarks/bench_rig_backend.py [--points 64] [--seconds 10]
        [--repeat 5] [--json OUT]

The rig: the built-in ``rotary-flexible-link`` (state feedback on the hub angle and the
tip deflection, 1 kHz, noise off), ``--seconds`` of its staircase reference, ``--points``
parameter points (hub inertia and Coulomb friction spread ±20 % on a grid, as one
Jacobian or one global-stage generation asks for). Both compute the measured hub angle,
tip deflection and command of every point, float64, after one warm-up call (compile time
printed apart). Prints the best of ``--repeat`` wall times of each, their ratio, and the
largest difference between the two (rad, m, V)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))


def rig(seconds: float):
    from flexarm.specs import load_scenario

    sc = load_scenario("rotary-flexible-link")
    sensors = {k: v.model_copy(update={"noise": 0.0}) for k, v in sc.sensors.items()}
    return sc.model_copy(
        update={
            "sensors": sensors,
            "simulation": sc.simulation.model_copy(update={"duration": seconds}),
        }
    )


def best(f, repeat: int) -> tuple[float, object]:
    out, times = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=64)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    from flexarm.identification.time_domain.general import stack_loops
    from flexarm.sim.build import prepare
    from flexarm.sim.rig_loop import as_jax, closed_loop_run
    from flexarm.sim.sampled import simulate_batch
    from flexarm.specs.paths import scenario_with

    sc = rig(a.seconds)
    d = sc.model_dump()
    J0, C0 = d["arm"]["motor"]["inertia"], d["arm"]["friction"]["coulomb"]
    g = int(np.ceil(np.sqrt(a.points)))
    grid = [(f1, f2) for f1 in np.linspace(0.8, 1.2, g) for f2 in np.linspace(0.8, 1.2, g)]
    grid = grid[: a.points]
    # the one simulator: one prepared loop per point, stacked, one vmapped call
    preps = [
        prepare(scenario_with(sc, {"arm.motor.inertia": J0 * f1, "arm.friction.coulomb": C0 * f2}))
        for f1, f2 in grid
    ]
    p0 = preps[0]
    loop = stack_loops([p.loop for p in preps])
    x0 = p0.model.initial_state(0.0, 0.0, 0.0)

    def sim():
        out = simulate_batch(loop, x0, p0.references, p0.n_samples, check=False)
        return np.asarray(out["measured"]), np.asarray(out["command"])

    t0 = time.perf_counter()
    meas, cmd = sim()
    t_first_sim = time.perf_counter() - t0
    # the servo rig's backend: the same arm as its parameter dict, one column per point,
    # read off the scenario (θ: hub angle, d: tip deflection)
    arm, sens, ctl = d["arm"], d["sensors"], d["controller"]
    mo, fr, beam = arm["motor"], arm["friction"], arm["beam"]
    Lb, mb = beam["length"], beam["masses"][0]["mass"]
    wc2 = 3 * beam["flexural_rigidity"] / Lb**3 / mb  # ω_c² of the pinned tip mass
    # torque per volt (N·m/V) and back-emf torque per rad/s at the hub
    ku = (
        mo["gear_efficiency"]
        * mo["motor_efficiency"]
        * mo["gear_ratio"]
        * mo["motor_constant"]
        / mo["armature_resistance"]
    )
    n = p0.n_samples
    const = as_jax(
        dict(
            dt=d["sampling"]["period"],
            length=Lb,
            k_u=ku,
            k_omega=ku * mo["gear_ratio"] * mo["motor_constant"],
            q_th=sens["motor_angle"]["range"] / 2 ** sens["motor_angle"]["bits"],
            q_d=0.0,
            limit=mo["voltage_limit"],
            vel_tol=fr["velocity_tolerance"],
            omega_th=0.0,
            omega_d=0.0,
        )
    )
    names = p0.loop.sensors.names
    z = np.zeros((1, n))
    data = as_jax(
        dict(
            ref=p0.references["reference"][None],
            y_th=meas[0, :, names.index("motor_angle")][None],
            y_d=meas[0, :, names.index("tip_deflection")][None],
            w_th=z,
            w_d=z,
            volt=z,
            K=np.array([[ctl[k] for k in ("k1", "k2", "k3", "k4")]]),
            tau=np.zeros(1),
        )
    )
    P = len(grid)
    base = dict(
        B=mo["viscous"],
        wc2=wc2,
        c2z=2 * beam["damping_ratio"] * np.sqrt(wc2),
        JlL=mb * Lb,
        Fs=fr["static"],
        bias=fr["bias"],
        gain=sens["tip_deflection"]["gain"],
        dth=sens["motor_angle"]["delay"],
        dd=sens["tip_deflection"]["delay"],
        th0=0.0,
        om0=0.0,
        w0=0.0,
        wd0=0.0,
    )
    model = as_jax(
        {
            "J": np.array([[J0 * f1 for f1, _ in grid]]),
            "Fc": np.array([[C0 * f2 for _, f2 in grid]]),
            **{k: np.full((1, P), v) for k, v in base.items()},
        }
    )

    def backend():
        tr, _ = closed_loop_run(model, data, const, substeps=p0.loop.substeps)
        return [np.asarray(x) for x in tr[:3]]

    t0 = time.perf_counter()
    backend()
    t_first_rig = time.perf_counter() - t0
    t_sim, (meas, cmd) = best(sim, a.repeat)
    t_rig, tr = best(backend, a.repeat)
    diff = {
        "motor_angle": float(
            np.max(np.abs(tr[0][:, 0, :].T - meas[:, :, names.index("motor_angle")]))
        ),
        "tip_deflection": float(
            np.max(np.abs(tr[1][:, 0, :].T - meas[:, :, names.index("tip_deflection")]))
        ),
        "command": float(np.max(np.abs(tr[2][:, 0, :].T - cmd[:, :, 0]))),
    }
    print(f"{P} parameter points x {a.seconds:g} s at 1 kHz, best of {a.repeat}:")
    print(f"  one simulator (simulate_batch): {t_sim:.3f} s  (first call {t_first_sim:.2f} s)")
    print(f"  servo-rig backend (closed_loop): {t_rig:.3f} s  (first call {t_first_rig:.2f} s)")
    print(f"  ratio simulator / backend: {t_sim / t_rig:.2f}")
    print("  largest difference: " + ", ".join(f"{k} {v:.2e}" for k, v in diff.items()))
    if a.json is not None:
        from flexarm.io.write import write_json

        write_json(
            a.json,
            {
                "points": P,
                "seconds_simulated": a.seconds,
                "simulator_s": t_sim,
                "backend_s": t_rig,
                "first_call_s": {"simulator": t_first_sim, "backend": t_first_rig},
                "max_difference": diff,
            },
            overwrite=True,
        )


if __name__ == "__main__":
    main()
