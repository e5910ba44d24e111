"""Differential evolution over a subset of the general fit's coordinates around its local
optimum (:func:`search_subset`, option
:class:`~flexarm.identification.time_domain.options.SubsetSearch`, issue #43): the rotary
servo's friction polish as an option of the one engine, for every rig.

Stick-slip friction makes the fit's cost Σ r² of eqs. (1)–(2) jump where a simulated stop
lands on another encoder count (the quantised loop) or a joint sticks a sample earlier, so
the finite-difference Jacobian of the friction levels is unreliable and least squares
stalls on a kink. The search:

1. takes the local stage's optimum z* (and, with multiple shooting, its node-state
   offsets), after the delay search;
2. searches the coordinates of ``paths`` (default: the free joint-friction paths) by a
   batched differential evolution (:func:`~.solvers.evolve`, whole generations as one
   simulated batch) in the box z*_i ± ``width`` · (hi_i − lo_i) clipped to the bounds,
   every other coordinate and the node states held, z* itself in the first generation;
3. where the best point lowers the cost, runs the local stage again from it (with
   the node states held before as its start), and keeps that stage's optimum if it is no
   worse than the evolution's best point; else z* stands.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["search_subset"]


def search_subset(
    eng: Any,
    z: np.ndarray,
    offsets: np.ndarray | None,
    local: Callable[[np.ndarray, np.ndarray | None], tuple],
    paths: list[str],
    progress: Callable[[str], None] | None = None,
) -> tuple[dict, tuple | None]:
    """Steps 1–3 of the module docstring on the general engine ``eng``
    (``eng.options.subset_search`` read) from the optimum ``z`` (its node-state
    ``offsets``, (S, n_x), or None); ``local(z, offsets)`` runs the local stage and returns
    its (res, r, J, info). ``paths``: the free paths searched. Returns the record
    (``stages["subset_search"]``: paths, the cost at z and the evolution's best, evaluations,
    whether it was kept, seconds) and the local stage's result from the better point, or
    None where z stands."""
    opts = eng.options.subset_search
    say = progress or (lambda msg: None)
    t0 = time.perf_counter()
    idx = np.array([eng.free.index(p) for p in paths], int)
    span = (eng.hi - eng.lo)[idx]
    lo = np.maximum(z[idx] - opts.width * span, eng.lo[idx])
    hi = np.minimum(z[idx] + opts.width * span, eng.hi[idx])
    off = None if offsets is None else np.asarray(offsets)

    def f(x):
        X = np.atleast_2d(np.asarray(x).T)
        Z = np.tile(z, (X.shape[0], 1))
        Z[:, idx] = X
        offs = None if off is None else np.broadcast_to(off, (X.shape[0], *off.shape))
        R = eng.residuals(Z, offs)
        return np.sum(R * R, axis=1)

    from flexarm.identification.time_domain.solvers import evolve

    c0 = float(f(z[idx][:, None])[0])
    res = evolve(
        f,
        list(zip(lo, hi, strict=True)),
        x0=z[idx],
        popsize=opts.popsize,
        maxiter=opts.maxiter,
        seed=opts.seed,
        tol=0.0,
    )
    record: dict[str, Any] = {
        "paths": list(paths),
        "cost": c0,
        "evolution_cost": float(res.fun),
        "nfev": int(res.nfev),
        "kept": False,
    }
    out = None
    if float(res.fun) < c0:
        z1 = z.copy()
        z1[idx] = res.x
        say(f"subset search: cost {c0:.6g} -> {float(res.fun):.6g}; local stage again")
        loc = local(z1, off)
        if loc[3]["cost"] <= float(res.fun) * (1 + 1e-12):
            out = loc
            record["kept"] = True
            record["local_cost"] = float(loc[3]["cost"])
    else:
        say(f"subset search: no point below the optimum's cost {c0:.6g}")
    record["seconds"] = round(time.perf_counter() - t0, 2)
    return record, out
