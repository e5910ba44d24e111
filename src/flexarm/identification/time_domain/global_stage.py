"""Global, derivative-free stage: SciPy's differential evolution over the unit box (the one
global stage, :func:`~flexarm.identification.time_domain.solvers.evolve`).

Stick-slip makes the output-error cost piecewise and jumpy, so a gradient method started
from nominal values stalls. Differential evolution (seeded, ``updating='deferred'``,
``vectorized=True``) hands each whole generation to :meth:`Objective.cost`, which
simulates it in one batched JAX call. Continuous parameters live in [0, 1] (see
:mod:`flexarm.identification.time_domain.params`); the sensor delays and the tip-gain sign are
integer coordinates (``integrality``). Where both delays are free and their ranges leave the
order open (nothing ties them down), the tip delay is searched as the hub's plus a lag
≥ 0 (``tip_after_hub``): an encoder reads the hub at once, a strain gauge's conditioning
only adds lag.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from flexarm.identification.time_domain.objective import Objective
from flexarm.identification.time_domain.solvers import evolve


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
    tip_after_hub: bool = False,
) -> GlobalResult:
    """Minimise :meth:`Objective.cost` over the continuous unit coordinates and the free
    discrete coordinates; ``u0``, ``d0`` seed the initial population. ``best`` (a dict),
    when given, holds the best point after every generation (U, D, cost).

    ``tip_after_hub``: where both delays are free and the tip range [t_lo, t_hi] starts
    no later than the hub range [h_lo, h_hi] (:func:`ordered_delays`), the second
    integer coordinate is a lag ℓ ∈ [0, t_hi − h_lo] and the tip delay is
    clip(hub + ℓ, t_lo, t_hi) ≥ hub; elsewhere it changes nothing."""
    n = obj.space.n_cont
    dbounds = obj.space.discrete_bounds()
    free = [i for i, (lo, hi) in enumerate(dbounds) if hi > lo]
    fixed_d = np.array([lo for lo, _ in dbounds], float)
    # the caller orders where the ranges leave the order open (:func:`ordered_delays`), or
    # again after a free search over overlapping ranges put the tip first
    lagged = tip_after_hub and (ordered_delays(dbounds) or overlapping_delays(dbounds))
    cbounds = list(dbounds)
    if lagged:
        cbounds[1] = (0, dbounds[1][1] - dbounds[0][0])  # ℓ ∈ [0, t_hi − h_lo]
    bounds = [(0.0, 1.0)] * n + [cbounds[i] for i in free]
    integrality = np.array([False] * n + [True] * len(free))

    def split(x):  # x: (dim, S)
        X = np.atleast_2d(x.T) if x.ndim == 2 else x[None]
        U = np.clip(X[:, :n], 0.0, 1.0)
        D = np.tile(fixed_d, (X.shape[0], 1))
        D[:, free] = np.round(X[:, n:])
        if lagged:
            D[:, 1] = np.clip(D[:, 0] + D[:, 1], dbounds[1][0], dbounds[1][1])
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

    c0 = np.asarray(d0, float).copy()
    if lagged:  # the start's delays as hub and lag
        c0[1] = np.clip(c0[1] - c0[0], *cbounds[1])
    x0 = np.concatenate([np.clip(u0, 0, 1), c0[free]])
    t0 = time.perf_counter()
    res = evolve(
        f,
        bounds,
        x0=x0,
        popsize=popsize,
        maxiter=maxiter,
        seed=seed,
        tol=tol,
        integrality=integrality,
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


def ordered_delays(dbounds) -> bool:
    """Whether ``tip_after_hub`` orders the search over the discrete bounds ``dbounds``
    ((hub delay), (tip delay), (sign); samples): both delays free and the ranges leaving
    their order open, the tip's starting no later than the hub's (no trusted hub → tip
    lag placed it after: 0 ... max_delay for both, or ``estimates=False``). A range that
    a trusted lag put after the hub's is searched as it is (units 6 and 7); where it still
    overlaps the hub's (:func:`overlapping_delays`) and the tip comes out before the hub,
    the fit searches again in order (:func:`~.fit.fit`)."""
    (h_lo, h_hi), (t_lo, t_hi) = dbounds[0], dbounds[1]
    return h_hi > h_lo and t_hi > t_lo and t_lo <= h_lo


def overlapping_delays(dbounds) -> bool:
    """Both delays free and the tip's range starting after the hub's start but before its
    end: the order is open although :func:`ordered_delays` is not (unit 7: an untrusted
    hub over 0 ... 100 samples, the tip's range from a trusted hub → tip lag). Searched
    freely, unit 7 came out hub 85 / tip 64 samples with a 1.5 g tip (held out 82.4 /
    63.2 %); searched again in order, 34 / 68 (85.7 / 57.8 %)."""
    (h_lo, h_hi), (t_lo, t_hi) = dbounds[0], dbounds[1]
    return h_hi > h_lo and t_hi > t_lo and h_lo < t_lo < h_hi
