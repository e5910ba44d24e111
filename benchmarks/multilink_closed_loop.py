"""Timing of the two-link benchmark closed loop (De Luca arm, EI = 15 N·m², 2 modes per link,
gravity, PD law (8), RK4 at 0.1 ms, 2 s): compile time, one rollout, and a vmap batch.
Also the same loop with jnp.linalg.solve instead of the unrolled Cholesky solve.

Run: PYTHONPATH=src python benchmarks/multilink_closed_loop.py
"""

import math
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402

from flexarm.control import regulation as R  # noqa: E402
from flexarm.models.multilink import MultiLinkPlant, build_multilink  # noqa: E402
from flexarm.specs.multilink import benchmark_arm  # noqa: E402


class LapackPlant(MultiLinkPlant):
    """The benchmark plant with B q̈ = f solved by jnp.linalg.solve (for comparison)."""

    def acceleration(self, x, u):
        nq = self.n_q
        q, qd = x[:nq], x[nq:]
        B, h = self._terms(q, qd, self.gamma)
        return jnp.linalg.solve(B, self._forces(q, qd, u, h))


def best(f, n=3):
    out = []
    for _ in range(n):
        t = time.perf_counter()
        jax.block_until_ready(f())
        out.append(time.perf_counter() - t)
    return min(out)


def main():
    model = build_multilink(benchmark_arm())
    deg = math.pi / 180
    p = R.regulation_params(model, [18, 18], [10, 2], [-45 * deg, 0.0])
    x0 = jnp.asarray(model.state(theta=[-90 * deg, 0.0]))
    h, n_sub, n_out = jnp.asarray(1e-4), jnp.asarray(10), 2000  # 2 s, 20000 RK4 steps

    for name, plant in (("unrolled Cholesky", model.plant),
                        ("jnp.linalg.solve", LapackPlant(**{
                            f: getattr(model.plant, f) for f in model.plant.__dataclass_fields__}))):
        args = (plant, R.law_pd_constant, p, x0, h, n_sub, n_out)
        t = time.perf_counter()
        jax.block_until_ready(R._run_rk4(*args))
        first = time.perf_counter() - t
        run = best(lambda: R._run_rk4(*args))
        print(f"{name:>18}: compile+first {first:6.2f} s, rollout {run * 1e3:7.1f} ms "
              f"({run / 80000 * 1e6:.2f} µs per RHS evaluation incl. the law)")

    batch = 32
    xs = jnp.tile(x0, (batch, 1)).at[:, 0].add(jnp.linspace(-0.1, 0.1, batch))
    vrun = eqx.filter_jit(jax.vmap(lambda x: R._run_rk4(model.plant, R.law_pd_constant, p, x,
                                                        h, n_sub, n_out)[1]))
    t = time.perf_counter()
    jax.block_until_ready(vrun(xs))
    first = time.perf_counter() - t
    run = best(lambda: vrun(xs), n=2)
    print(f"vmap batch of {batch}: compile+first {first:.2f} s, {run / batch * 1e3:.1f} ms per rollout")


if __name__ == "__main__":
    main()
