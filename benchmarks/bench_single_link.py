"""Benchmark: 2 s of the FRB single-mass arm in a PD motor loop with Coulomb friction,
3 ms sampling, one-period delay, 12-bit converters, current saturation.

Prints, in one run: flexarm's compile time, time per rollout (single, and per rollout in
a vmap-ed batch of 1000 gain variations), and the same closed loop written the way a user
would without flexarm (NumPy right-hand side, scipy.integrate.solve_ivp between samples),
with the ratios against the targets (>= 20x single, batch per rollout >= 5x our single).

The machine may be shared: every figure is the best of several runs; compare figures
from one run only (docs/performance.md has measured figures and what cost what).

Run:  .venv/bin/python benchmarks/bench_single_link.py
"""

from __future__ import annotations

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from flexarm.control import discrete
from flexarm.sim.build import prepare
from flexarm.sim.sampled import _prepare_refs, _run_all, simulate_batch, simulate_loop
from flexarm.specs import load_scenario

N_BATCH = 1000


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def numpy_scipy_baseline(sc, p) -> tuple[float, np.ndarray]:
    """The loop as a user writes it: NumPy RHS, solve_ivp (RK45) over each sample period,
    Karnopp friction with the velocity zeroed at a stick, PD with one-sample delay."""
    m = p.model
    A, B, C, D = m.beam.A, m.beam.B, m.beam.C, m.beam.D
    J, V, K = m.J, m.V, float(m.drive.k_u)
    Fc, Fs, dv = float(m.friction.coulomb), float(m.friction.static), 1e-3
    kp, kd, T = sc.controller.kp, sc.controller.kd, sc.sampling.period
    qy, qu, lim = 2 * np.pi / 4096, 2 * 4.12 / 4096, 4.12

    def forces(x, i):
        th, om, zb = x[0], x[1], x[2:]
        yb = C @ zb + D @ np.array([th, om])
        ta = K * i - V * om - yb[1]
        f = np.clip(ta, -Fs, Fs) if abs(om) < dv else Fc * np.sign(om)
        return ta, f, zb, th, om

    def rhs(t, x, i):
        ta, f, zb, th, om = forces(x, i)
        return np.concatenate([[om, (ta - f) / J], A @ zb + B @ np.array([th, om])])

    x = np.array(p.x0, float)
    e_prev, u_next = 0.0, 0.0
    out = []
    for k in range(p.n_samples):
        y = np.round(x[0] / qy) * qy
        e = p.references["reference"][k] - y
        u_c = kp * e + kd * (e - e_prev) / T
        e_prev = e
        u = np.round(np.clip(u_next, -lim, lim) / qu) * qu  # one-period delay
        u_next = u_c
        out.append(x[0])
        sol = solve_ivp(rhs, (0.0, T), x, args=(u,), rtol=1e-8, atol=1e-10)
        x_new = sol.y[:, -1]
        ta, _, _, _, _ = forces(x_new, u)
        if (x[1] * x_new[1] <= 0 or abs(x_new[1]) < dv) and abs(ta) <= Fs:
            x_new[1] = 0.0
        x = x_new
    return 0.0, np.array(out)


def main() -> None:
    sc = load_scenario("feliu-single-mass")
    p = prepare(sc)
    n = p.n_samples
    print(
        f"single-mass arm, PD motor loop with friction: {n} samples of "
        f"{sc.sampling.period * 1e3:g} ms, "
        f"{sc.simulation.substeps} RK4 substeps, 12-bit converters, one-period delay"
    )

    t0 = time.perf_counter()
    out = simulate_loop(p.loop, p.x0, p.references, n)
    compile_s = time.perf_counter() - t0
    single = best_of(lambda: simulate_loop(p.loop, p.x0, p.references, n), 30)
    # the same compiled call, without the Python around it (references, numpy outputs,
    # divergence check)
    refs, x0, seed = _prepare_refs(p.references, n), np.asarray(p.x0), np.asarray(0)
    core_s = best_of(lambda: jax.block_until_ready(_run_all(p.loop, x0, refs, seed)), 30)

    # batch: 1000 PD gain variations (kp 10..20 A/rad, kd 0.2..0.4 A*s/rad)
    kp = np.linspace(10, 20, N_BATCH)
    kd = np.linspace(0.2, 0.4, N_BATCH)
    ctrls = discrete.pd(jnp.asarray(kp), jnp.asarray(kd), sc.sampling.period)
    stacked = discrete.LinearController(
        jnp.broadcast_to(ctrls.A, (N_BATCH, 1, 1)),
        jnp.broadcast_to(ctrls.B, (N_BATCH, 1)),
        jnp.reshape(ctrls.C, (N_BATCH, 1)),
        ctrls.D,
    )
    loop = eqx.tree_at(lambda lp: lp.controller, p.loop, stacked)
    axes = jax.tree.map(lambda _: None, loop)
    axes = eqx.tree_at(lambda lp: lp.controller, axes, discrete.LinearController(0, 0, 0, 0))
    t0 = time.perf_counter()
    bout = simulate_batch(loop, p.x0, p.references, n, in_axes=axes)
    batch_compile = time.perf_counter() - t0
    batch = best_of(lambda: simulate_batch(loop, p.x0, p.references, n, in_axes=axes), 5)
    per_rollout = batch / N_BATCH
    mid = N_BATCH // 2
    check = simulate_loop(
        eqx.tree_at(
            lambda lp: lp.controller, p.loop, discrete.pd(kp[mid], kd[mid], sc.sampling.period)
        ),
        p.x0,
        p.references,
        n,
    )
    batch_err = np.max(np.abs(bout["signals"][mid, :, 0] - check["signals"][:, 0]))

    base = best_of(lambda: numpy_scipy_baseline(sc, p), 2)
    _, base_theta = numpy_scipy_baseline(sc, p)
    agree = np.max(np.abs(base_theta - out["signals"][:, 0]))

    print(f"  compile (first call, incl. run)      {compile_s * 1e3:9.1f} ms")
    print(f"  flexarm single rollout (public call) {single * 1e3:9.3f} ms")
    print(f"  flexarm single rollout (jit core)    {core_s * 1e3:9.3f} ms")
    print(f"  flexarm batch of {N_BATCH}: compile      {batch_compile:9.2f} s")
    print(
        f"  flexarm batch of {N_BATCH}: total        {batch * 1e3:9.1f} ms, "
        f"{per_rollout * 1e3:.4f} ms per rollout (matches single runs to {batch_err:.1e} rad)"
    )
    print(
        f"  NumPy RHS + solve_ivp (baseline)     {base * 1e3:9.1f} ms "
        f"(agrees with flexarm to {agree:.2e} rad max over the run)"
    )
    r1 = base / single
    r2 = single / per_rollout
    print(
        f"  single speed-up vs baseline: {r1:7.1f}x   "
        f"(target >= 20x: {'PASS' if r1 >= 20 else 'FAIL'})"
    )
    print(
        f"  batch per rollout vs single: {r2:7.1f}x   "
        f"(target >=  5x: {'PASS' if r2 >= 5 else 'FAIL'})"
    )


if __name__ == "__main__":
    main()
