"""Benchmark: the two-link De Luca benchmark arm (EI = 15 N·m², 2 clamped-mass modes per link,
12 states, gravity) under the PD law (8), from θ = (−90°, 0) to (−45°, 0), 2 s, fixed-step
RK4 at 0.1 ms (20 000 steps, 80 000 right-hand sides).

Prints, in one run: flexarm's compile time, one rollout (the public ``simulate_continuous``
call and its jit core, the one sampled-data loop with the law evaluated at every RK4 stage),
a batch of gain variations per rollout (``simulate_continuous_batch``, the loop's batch,
K_P and K_D scaled by 0.8…1.25), and the same closed loop written the way a user would
without flexarm: the same model (B, c + g in the explicit particle form, from the same
``MultiLinkModel`` numbers) as a NumPy right-hand side with ``np.linalg.solve``, integrated by
``scipy.integrate.solve_ivp`` (RK45, rtol 1e-8, atol 1e-10) over the 2 s. Then the ratios and
PASS/FAIL against the targets: single ≥ 20x faster than the baseline, batch per rollout ≥ 5x
faster than our single. Timings are wall-clock, best of a few; the machine's load average is
printed with them (the project's machine has 2 shared cores).

Run:  PYTHONPATH=src python benchmarks/bench_multilink.py [--batch N]   (default N = 1000)
"""

from __future__ import annotations

import argparse
import math
import os
import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from flexarm.control import regulation as R
from flexarm.models.multilink import build_multilink
from flexarm.sim import continuous as C
from flexarm.sim import sampled
from flexarm.specs.multilink import benchmark_arm

DEG = math.pi / 180
T_FINAL, DT, STEP = 2.0, 1e-3, 1e-4
KP, KD = np.array([18.0, 18.0]), np.array([10.0, 2.0])
THETA_0, THETA_D = np.array([-90 * DEG, 0.0]), np.array([-45 * DEG, 0.0])


class NumpyArm:
    """The arm's B(q) q̈ = [u; −Kδ − Dδ̇] − c − g in NumPy, the explicit particle form of
    flexarm.models.multilink (Jacobians of the joints propagated along the chain, modal
    integrals closing each link), built from the same MultiLinkModel numbers."""

    def __init__(self, model):
        P = model.plant

        def g(a):
            return np.array(a, float)

        self.n, self.nq = P.n_links, P.n_q
        self.L, self.m, self.d = g(P.lengths), g(P.link_mass), g(P.link_d)
        self.mh, self.mp = g(P.hub_mass), float(P.payload_mass)
        self.phi, self.dphi, self.v, self.Z = g(P.phi_tip), g(P.dphi_tip), g(P.v), g(P.Z)
        self.K, self.D, self.B0 = g(P.K), g(P.D), g(P.B0)
        self.gx, self.gy = float(P.gamma[0]), float(P.gamma[1])
        self.rate, self.vrow, self.tip = g(P.rate_rows), g(P.v_rows), g(P.tip_rows)
        self.sl, k = [], 0
        for m in P.n_modes:
            self.sl.append(slice(k, k + m))
            k += m

    def terms(self, q, qd):
        """B(q) and h = c(q, q̇) + g(q)."""
        n, nq = self.n, self.nq
        B, h = self.B0.copy(), np.zeros(nq)
        Jx, Jy = np.zeros(nq), np.zeros(nq)
        accx = accy = 0.0
        alpha = q[0]
        for i, sl in enumerate(self.sl):
            a = self.rate[i]
            mt = self.m[i] + (self.mh[i] if i > 0 else 0.0)
            d, ell = self.d[i], self.L[i]
            c, s = math.cos(alpha), math.sin(alpha)
            Ax, Ay = c * Jx + s * Jy, c * Jy - s * Jx
            ad = a @ qd
            di, ddi = q[n + sl.start : n + sl.stop], qd[n + sl.start : n + sl.stop]
            v, phi = self.v[sl], self.phi[sl]
            Zd = self.Z[sl, sl] @ di
            vd, W, dZd = v @ di, phi @ di, di @ Zd
            vdd, Wd, dZdd = v @ ddi, phi @ ddi, Zd @ ddi
            y = d * a + self.vrow[i]
            U = np.array([Jx, Jy, Ay, y, Ax, a])
            C = np.zeros((6, 6))
            C[0, 0] = C[1, 1] = mt
            C[2, 3] = C[3, 2] = 1.0
            C[4, 5] = C[5, 4] = -vd
            C[5, 5] = dZd
            B += U.T @ (C @ U)
            gx, gy = accx - self.gx, accy - self.gy
            Px, Py = c * gx + s * gy, c * gy - s * gx
            ad2 = ad * ad
            h += U.T @ np.array(
                [
                    mt * gx,
                    mt * gy,
                    -ad2 * vd,
                    0.0,
                    -(ad2 * d + 2 * ad * vdd),
                    d * Py - vd * Px + 2 * ad * dZdd,
                ]
            )
            h[n + sl.start : n + sl.stop] += v * Py - ad2 * Zd
            tx, ty = -W * a, ell * a + self.tip[i]
            Jx, Jy = Jx + c * tx - s * ty, Jy + s * tx + c * ty
            lx, ly = -ad2 * ell - 2 * ad * Wd, -ad2 * W
            accx, accy = accx + c * lx - s * ly, accy + s * lx + c * ly
            alpha = alpha + self.dphi[sl] @ di + (q[i + 1] if i + 1 < n else 0.0)
        J = np.array([Jx, Jy])
        B += self.mp * (J.T @ J)
        h += self.mp * ((accx - self.gx) * Jx + (accy - self.gy) * Jy)
        return B, h

    def rhs(self, x, u):
        nq, n = self.nq, self.n
        q, qd = x[:nq], x[nq:]
        B, h = self.terms(q, qd)
        f = np.concatenate([u, -(self.K @ q[n:] + self.D @ qd[n:])]) - h
        return np.concatenate([qd, np.linalg.solve(B, f)])


