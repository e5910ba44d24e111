"""The one least-squares loop and the one global stage (``identification.time_domain.
solvers``), on problems whose optimum is known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.identification.time_domain.solvers import evolve, trust_region


def _rosenbrock():
    def fun(x):  # r = (10 (x1 - x0²), 1 - x0): ½ Σ r² is Rosenbrock's, optimum (1, 1)
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])

    def jac(x):
        return np.array([[-20 * x[0], 10.0], [-1.0, 0.0]])

    return fun, jac


def test_trust_region_finds_rosenbrocks_optimum_within_bounds():
    fun, jac = _rosenbrock()
    res = trust_region(
        fun, jac, np.array([-1.2, 1.0]), np.full(2, -5.0), np.full(2, 5.0),
        max_nfev=200, ftol=1e-12, xtol=1e-12, gtol=1e-12,
    )  # fmt: skip
    assert res.x == pytest.approx([1.0, 1.0], abs=1e-8)
    assert res.restarts == [] and res.nfev <= 200


def test_trust_region_stops_on_the_bound_it_is_given():
    fun, jac = _rosenbrock()
    # x0 <= 0.5: the constrained optimum is on the bound, x0 = 0.5, x1 = x0² = 0.25
    res = trust_region(
        fun, jac, np.array([0.0, 0.0]), np.array([-5.0, -5.0]), np.array([0.5, 5.0]),
        max_nfev=200, ftol=1e-12, xtol=1e-12, gtol=1e-12, resolution=True, restarts=2,
    )  # fmt: skip
    assert res.x == pytest.approx([0.5, 0.25], abs=1e-6)
    assert len(res.restarts) <= 2


def test_evolve_takes_whole_generations_and_finds_the_minimum():
    seen = []

    def f(x):  # x: (dim, S); a bowl with its minimum at (0.3, -0.2)
        seen.append(x.shape)
        return (x[0] - 0.3) ** 2 + (x[1] + 0.2) ** 2

    res = evolve(f, [(-1, 1), (-1, 1)], x0=np.zeros(2), popsize=10, maxiter=200, seed=1, tol=0.0)
    assert res.x == pytest.approx([0.3, -0.2], abs=1e-3)
    assert all(s[0] == 2 and s[1] >= 10 for s in seen[1:])  # batches of a generation


def test_evolve_searches_integer_coordinates():
    def f(x):
        return (x[0] - 0.5) ** 2 + (x[1] - 3.0) ** 2

    res = evolve(
        f, [(0, 1), (0, 9)], x0=np.array([0.0, 0.0]), popsize=10, maxiter=100, seed=0, tol=0.0,
        integrality=np.array([False, True]),
    )  # fmt: skip
    assert res.x[1] == 3.0 and res.x[0] == pytest.approx(0.5, abs=1e-3)
