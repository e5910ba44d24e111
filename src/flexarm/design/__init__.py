"""Controller design for a fitted rig: state feedback (``lqr``, ``place``), Feliu's nested
loops (``nested``) and gains tuned in simulation over the fit's uncertainty (``tune``).

The front door :func:`design` dispatches on the method through :data:`METHODS` (method →
the function that designs it, each ``f(scenario, **options) -> Design``); a new method adds
one entry there.

:func:`flexarm.design.gate.design_checked` is what ``flexarm design`` calls: the
design, compared with the scenario's own controller, with the gate's verdict (``"stable"``
or what failed), refused unless accepted.

``flexarm.design`` is both this package and the front door: the package is callable,
``flexarm.design(scenario, "lqr")`` is :func:`design`, and its modules stay importable
(``import flexarm.design.linear``)."""

from __future__ import annotations

import sys
import types
from collections.abc import Callable
from typing import Any

from flexarm.design.result import Design

# design_checked and GateOptions live in flexarm.design.gate, which imports design() from
# here: re-exporting them here made the two modules import each other (issue #43)
__all__ = ["Design", "METHODS", "design"]


def _lqr(
    scenario,
    *,
    plants=None,
    count: float | None = None,
    max_rounds: int = 4,
    check_duration: float = 6.0,
    **options,
) -> Design:
    """``lqr``; with ``plants`` (a :class:`~flexarm.design.plants.PlantBatch`) made robust
    over them: while a drawn plant is unstable or reaches the command limit in the
    comparison's step (:func:`flexarm.design.compare.compare`, ``check_duration`` s; ``count``
    the encoder count where the scenario has none), the command weight R is
    raised fourfold and the design redone (at most ``max_rounds`` times). The round with
    the fewest failures is kept (nominal plant unstable first, then drawn plants unstable
    or at the limit; the later round on a tie): a higher R is not always safer (a slower
    loop leaves a hub stuck in its friction band). A warning says when the kept round still
    fails. A design on the nominal plant alone knows nothing of the spread: on unit 7's fit
    the default weights left 5 of 200 plants unstable."""
    import numpy as np

    from flexarm.design.linear import design_linear

    des = design_linear(scenario, "lqr", **options)
    if plants is None or len(plants) == 0:
        return des
    from flexarm.design.compare import compare

    history = []
    best = None
    n = len(plants)
    for k in range(max_rounds + 1):
        row = compare(plants, {"lqr": des}, logged=None, count=count, duration=check_duration).rows[
            "lqr"
        ]
        r = list(des.info["weights"]["r"])
        history.append(
            {
                "r": r,
                "unstable": row["unstable"],
                "nominal_stable": row["nominal_stable"],
                "limit_respected": row["limit_respected"],
            }
        )
        fails = (not row["nominal_stable"], row["unstable"] + (0 if row["limit_respected"] else n))
        if best is None or fails <= best[0]:
            best = (fails, des, k)
        if fails == (False, 0):
            break
        if k == max_rounds:
            break
        des = design_linear(scenario, "lqr", **{**options, "r": (4 * np.asarray(r)).tolist()})
    assert best is not None  # one round at least (max_rounds >= 0)
    fails, des, kept = best
    if fails != (False, 0):
        h = history[kept]
        des.warnings.append(
            f"over the {n} plants the best of {len(history)} rounds (R x{4**kept}) leaves "
            f"{'the nominal plant unstable, ' if not h['nominal_stable'] else ''}"
            f"{h['unstable']} unstable"
            f"{'' if h['limit_respected'] else ' and reaches the limit'} (R raised up to "
            f"{4 ** (len(history) - 1)}-fold): the spread of the fit is too wide for one "
            "linear design; tune over the plants (method 'tune') or fit longer logs"
        )
    des.info["robust_over_plants"] = {"n_plants": n, "rounds": history, "kept_round": kept}
    return des


def _place(scenario, **options) -> Design:
    from flexarm.design.linear import design_linear

    return design_linear(scenario, "place", **options)


def _nested(scenario, **options) -> Design:
    from flexarm.design.nested import design_nested

    return design_nested(scenario, **options)


def _tune(
    scenario, *, plants=None, spread=None, n_plants: int = 200, plant_seed: int = 0, **options
) -> Design:
    """``tune`` over ``plants`` (a :class:`~flexarm.design.plants.PlantBatch`, e.g.
    :func:`~flexarm.design.plants.from_fit` of a fit result), or over ``n_plants`` drawn from
    ``spread`` (scenario path → (mean, std), :func:`~flexarm.design.plants.from_paths`)."""
    from flexarm.design.plants import from_paths
    from flexarm.design.tune import design_tune

    if plants is None:
        if not spread:
            raise ValueError(
                "method 'tune' needs the plants to tune over: plants= (e.g. "
                "flexarm.design.plants.from_fit(fit_result, 200)) or spread= "
                "{path: (mean, std)}"
            )
        plants = from_paths(scenario, spread, n_plants, seed=plant_seed)
    return design_tune(scenario, plants, **options)


#: method name → designer ``f(scenario, **options) -> Design``
METHODS: dict[str, Callable[..., Design]] = {
    "lqr": _lqr,
    "place": _place,
    "nested": _nested,
    "tune": _tune,
}


def design(scenario: Any, method: str = "lqr", **options) -> Design:
    """Design a controller for ``scenario`` (a :class:`flexarm.specs.scenario.Scenario`, a
    scenario file or a built-in name) by ``method`` (a key of :data:`METHODS`); the options
    are the method's (``lqr``/``place``: :func:`flexarm.design.linear.design_linear`;
    ``nested``: :func:`flexarm.design.nested.design_nested`; ``tune``: :func:`_tune`)."""
    if method not in METHODS:
        raise ValueError(f"method = {method!r} is not known; choose one of {', '.join(METHODS)}")
    if isinstance(scenario, str) or hasattr(scenario, "__fspath__"):
        from flexarm.specs import load_scenario

        scenario = load_scenario(str(scenario))
    return METHODS[method](scenario, **options)


class _CallablePackage(types.ModuleType):
    """This package, callable as :func:`design` (so ``flexarm.design(...)`` designs and
    ``flexarm.design.linear`` is still the module)."""

    def __call__(self, scenario: Any, method: str = "lqr", **options) -> Design:
        return design(scenario, method, **options)


sys.modules[__name__].__class__ = _CallablePackage
