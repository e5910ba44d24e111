"""Plants drawn from a fit's parameter uncertainty, run as one ``vmap``-ed batch.

Two sources:

* :func:`from_fit`: a servo-rig fit (:class:`flexarm.identification.time_domain.FitResult`).
  The fit searches each parameter p_i in a unit coordinate u_i (``log``: p = lo (hi/lo)^u;
  ``loglin``: p = lo + (hi − lo)(e^{a u} − 1)/(e^a − 1); ``lin``; see
  :mod:`flexarm.identification.time_domain.params`) and its Newey–West (HAC) covariance Σ_u
  is linearised there (``stages['local']['covariance_unit']``). A draw is

      u⁽ʲ⁾ ~ N(û, Σ_u),   p⁽ʲ⁾ = p(u⁽ʲ⁾)                                          (1)

  in those coordinates, so log-scaled parameters (inertias, link frequency, damping, gauge
  gain) stay positive by construction; a draw with a negative friction level
  (``loglin`` below its lower bound 0) or a value the scenario schema refuses (a link
  damping ratio above 1) is rejected and drawn again (a truncated normal: the fraction
  rejected is reported in ``info``). Without the full covariance (fits made
  before it was kept) the coordinates are drawn independently with the fit's std_u =
  std / |dp/du|. A coordinate whose std_u exceeds :data:`UNDETERMINED` (the normal then
  spans the whole search box within ±2σ) is not determined by the data (a parameter at a
  bound, e.g. a breakaway excess fitted at 0): it is held at its fitted value (the marginal
  of the others, which keeps their std equal to the fit's) and a warning says so.
  Each draw becomes the fitted scenario through the fit's own mapping
  (:func:`flexarm.identification.time_domain.report.scenario_from_fit`).

* :func:`from_paths`: any scenario and ``{path: (mean, std)}`` (paths as in the general
  fit, ``"arm.friction.coulomb"``, ``"sensors.tip_deflection.gain"``), independent draws.
  A parameter with a non-zero mean is drawn log-normal with exactly that mean and std,

      ln|p| ~ N(μ, σ²),  σ² = ln(1 + (s/m)²),  μ = ln|m| − σ²/2,  p = sgn(m)·e^{ln|p|}   (2)

  (so it keeps its sign: a physical magnitude never crosses zero); a zero mean is drawn
  normal. Each draw is set into the scenario by the general fit's
  :func:`~flexarm.specs.paths.scenario_with` and validated.

A :class:`PlantBatch` holds the nominal scenario and the N drawn ones; :meth:`PlantBatch.loop`
prepares them (:func:`flexarm.sim.build.prepare`) and stacks their loops leaf by leaf
(:func:`flexarm.sim.batch.stack_loops`) into one
:class:`BatchLoop` that :func:`flexarm.sim.sampled.simulate_batch` runs in one call, the
nominal plant first (rollout 0) and the N draws after it.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "PlantBatch",
    "PlantSource",
    "BatchLoop",
    "chunk_plants",
    "from_fit",
    "from_paths",
    "nominal_batch",
    "with_overrides",
    "UNDETERMINED",
]

#: std of a unit coordinate above which the data do not determine it (see module doc)
UNDETERMINED = 0.5


class Replace(dict):
    """An override table that replaces the scenario's table instead of being merged into it
    (:func:`with_overrides`; e.g. another ``[controller]`` type)."""


def _merge(d: dict, over: Mapping) -> dict:
    for k, v in over.items():
        if v is None:  # None removes the field (back to its default)
            d.pop(k, None)
        elif isinstance(v, Replace):  # a whole table replaced, not merged
            d[k] = copy.deepcopy(dict(v))
        elif isinstance(v, Mapping) and isinstance(d.get(k), dict):
            _merge(d[k], v)
        else:
            d[k] = copy.deepcopy(v)
    return d


def with_overrides(scenario, overrides: Mapping | None, source: str = "scenario"):
    """The scenario with the nested dict ``overrides`` merged into its fields (e.g.
    ``{"reference": {"type": "step", ...}, "simulation": {"duration": 2.0}}``; a None value
    removes that field), validated."""
    if not overrides:
        return scenario
    from flexarm.specs.scenario import scenario_from_dict

    d = _merge(scenario.model_dump(mode="json", exclude_none=True), overrides)
    return scenario_from_dict(
        d, source=f"{source} ({scenario.name!r} with {', '.join(overrides)} changed)"
    )


@dataclass
class BatchLoop:
    """The N + 1 plants' loops stacked leaf by leaf (rollout 0 the nominal plant), one
    controller, the shared initial state, references and sample times."""

    loop: Any
    x0: np.ndarray
    references: dict[str, np.ndarray]
    time: np.ndarray
    prepared: Any  # the nominal plant's flexarm.sim.build.Prepared
    size: int

    def with_controller(self, controller) -> BatchLoop:
        """The same plants under another controller (one :class:`Controller`, its leaves
        broadcast to every rollout): no plant is prepared again, and a controller of the
        same structure reuses the compiled batch."""
        from flexarm.sim.build import _measured_names

        missing = sorted(_measured_names(controller) - set(self.loop.sensors.names))
        if missing:
            raise ValueError(
                f"the controller reads {', '.join(missing)}, which the plants' "
                f"sensors ({', '.join(self.loop.sensors.names)}) do not measure; "
                "add [sensors.NAME] to the rig scenario"
            )
        n = self.size
        tiled = jax.tree.map(
            lambda a: jnp.broadcast_to(a, (n,) + jnp.shape(a)), eqx.filter(controller, eqx.is_array)
        )
        ctrl = eqx.combine(tiled, eqx.filter(controller, eqx.is_array, inverse=True))
        return dataclasses.replace(
            self, loop=eqx.tree_at(lambda lp: lp.controller, self.loop, ctrl)
        )

    def run(self, *, seed: int = 0) -> dict[str, np.ndarray]:
        """One :func:`~flexarm.sim.sampled.simulate_batch` call; diverged rollouts are
        returned as they are (flagged by :func:`diverged`), not raised."""
        from flexarm.sim.sampled import simulate_batch

        # no client or chunks: the arrays themselves
        return cast(
            "dict[str, np.ndarray]",
            simulate_batch(
                self.loop, self.x0, self.references, len(self.time), seed=seed, check=False
            ),
        )


def diverged(out: dict) -> np.ndarray:
    """(B,) rollouts whose signals left the finite range ±DIVERGENCE_LIMIT (SI)."""
    from flexarm.sim.sampled import DIVERGENCE_LIMIT

    s = out["signals"]
    return ~np.all(np.isfinite(s) & (np.abs(s) <= DIVERGENCE_LIMIT), axis=(1, 2))


@dataclass
class PlantBatch:
    """``nominal``: the fitted (or given) scenario; ``scenarios``: the N drawn ones;
    ``values``: parameter → (N,) drawn values (SI); ``coordinates``: (N, k) the draws in
    the coordinates they were drawn in (:func:`from_fit`: the fit's unit coordinates of
    ``names``; :func:`from_paths`: the SI values), ``center`` / ``scale`` their mean and
    std; ``seed``; ``warnings``; ``info`` (rejections, held parameters)."""

    nominal: Any
    scenarios: list
    values: dict[str, np.ndarray]
    names: list[str]
    coordinates: np.ndarray
    center: np.ndarray
    scale: np.ndarray
    seed: int
    warnings: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.scenarios)

    @classmethod
    def nominal_only(cls, scenario) -> PlantBatch:
        """The scenario alone, no drawn plants (a comparison on the nominal plant)."""
        return cls(
            scenario,
            [],
            {},
            [],
            np.zeros((0, 0)),
            np.zeros(0),
            np.zeros(0),
            0,
            [],
            {"source": "the nominal plant only", "n": 0},
        )

    def with_overrides(self, overrides: Mapping | None) -> PlantBatch:
        """Every plant (and the nominal) with the same experiment changes (reference,
        duration, sensor quantum, controller) merged in (:func:`with_overrides`)."""
        if not overrides:
            return self
        return dataclasses.replace(
            self,
            nominal=with_overrides(self.nominal, overrides, "nominal plant"),
            scenarios=[
                with_overrides(s, overrides, f"plant {i}") for i, s in enumerate(self.scenarios)
            ],
        )

    def loop(self, controller=None, *, include_nominal: bool = True) -> BatchLoop:
        """Prepare every plant (the nominal first) with ``controller`` (a
        :class:`~flexarm.control.discrete.Controller`; default the nominal scenario's
        ``[controller]``) and stack the loops."""
        from flexarm.sim.batch import stack_loops
        from flexarm.sim.build import prepare

        scns = ([self.nominal] if include_nominal else []) + list(self.scenarios)
        p0 = prepare(scns[0], controller)
        ctrl = p0.loop.controller if controller is None else controller
        preps = [p0] + [prepare(s, ctrl) for s in scns[1:]]
        x0s = np.stack([p.x0 for p in preps])
        if not np.allclose(x0s, x0s[:1], rtol=0, atol=1e-12):
            raise ValueError(
                "the plants' initial states differ (an initial tip deflection "
                "maps onto each plant's own beam); start them at rest "
                "(initial.tip_deflection = 0) to run them as one batch"
            )
        return BatchLoop(
            stack_loops([p.loop for p in preps]), x0s[0], p0.references, p0.time, p0, len(preps)
        )


# ----------------------------------------------------------------------------- lazily drawn
@dataclass(frozen=True, eq=False)
class PlantSource:
    """N plants drawn chunk by chunk where they run: chunk j (plants [a, b)) is
    ``draw(b - a, seed=chunk_seed(seed, j))`` (a :class:`PlantBatch`;
    :func:`flexarm.sim.batch.chunk_seed`), so 10^6 plants never exist on the client.
    ``draw`` must be picklable (a module-level function or a ``functools.partial`` of one):
    :meth:`from_fit` and :meth:`from_paths` build it."""

    draw: Callable[..., Any]
    n: int
    seed: int = 0
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_fit(cls, result, n: int, *, seed: int = 0) -> PlantSource:
        """Plants drawn from a fit's covariance (:func:`from_fit`), chunk by chunk."""
        return cls(
            functools.partial(from_fit, result),
            int(n),
            int(seed),
            {"source": "flexarm.design.plants.from_fit, seeds per chunk"},
        )

    @classmethod
    def from_paths(
        cls, scenario, spread: Mapping[str, tuple[float, float]], n: int, *, seed: int = 0
    ) -> PlantSource:
        """Independent draws (:func:`from_paths`), chunk by chunk."""
        return cls(
            functools.partial(from_paths, scenario, dict(spread)),
            int(n),
            int(seed),
            {"source": "flexarm.design.plants.from_paths, seeds per chunk"},
        )

    def __len__(self) -> int:
        return self.n

    @functools.cached_property
    def nominal(self):
        """The nominal (fitted or given) scenario."""
        from flexarm.sim.batch import chunk_seed

        return self.draw(1, seed=chunk_seed(self.seed, 0)).nominal

    @property
    def warnings(self) -> list[str]:
        from flexarm.sim.batch import chunk_seed

        return list(self.draw(1, seed=chunk_seed(self.seed, 0)).warnings)


