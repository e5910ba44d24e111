"""Global, derivative-free stage: SciPy's differential evolution over the unit box.

Stick-slip makes the output-error cost piecewise and jumpy, so a gradient method started
from nominal values stalls. Differential evolution (seeded, ``updating='deferred'``,
``vectorized=True``) hands each whole generation to :meth:`Objective.cost`, which
simulates it in one batched JAX call. Continuous parameters live in [0, 1] (see
:mod:`flexarm.identification.time_domain.params`); the sensor delays and the tip-gain sign are
integer coordinates (``integrality``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from flexarm.identification.time_domain.objective import Objective


@dataclass
class GlobalResult:
    U: np.ndarray  # best unit coordinates (n_cont,)
    D: np.ndarray  # best discrete (3,) = angle delay, tip delay, sign 0/1
    cost: float
    nfev: int
    nit: int
    success: bool
    message: str
    seconds: float
    population_cost: np.ndarray


def differential_evolution_stage(
    obj: Objective,
    u0: np.ndarray,
    d0: np.ndarray,
    *,
    popsize: int = 8,
    maxiter: int = 40,
    seed: int = 0,
    tol: float = 1e-3,
    progress: Callable[[int, float], None] | None = None,
    best: dict | None = None,
) -> GlobalResult:
    """Minimise :meth:`Objective.cost` over the continuous unit coordinates and the free
    discrete coordinates; ``u0``, ``d0`` seed the initial population. ``best`` (a dict),
    when given, holds the best point after every generation (U, D, cost)."""
    n = obj.space.n_cont
    dbounds = obj.space.discrete_bounds()
    free = [i for i, (lo, hi) in enumerate(dbounds) if hi > lo]
    fixed_d = np.array([lo for lo, _ in dbounds], float)
    bounds = [(0.0, 1.0)] * n + [dbounds[i] for i in free]
    integrality = np.array([False] * n + [True] * len(free))

    def split(x):  # x: (dim, S)
        X = np.atleast_2d(x.T) if x.ndim == 2 else x[None]
        U = np.clip(X[:, :n], 0.0, 1.0)
        D = np.tile(fixed_d, (X.shape[0], 1))
        D[:, free] = np.round(X[:, n:])
        return U, D.astype(int)

    it = [0]

    def f(x):
        U, D = split(x)
        return obj.cost(U, D)

    def cb(intermediate_result):
        it[0] += 1
        if best is not None:  # the best point so far, for an interrupted fit
            U, D = split(np.asarray(intermediate_result.x)[:, None])
            best.update(U=U[0], D=D[0], cost=float(intermediate_result.fun))
        if progress is not None:
            progress(it[0], float(intermediate_result.fun))

    x0 = np.concatenate([np.clip(u0, 0, 1), np.asarray(d0, float)[free]])
    t0 = time.perf_counter()
    res = differential_evolution(
        f,
        bounds,
        popsize=popsize,
        maxiter=maxiter,
        tol=tol,
        atol=0.0,
        seed=seed,  # pyright: ignore[reportCallIssue]  (scipy: seed, still accepted, is hidden by its rng decorator)
        updating="deferred",
        vectorized=True,
        polish=False,
        init="latinhypercube",
        integrality=integrality,
        x0=x0,
        mutation=(0.5, 1.0),
        recombination=0.7,
        callback=cb,
    )
    U, D = split(res.x[:, None])
    return GlobalResult(
        U[0],
        D[0],
        float(res.fun),
        int(res.nfev),
        int(res.nit),
        bool(res.success),
        str(res.message),
        time.perf_counter() - t0,
        np.asarray(res.population_energies),
    )
