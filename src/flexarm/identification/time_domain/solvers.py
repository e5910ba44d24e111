"""The time-domain fit's two searches, one each for every engine and stage (issue #43):

* :func:`trust_region` — the one least-squares loop: SciPy ``least_squares`` (trust-region
  reflective, ``x_scale=1``) on residuals whose Jacobian the caller simulates as one batch,
  with the stop rule "Σ r² fell by less than it resolves" and restarts from the optimum
  where stick-slip friction collapsed the trust region on a kink;
* :func:`evolve` — the one global stage: SciPy ``differential_evolution`` with whole
  generations handed to the cost as one batch (``updating="deferred"``,
  ``vectorized=True``), no polish, the mutation / recombination every stage uses.

The general engine (:mod:`~flexarm.identification.time_domain.general`: its local and
global stages; :mod:`~flexarm.identification.time_domain.subset`: its friction
re-search), the rotary servo preset's stages
(:mod:`~flexarm.identification.time_domain.fit`: local, friction re-search;
:mod:`~flexarm.identification.time_domain.global_stage`) and the delay searches call
these; nothing else in ``src/`` runs a least-squares fit of a model or a differential
evolution (the cheap estimates' small regressions aside: ``estimates.tip_model``,
``controller_check``).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import OptimizeResult, differential_evolution, least_squares

__all__ = ["trust_region", "evolve", "MUTATION", "RECOMBINATION"]

#: differential evolution's dithered mutation and its crossover rate (every stage's)
MUTATION, RECOMBINATION = (0.5, 1.0), 0.7
_HAS_CALLBACK = "callback" in inspect.signature(least_squares).parameters


def trust_region(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], Any],
    x0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    *,
    max_nfev: int,
    ftol: float,
    xtol: float,
    gtol: float,
    tr_solver: str = "exact",
    resolution: bool = False,
    restarts: int = 0,
) -> OptimizeResult:
    """min ½ Σ r(x)² over lo <= x <= hi by ``least_squares(method="trf", x_scale=1.0)``.

    ``resolution``: stop when a step lowers Σ r² by less than ``ftol`` of itself (SciPy's own
    ftol test also asks the step's predicted reduction to be met, which a finite-difference
    model misses near the optimum; needs a SciPy whose ``least_squares`` takes a callback,
    else SciPy's test alone). ``restarts``: up to this many fresh trust regions from the
    optimum while evaluations are left and each lowers Σ r² by more than ``ftol`` of itself
    (stick-slip friction makes the cost non-smooth: a region that collapsed on a kink ends
    the search where a fresh one goes on). The result's ``nfev`` counts every run, its
    ``restarts`` lists each restart's fall of Σ r²."""
    last: list[float] = []

    def resolved(intermediate_result):  # the name SciPy passes the OptimizeResult to
        c = 2.0 * float(intermediate_result.cost)
        if last and 0.0 < last[-1] - c < ftol * c:
            raise StopIteration
        last.append(c)

    stop: dict[str, Any] = {"callback": resolved} if resolution and _HAS_CALLBACK else {}

    def solve(x_start, budget):
        last.clear()
        out = least_squares(
            fun,
            x_start,
            jac=jac,  # pyright: ignore[reportArgumentType]  (scipy: jac is typed from its '2-point' default)
            bounds=(lo, hi),
            method="trf",
            x_scale=1.0,
            tr_solver=tr_solver,  # pyright: ignore[reportArgumentType]
            max_nfev=budget,
            ftol=ftol,
            xtol=xtol,
            gtol=gtol,
            **stop,
        )
        if out.status == -2:  # resolved: a step lowered the cost by less than it resolves
            out.status = 2
            out.message = f"Σ r² fell by less than ftol = {ftol:.3g} of itself (COST_RESOLUTION)"
        return out

    res = solve(x0, max_nfev)
    nfev, falls = int(res.nfev), []
    for _ in range(restarts):
        if res.status <= 0 or nfev >= max_nfev:
            break
        c_before = 2.0 * float(res.cost)
        again = solve(res.x, max_nfev - nfev)
        nfev += int(again.nfev)
        gain = c_before - 2.0 * float(again.cost)
        falls.append(round(gain, 6))
        if gain <= ftol * c_before:  # not resolved: the optimum stays
            break
        res = again
    res.nfev = nfev
    res.restarts = falls
    return res


def evolve(
    f: Callable[[np.ndarray], np.ndarray],
    bounds: list[tuple[float, float]],
    *,
    x0: np.ndarray,
    popsize: int,
    maxiter: int,
    seed: int,
    tol: float,
    integrality: np.ndarray | None = None,
    callback: Callable[[Any], Any] | None = None,
) -> OptimizeResult:
    """min f over the box ``bounds`` by SciPy's differential evolution: ``f`` takes a whole
    generation, x of shape (dim, S), and returns its S costs (one batched simulation);
    seeded (``seed``), Latin-hypercube start with ``x0`` in it, ``atol`` 0, no polish."""
    return differential_evolution(
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
        mutation=MUTATION,
        recombination=RECOMBINATION,
        callback=callback,
    )