def chunk_plants(plants: PlantBatch | PlantSource, j: int, a: int, b: int) -> PlantBatch:
    """Chunk j's plants as a PlantBatch (the nominal plant and plants [a, b)): a
    :class:`PlantSource` draws them with chunk j's seed, a :class:`PlantBatch` is sliced."""
    if isinstance(plants, PlantSource):
        from flexarm.sim.batch import chunk_seed

        return plants.draw(b - a, seed=chunk_seed(plants.seed, j))
    vals = {k: np.asarray(v)[a:b] for k, v in plants.values.items()}
    coords = np.asarray(plants.coordinates)
    return dataclasses.replace(
        plants,
        scenarios=list(plants.scenarios[a:b]),
        values=vals,
        coordinates=coords[a:b] if coords.shape[0] else coords,
    )


def nominal_batch(plants: PlantBatch | PlantSource) -> PlantBatch:
    """The nominal plant alone (a source's first draw supplies it)."""
    return PlantBatch.nominal_only(plants.nominal)


# ----------------------------------------------------------------------------- from a fit
def from_fit(
    result, n: int = 200, *, seed: int = 0, undetermined: float = UNDETERMINED, max_rounds: int = 50
) -> PlantBatch:
    """N plants drawn from a servo-rig fit's uncertainty, eq. (1) of the module doc.
    ``result``: the servo rig's result (:func:`flexarm.fit` of the servo-rig preset, whose
    ``engine_result`` it uses, or the rig engine's own)."""
    from flexarm.identification.time_domain.params import derived
    from flexarm.identification.time_domain.report import scenario_from_fit
    from flexarm.specs.scenario import ScenarioError, scenario_from_dict

    if n < 1:
        raise ValueError(f"n = {n}: the number of plants must be >= 1")
    result = getattr(result, "engine_result", None) or result
    space, U = result.space, np.asarray(result.unit, float)
    if space is None or U is None:
        raise ValueError(
            "the fit result has no search space (space/unit): it was not made "
            "by flexarm.identification.time_domain.fit; draw from_paths instead"
        )
    names, defs = list(space.names), list(space.defs)
    k = len(names)
    std_u = np.asarray(
        [
            result.std[nm] / abs(float(d.dphys_du(U[i])))
            if abs(float(d.dphys_du(U[i]))) > 0
            else np.nan
            for i, (nm, d) in enumerate(zip(names, defs, strict=True))
        ]
    )
    cov = result.stages.get("local", {}).get("covariance_unit")
    warnings: list[str] = []
    if cov is not None:
        cov = np.asarray(cov, float)
        std_u = np.sqrt(np.maximum(np.diag(cov), 0.0))
        source = "full HAC covariance of the fit (unit coordinates)"
    else:
        cov = np.diag(np.nan_to_num(std_u) ** 2)
        source = "independent normals with the fit's HAC std (no covariance in the result)"
        warnings.append(
            "the fit result holds no parameter covariance: parameters drawn "
            "independently (correlations ignored); refit with this flexarm to "
            "keep stages['local']['covariance_unit']"
        )
    bad = ~np.isfinite(std_u) | ~np.all(np.isfinite(cov), axis=1)
    held = [i for i in range(k) if bad[i] or std_u[i] > undetermined]
    for i in held:
        warnings.append(
            f"{names[i]} = {result.params[names[i]]:.4g} {defs[i].unit} is not determined by "
            f"the data (std {std_u[i]:.3g} in its search coordinate, more than "
            f"{undetermined} of the [0, 1] search box): held at its fitted value in every plant"
        )
    free = [i for i in range(k) if i not in held]
    rng = np.random.default_rng(seed)
    sign = {
        nm: (-1.0 if result.params.get(nm, 1.0) < 0 else 1.0)
        for nm in names
        if nm.split("[")[0] == "tip_gain"
    }
    lower_ok = np.array([d.scale != "loglin" for d in defs])  # loglin: p >= lo needs u >= 0
    sub = cov[np.ix_(free, free)]
    length = result.rig.length

    def plant(z, j):
        """The scenario of draw z, or None where it is not physical: a friction level
        below 0, or a value the scenario schema refuses (e.g. a damping ratio > 1)."""
        if not np.all(lower_ok | (z >= 0.0)):
            return None
        p = {
            nm: float(d.to_phys(z[i])) * sign.get(nm, 1.0)
            for i, (nm, d) in enumerate(zip(names, defs, strict=True))
        }

        def first(m):
            return p.get(m, p.get(f"{m}[0]", 0.0))

        der = derived(
            {
                m: first(m)
                for m in ("hub_inertia", "link_frequency", "link_inertia")
                if m in p or f"{m}[0]" in p
            },
            length,
        )
        d, _ = scenario_from_fit(dataclasses.replace(result, params=p, derived=der))
        d["name"] = f"{d['name']}-draw-{j}"
        try:
            return scenario_from_dict(d, source=f"plant {j} drawn from the fit")
        except ScenarioError:
            return None

    draws, scen, tried = [], [], 0
    for _ in range(max_rounds):
        Z = np.tile(U, (n, 1))
        if free:
            Z[:, free] = rng.multivariate_normal(U[free], sub, size=n, method="eigh")
        for z in Z:
            tried += 1
            s = plant(z, len(scen))
            if s is not None:
                draws.append(z)
                scen.append(s)
                if len(scen) == n:
                    break
        if len(scen) == n:
            break
    if len(scen) < n:
        raise ValueError(
            f"only {len(scen)} of {tried} draws from the fit are physical "
            "(friction levels >= 0, values the scenario schema accepts): its "
            "uncertainty is too wide to sample; refit with more data or give "
            "the spreads with from_paths"
        )
    Z = np.asarray(draws)
    values = {
        nm: np.asarray(d.to_phys(Z[:, i])) * sign.get(nm, 1.0)
        for i, (nm, d) in enumerate(zip(names, defs, strict=True))
    }
    nominal = result.scenario()
    info = {
        "source": source,
        "n": n,
        "seed": seed,
        "drawn": tried,
        "rejected_fraction": 1.0 - n / tried if tried else 0.0,
        "held": [names[i] for i in held],
        "undetermined_threshold": undetermined,
    }
    return PlantBatch(nominal, scen, values, names, Z, U.copy(), std_u, seed, warnings, info)


