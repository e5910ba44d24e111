"""Fixed-step integration of a plant between two sample instants.

The plant is integrated with a fixed step h = T / substeps by a diffrax explicit
Runge–Kutta solver (RK4 by default), and its :meth:`~flexarm.sim.plant.Plant.project`
is applied after every substep (stick events of Karnopp friction). Fixed steps do not
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


def integrate_hold(plant: Plant, x: Array, u: Array, h: Array, substeps: int,
                   solver: diffrax.AbstractSolver) -> Array:
    """Integrate ẋ = f(x, u) with u held for ``substeps`` steps of length ``h``."""
    term = diffrax.ODETerm(lambda t, y, args: plant.rhs(y, args))

    def body(_, y):
        y1, _, _, _, _ = solver.step(term, 0.0, h, y, u, None, made_jump=False)
        return plant.project(y, y1, u)

    return jax.lax.fori_loop(0, substeps, body, x)
