"""Fixed-step integration of a plant between two sample instants.

The plant is integrated with a fixed step h = T / substeps by an explicit Runge–Kutta
solver: RK4 by default (a diffrax tableau, its step written out in :func:`rk4_step` for
speed), the others diffrax's. The plant's :meth:`~flexarm.models.plant.Plant.project` is
applied after every substep (stick events of Karnopp friction). Fixed steps do not
locate friction switches: after a stick event the hub angle is accurate to about
h·|ω| before it (docs/performance.md has the measured figures).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.models.plant import Plant


class RK4(diffrax.AbstractERK):
    """The classical 4th-order Runge–Kutta method as a diffrax solver (diffrax ships
    none): its Butcher tableau on diffrax's explicit Runge–Kutta machinery."""

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
        a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
        b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
        b_error=np.zeros(4),
        c=np.array([0.5, 0.5, 1.0]),
    )
    interpolation_cls: ClassVar[Callable] = diffrax.ThirdOrderHermitePolynomialInterpolation.from_k

    def order(self, terms):
        return 4


class Tsit5(diffrax.Tsit5):
    """diffrax's Tsit5, adaptive (PID step-size control) within each sample period: the
    loop's ``solver = "tsit5"``, for continuous-time laws only (:func:`integrate_law`)."""


#: Most steps the adaptive solver may take within one sample period.
TSIT5_MAX_STEPS = 100_000

SOLVERS = {
    "rk4": RK4,
    "euler": diffrax.Euler,
    "heun": diffrax.Heun,
    "midpoint": diffrax.Midpoint,
    "ralston": diffrax.Ralston,
    "bosh3": diffrax.Bosh3,
    "tsit5": Tsit5,
}


def solver_for(name: str) -> diffrax.AbstractSolver:
    try:
        return SOLVERS[name]()
    except KeyError:
        raise ValueError(
            f"solver = {name!r} is not known; choose one of {', '.join(SOLVERS)}"
        ) from None


def rk4_step(plant: Plant, y: Array, u: Array, h: Array) -> Array:
    """One classical RK4 step, written out (the same method as :class:`RK4`).

    diffrax runs the stages of any explicit RK method in an inner while loop, with a
    dot product of the tableau row and the stage buffer per stage (a separate kernel on
    CPU). For the single-link benchmark (667 samples x 10 substeps) that cost, measured
    in one run: 2.64 -> 1.97 ms single and 0.45 -> 0.20 ms per rollout in a vmap batch
    of 1000 (docs/performance.md). The results differ from diffrax's by rounding only
    (XLA fuses, and contracts to FMA, across other kernel boundaries): <= 4e-13 rad."""
    k1 = plant.rhs(y, u)
    k2 = plant.rhs(y + (0.5 * h) * k1, u)
    k3 = plant.rhs(y + (0.5 * h) * k2, u)
    k4 = plant.rhs(y + h * k3, u)
    return y + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4)


def integrate_hold(
    plant: Plant, x: Array, u: Array, h: Array, substeps: int, solver: diffrax.AbstractSolver
) -> Array:
    """Integrate ẋ = f(x, u) with u held for ``substeps`` steps of length ``h``."""
    if type(solver) is RK4:

        def body(_, y):
            return plant.project(y, rk4_step(plant, y, u, h), u)
    else:
        term = diffrax.ODETerm(lambda t, y, args: plant.rhs(y, args))

        def body(_, y):
            y1, _, _, _, _ = solver.step(term, 0.0, h, y, u, None, made_jump=False)
            return plant.project(y, y1, u)

    return jax.lax.fori_loop(0, substeps, body, x)