# ----------------------------------------------------------------------------- from paths
def from_paths(
    scenario, spread: Mapping[str, tuple[float, float]], n: int = 200, *, seed: int = 0
) -> PlantBatch:
    """N plants from ``scenario`` with the parameters at ``spread`` (path → (mean, std) in
    SI) drawn independently, eq. (2) of the module doc."""
    from flexarm.specs.paths import scenario_with

    if n < 1:
        raise ValueError(f"n = {n}: the number of plants must be >= 1")
    names = list(spread)
    mean = np.empty(len(names))
    std = np.empty(len(names))
    for i, p in enumerate(names):
        try:
            m, s = (float(v) for v in spread[p])
        except (TypeError, ValueError):
            raise ValueError(
                f"spread[{p!r}] = {spread[p]!r}: give (mean, std) in SI, e.g. "
                "{'arm.friction.coulomb': (0.03, 0.005)}"
            ) from None
        if not (math.isfinite(m) and math.isfinite(s) and s >= 0):
            raise ValueError(
                f"spread[{p!r}] = ({m}, {s}): mean must be finite and std a finite number >= 0"
            )
        mean[i], std[i] = m, s
    # one standard normal per plant and parameter, row by row: plant j's draw does not
    # depend on how many plants are drawn
    E = np.random.default_rng(seed).standard_normal((n, len(names)))
    Z = np.empty((n, len(names)))
    for i in range(len(names)):
        m, s = mean[i], std[i]
        if m == 0.0:
            Z[:, i] = s * E[:, i]
        else:
            s2 = math.log1p((s / m) ** 2)
            Z[:, i] = math.copysign(1.0, m) * np.exp(
                math.log(abs(m)) - s2 / 2 + math.sqrt(s2) * E[:, i]
            )
    scen = [scenario_with(scenario, dict(zip(names, Z[j], strict=True))) for j in range(n)]
    nominal = scenario_with(scenario, dict(zip(names, mean, strict=True)))
    return PlantBatch(
        nominal,
        scen,
        {p: Z[:, i] for i, p in enumerate(names)},
        names,
        Z,
        mean,
        std,
        seed,
        [],
        {"source": "independent draws, eq. (2)", "n": n, "seed": seed},
    )