def numpy_baseline(model, g_d) -> tuple[float, np.ndarray, int]:
    """The closed loop as a user writes it: NumPy RHS, PD law (8), solve_ivp over 2 s."""
    arm = NumpyArm(model)
    Kp, Kd = np.diag(KP), np.diag(KD)

    def f(t, x):
        u = Kp @ (THETA_D - x[:2]) - Kd @ x[6:8] + g_d
        return arm.rhs(x, u)

    ts = np.linspace(0.0, T_FINAL, int(round(T_FINAL / DT)) + 1)
    t0, c0 = time.perf_counter(), time.process_time()
    sol = solve_ivp(f, (0.0, T_FINAL), model.state(theta=THETA_0), t_eval=ts, rtol=1e-8, atol=1e-10)
    return (time.perf_counter() - t0, time.process_time() - c0), sol.y[:2].T, sol.nfev


def best_of(fn, repeat: int) -> tuple[float, float]:
    """(wall, CPU) seconds of the fastest of ``repeat`` calls (CPU: this process, all threads)."""
    out = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        out.append((time.perf_counter() - t0, time.process_time() - c0))
    return min(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=1000, help="rollouts in the batch (default 1000)")
    ap.add_argument("--chunk", type=int, default=128, help="rollouts per chunk (default 128)")
    args = ap.parse_args()
    print(
        f"two-link De Luca arm, PD law (8), RK4 {STEP * 1e3:g} ms, {T_FINAL:g} s "
        f"({int(T_FINAL / STEP)} steps); load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores"
    )
    model = build_multilink(benchmark_arm())
    arm = NumpyArm(model)
    rng = np.random.default_rng(0)
    err = 0.0
    for _ in range(20):
        x = np.concatenate([rng.uniform(-3, 3, 2), rng.uniform(-0.05, 0.05, 4), rng.normal(size=6)])
        u = rng.normal(size=2)
        ref = model.rhs(x, u)
        err = max(err, np.abs(arm.rhs(x, u) - ref).max() / np.abs(ref).max())
    print(f"  NumPy RHS = flexarm RHS to {err:.1e} (relative, 20 random states)")

    p = R.regulation_params(model, KP, KD, THETA_D)
    x0 = model.state(theta=THETA_0)

    def single():
        return C.simulate_continuous(model, R.law_pd_constant, x0, T_FINAL, DT, params=p, step=STEP)

    t0 = time.perf_counter()
    run = single()
    compile_s = time.perf_counter() - t0
    single_s, single_c = best_of(single, 7)
    loop = C.law_loop(model, R.law_pd_constant, p, DT, int(round(DT / STEP)))
    core_args = (
        loop,
        jnp.asarray(x0),
        sampled._prepare_refs({}, int(round(T_FINAL / DT)) + 1),
        np.asarray(0, dtype=np.int64),
    )
    core_s, _ = best_of(lambda: jax.block_until_ready(sampled._run_all(*core_args)), 7)

    N = args.batch
    scale = np.linspace(0.8, 1.25, N)
    pb, axes = R.regulation_params_batch(model, np.outer(scale, KP), np.outer(scale, KD), THETA_D)
    dt_batch = 1e-2  # outputs every 10 ms (the integration step stays 0.1 ms)

    def batch():
        return C.simulate_continuous_batch(
            model,
            R.law_pd_constant,
            x0,
            T_FINAL,
            dt_batch,
            params=pb,
            axes=axes,
            step=STEP,
            chunk=args.chunk,
        )

    t0 = time.perf_counter()
    bout = batch()
    batch_compile = time.perf_counter() - t0
    batch_s, batch_c = best_of(batch, 2)
    per_rollout, per_rollout_c = batch_s / N, batch_c / N
    mid = N // 2
    pm = R.regulation_params(model, scale[mid] * KP, scale[mid] * KD, THETA_D)
    check = C.simulate_continuous(
        model, R.law_pd_constant, x0, T_FINAL, dt_batch, params=pm, step=STEP
    )
    batch_err = np.abs(bout.state_array[mid] - check.state_array).max()

    (base_s, base_c), base_theta, nfev = numpy_baseline(model, np.asarray(p.g_d))
    base_s, base_c = min((base_s, base_c), numpy_baseline(model, np.asarray(p.g_d))[0])
    agree = np.abs(base_theta - run.theta).max()

    print(f"  compile (first call, incl. one run)      {compile_s:9.2f} s")
    print(
        f"  flexarm single rollout (public call)     {single_s * 1e3:9.1f} ms "
        f"(CPU {single_c * 1e3:.1f} ms)"
    )
    print(f"  flexarm single rollout (jit core)        {core_s * 1e3:9.1f} ms")
    print(f"  flexarm batch of {N}: compile+first run {batch_compile:9.2f} s")
    print(
        f"  flexarm batch of {N}: total             {batch_s:9.2f} s, "
        f"{per_rollout * 1e3:.2f} ms per rollout (CPU {per_rollout_c * 1e3:.2f} ms; "
        f"chunks of {args.chunk}; run {mid} = its single run to {batch_err:.1e})"
        f"{'' if not bout.diverged.any() else f'; {bout.diverged.sum()} diverged'}"
    )
    print(
        f"  NumPy RHS + solve_ivp (baseline)         {base_s * 1e3:9.1f} ms "
        f"(CPU {base_c * 1e3:.0f} ms; {nfev} RHS evaluations; "
        f"max |θ − θ_flexarm| = {agree:.1e} rad over the run)"
    )
    r1, r1c = base_s / single_s, base_c / single_c
    r2, r2c = single_s / per_rollout, single_c / per_rollout_c
    print(
        f"  single speed-up vs baseline:  {r1:7.1f}x wall, {r1c:.1f}x CPU  "
        f"(target >= 20x: {'PASS' if r1 >= 20 else 'FAIL'})"
    )
    print(
        f"  batch per rollout vs single:  {r2:7.1f}x wall, {r2c:.1f}x CPU  "
        f"(target >=  5x: {'PASS' if r2 >= 5 else 'FAIL'})"
    )


if __name__ == "__main__":
    main()