def integrate_law(
    plant: Plant,
    x: Array,
    command: Callable[[Array, Array], Array],
    t0: Array,
    h: Array,
    substeps: int,
    solver: diffrax.AbstractSolver,
    tolerances: tuple[float, float] = (1e-8, 1e-10),
) -> Array:
    """Integrate ẋ = f(x, command(x, t)) over [t0, t0 + substeps·h]: a continuous-time law
    evaluated at every stage (:class:`flexarm.control.continuous_law.ContinuousLaw`).

    Fixed-step solvers take ``substeps`` steps of h, stage times t0 + i h + c_s h (RK4
    written out as :func:`rk4_step`); the plant's ``project`` follows each step with the
    command at the step's end. ``solver`` :class:`Tsit5` is adaptive instead: diffrax's
    Tsit5 with a PID step-size controller (``tolerances`` = (rtol, atol)) over the period,
    first step h; it returns NaN (so the loop reports divergence) when it fails, e.g. when
    its step size collapses or it needs more than :data:`TSIT5_MAX_STEPS` steps."""
    if type(solver) is RK4:

        def f(y, t):
            return plant.rhs(y, command(y, t))

        def body(i, y):
            t = t0 + i * h
            y1 = _rk4_stages(f, y, t, h, unroll=y.ndim > 1)
            return plant.project(y, y1, command(y1, t + h))

        return jax.lax.fori_loop(0, substeps, body, x)

    def vector_field(t, y, args):
        return plant.rhs(y, command(y, t))

    term = diffrax.ODETerm(vector_field)
    if type(solver) is Tsit5:
        rtol, atol = tolerances
        sol = diffrax.diffeqsolve(
            term,
            diffrax.Tsit5(),
            t0,
            t0 + substeps * h,
            h,
            x,
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            max_steps=TSIT5_MAX_STEPS,
            throw=False,
        )
        assert sol.ys is not None  # saved at t1 (diffeqsolve's default)
        return jnp.where(sol.result == diffrax.RESULTS.successful, sol.ys[-1], jnp.nan)

    def step(i, y):
        t = t0 + i * h
        y1, _, _, _, _ = solver.step(term, t, t + h, y, None, None, made_jump=False)
        return plant.project(y, y1, command(y1, t + h))

    return jax.lax.fori_loop(0, substeps, step, x)


_RK4_A = (0.0, 0.5, 0.5, 1.0)
_RK4_W = (1.0 / 6.0, 2.0 / 6.0, 2.0 / 6.0, 1.0 / 6.0)


def _rk4_stages(f: Callable[[Array, Array], Array], x: Array, t, h, *, unroll: bool) -> Array:
    """One classical RK4 step of ẋ = f(x, t): x + h Σ_s w_s k_s, k_s = f(x + a_s h k_(s−1),
    t + a_s h). The stages run in a scan (``unroll=False``: for one rollout as fast as
    written out, and 2.2x quicker to compile: 0.64 s against 2.7 s for the De Luca arm) or
    written out (``unroll=True``: for a batch carried as (n_x, B), 28 % less time per
    rollout, because XLA then fuses each stage's x + a·h·k into the kernels of the
    right-hand side instead of running a loop of separate kernels per stage). Both compute
    the same sums in the same order."""
    if unroll:
        acc, kk = jnp.zeros_like(x), jnp.zeros_like(x)
        for a, w in zip(_RK4_A, _RK4_W, strict=True):
            kk = f(x + a * h * kk, t + a * h)
            acc = acc + w * kk
        return x + h * acc

    def stage(c, ab):
        acc, kk = c
        kk = f(x + ab[0] * h * kk, t + ab[0] * h)
        return (acc + ab[1] * kk, kk), None

    (acc, _), _ = jax.lax.scan(
        stage, (jnp.zeros_like(x), jnp.zeros_like(x)), (jnp.array(_RK4_A), jnp.array(_RK4_W))
    )
    return x + h * acc


def rk4_path(
    f: Callable[[Array, Array], Array], x0: Array, h, n_sub, n_out: int, *, unroll: bool = False
) -> Array:
    """Classical RK4 for ẋ = f(x, t) with step h from x0 (shape (n_x, *batch)), n_sub steps
    per output, n_out outputs: the states at 0, n_sub·h, …, shape (n_out + 1, *x0.shape).

    Not a closed-loop simulator (that is :mod:`flexarm.sim.sampled`, which runs continuous
    laws too, :func:`integrate_law`): a plain integrator of a given ẋ = f(x, t), e.g. free
    motion (tests/test_models__properties.py). Stages as :func:`_rk4_stages`."""

    def step(k, carry):
        x, t = carry
        return _rk4_stages(f, x, t, h, unroll=unroll), t + h

    def sample(carry, _):
        carry = jax.lax.fori_loop(0, n_sub, step, carry)
        return carry, carry[0]

    _, xs = jax.lax.scan(sample, (x0, jnp.zeros(())), None, length=n_out)
    return jnp.concatenate([x0[None], xs])
