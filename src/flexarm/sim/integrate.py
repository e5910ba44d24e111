"""Fixed-step integration of a plant between two sample instants.

The plant is integrated with a fixed step h = T / substeps by an explicit Runge–Kutta
solver: RK4 by default (a diffrax tableau, its step written out in :func:`rk4_step` for
speed), the others diffrax's. The plant's :meth:`~flexarm.sim.plant.Plant.project` is
applied after every substep (stick events of Karnopp friction). Fixed steps do not
locate friction switches: after a stick event the hub angle is accurate to about
h·|ω| before it (docs/performance.md has the measured figures).
"""

from __future__ import annotations

from typing import Callable, ClassVar

import diffrax
import jax
import numpy as np
from jax import Array

from flexarm.sim.plant import Plant


class RK4(diffrax.AbstractERK):
    """The classical 4th-order Runge–Kutta method as a diffrax solver (diffrax ships
    none): its Butcher tableau on diffrax's explicit Runge–Kutta machinery."""

    tableau: ClassVar[diffrax.ButcherTableau] = diffrax.ButcherTableau(
        a_lower=(np.array([0.5]), np.array([0.0, 0.5]), np.array([0.0, 0.0, 1.0])),
        b_sol=np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]),
        b_error=np.zeros(4),
        c=np.array([0.5, 0.5, 1.0]),
    )
    interpolation_cls: ClassVar[Callable] = (
        diffrax.ThirdOrderHermitePolynomialInterpolation.from_k
    )

    def order(self, terms):
        return 4


SOLVERS = {
    "rk4": RK4,
    "euler": diffrax.Euler,
    "heun": diffrax.Heun,
    "midpoint": diffrax.Midpoint,
    "ralston": diffrax.Ralston,
    "bosh3": diffrax.Bosh3,
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


def integrate_hold(plant: Plant, x: Array, u: Array, h: Array, substeps: int,
                   solver: diffrax.AbstractSolver) -> Array:
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
