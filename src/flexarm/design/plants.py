"""Plants drawn from a fit's parameter uncertainty, run as one ``vmap``-ed batch.

Two sources:

* :func:`from_fit`: any fit (:class:`flexarm.identification.time_domain.result.FitResult`,
  every preset), whose ``params``, ``std`` and ``correlation`` are keyed by scenario paths
  (``"arm.joints[0].friction.coulomb"``). The fit estimates each parameter in log space
  (p = p0·e^z) and reports its std σ_i (SI) and the correlation R of the z_i, so the
  covariance of ln p is Σ = D R D with D = diag(σ_i / |p̂_i|). A draw is

      z⁽ʲ⁾ ~ N(0, Σ),   p⁽ʲ⁾_i = p̂_i · e^{z⁽ʲ⁾_i}                                      (1)

  (a log-normal with median p̂: a physical magnitude keeps its sign and never crosses
  zero), set into the fitted scenario by :func:`~flexarm.specs.paths.scenario_with` (a
  tied path, the fit's ``ties``, moves by its free parameter's factor). A draw the scenario
  schema refuses (a damping ratio above 1) is drawn again (a truncated normal: the fraction
  rejected is in ``info``). A parameter whose std in ln p exceeds :data:`UNDETERMINED`, or is
  not finite (the fit could not determine it), is held at its fitted value (the marginal of
  the others keeps their covariance) and a warning says so.

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

#: std of ln p above which the data do not determine a parameter (module doc): its normal
#: would span e^±2 ≈ ×0.14 … ×7.4 within ±2σ
UNDETERMINED = 1.0


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
    the coordinates they were drawn in (:func:`from_fit`: ln |p| of ``names``;
    :func:`from_paths`: the SI values), ``center`` / ``scale`` their centre (ln |p̂|, or the
    mean) and std; ``seed``; ``warnings``; ``info`` (rejections, held parameters)."""

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
def _is_path(dump: dict, path: str) -> bool:
    from flexarm.specs.paths import get

    try:
        v = get(dump, path)
    except (KeyError, IndexError, TypeError, ValueError):
        return False
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def from_fit(
    result,
    n: int = 200,
    *,
    seed: int = 0,
    undetermined: float = UNDETERMINED,
    ties: Mapping[str, str] | None = None,
    max_rounds: int = 50,
) -> PlantBatch:
    """N plants drawn from a fit's uncertainty, eq. (1) of the module doc: ``result`` is any
    :class:`flexarm.identification.time_domain.result.FitResult` (or one read back with
    ``FitResult.from_dict(document, scenario)``) whose ``free`` / ``params`` / ``std`` /
    ``correlation`` are keyed by scenario paths, its ``scenario`` the fitted one.
    ``ties``: path → free path, a parameter that moves with a free one by the same factor
    (the fit's ``ties``; default ``result.stages["ties"]`` where the fit recorded them).

    A result whose parameters are not scenario paths (the rotary servo pipeline's names,
    ``hub_inertia``, ``coulomb[0]``) is drawn from its std mapped onto the fitted scenario's
    paths (:func:`flexarm.identification.time_domain.report.scenario_spread`),
    independently (:func:`from_paths`), and a warning says so."""
    if n < 1:
        raise ValueError(f"n = {n}: the number of plants must be >= 1")
    if callable(getattr(result, "result", None)) and hasattr(result, "space"):
        result = result.result()  # the servo pipeline's own result: its one FitResult
    scenario: Any = getattr(result, "scenario", None)
    if callable(scenario) and not hasattr(scenario, "model_dump"):
        scenario = scenario()  # the servo pipeline's own result builds it (deprecated)
    if scenario is None or not hasattr(scenario, "model_dump"):
        raise ValueError(
            "the fit result holds no fitted scenario: read a fit document back with "
            "FitResult.from_dict(document, load_scenario(SCENARIO_OUT)), the scenario its "
            "fit wrote (--scenario-out)"
        )
    dump = scenario.model_dump()
    names = list(getattr(result, "free", None) or result.params)
    if not all(_is_path(dump, p) for p in names):
        return _from_named_fit(result, scenario, n, seed)
    tie = dict(ties if ties is not None else (result.stages or {}).get("ties", {}) or {})
    for t, m in tie.items():
        if m not in names or not _is_path(dump, t):
            raise ValueError(
                f"ties[{t!r}] = {m!r}: a tie names a scenario path and the free path it "
                f"moves with; free: {', '.join(names)}"
            )
    k = len(names)
    p_hat = np.array([float(result.params[p]) for p in names])
    std = np.array([float(result.std.get(p, np.nan)) for p in names])
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.abs(std / p_hat)  # the std of ln p: the fit's log-space std
    R = np.asarray(result.correlation, float)
    warnings: list[str] = []
    if R.shape != (k, k):
        R = np.eye(k)
        warnings.append(
            "the fit result holds no correlation of its parameters: drawn independently "
            "(correlations ignored)"
        )
    held = [
        i
        for i in range(k)
        if p_hat[i] == 0.0 or not np.isfinite(s[i]) or s[i] > undetermined or s[i] == 0.0
    ]
    for i in held:
        if s[i] == 0.0:
            continue  # known exactly: nothing to say
        why = (
            f"std {std[i]:.3g}, {s[i]:.3g} in ln p, more than {undetermined}"
            if np.isfinite(s[i])
            else "the fit gives no finite std"
        )
        warnings.append(
            f"{names[i]} = {p_hat[i]:.4g} is not determined by the data ({why}): held at "
            "its fitted value in every plant"
        )
    free = [i for i in range(k) if i not in held]
    Rf = R[np.ix_(free, free)]
    if not np.all(np.isfinite(Rf)):
        raise ValueError(
            "the fit's correlation matrix is not finite between determined parameters: "
            "refit, or give the spreads with from_paths"
        )
    cov = Rf * np.outer(s[free], s[free])
    w, V = np.linalg.eigh((cov + cov.T) / 2)
    factor = V * np.sqrt(np.clip(w, 0.0, None))  # cov = factor factorᵀ (round-off clipped)
    t_hat = {t: float(_get(dump, t)) for t in tie}
    col = {p: i for i, p in enumerate(names)}

    def values_of(z):
        v = {p: float(p_hat[i] * math.exp(z[i])) for i, p in enumerate(names)}
        v.update({t: t_hat[t] * math.exp(z[col[m]]) for t, m in tie.items()})
        return v

    rng = np.random.default_rng(seed)
    draws, scen, tried = [], [], 0
    for _ in range(max_rounds):
        # one row of standard normals per plant: plant j's draw does not depend on n
        E = rng.standard_normal((n, len(free)))
        for e in E:
            z = np.zeros(k)
            z[free] = factor @ e
            tried += 1
            s_j = _plant(scenario, values_of(z), len(scen))
            if s_j is not None:
                draws.append(z)
                scen.append(s_j)
                if len(scen) == n:
                    break
        if len(scen) == n:
            break
    if len(scen) < n:
        raise ValueError(
            f"only {len(scen)} of {tried} draws from the fit are valid scenarios: its "
            "uncertainty is too wide to sample; refit with more data or give the spreads "
            "with from_paths"
        )
    Z = np.asarray(draws)
    vals = {p: p_hat[i] * np.exp(Z[:, i]) for i, p in enumerate(names)}
    vals.update({t: t_hat[t] * np.exp(Z[:, col[m]]) for t, m in tie.items()})
    info = {
        "source": "the fit's covariance of ln p over scenario paths, eq. (1)",
        "n": n,
        "seed": seed,
        "drawn": tried,
        "rejected_fraction": 1.0 - n / tried if tried else 0.0,
        "held": [names[i] for i in held],
        "ties": tie,
        "undetermined_threshold": undetermined,
    }
    with np.errstate(divide="ignore"):
        center = np.log(np.abs(p_hat))
    return PlantBatch(
        scenario,
        scen,
        vals,
        names,
        center + Z,
        center,
        np.where(np.isfinite(s), s, np.nan),
        seed,
        warnings,
        info,
    )


def _get(dump: dict, path: str):
    from flexarm.specs.paths import get

    return get(dump, path)


def _plant(scenario, values: dict[str, float], j: int):
    """The scenario with ``values``, or None where the schema refuses it (e.g. a damping
    ratio above 1)."""
    from flexarm.specs.paths import scenario_with
    from flexarm.specs.scenario import ScenarioError

    try:
        sc = scenario_with(scenario, values)
    except (ScenarioError, ValueError):
        return None
    return sc.model_copy(update={"name": f"{scenario.name}-draw-{j}"})


def _from_named_fit(result, scenario, n: int, seed: int) -> PlantBatch:
    """A fit whose parameters are not scenario paths (the rotary servo pipeline's): its std
    on the fitted scenario's paths (``report.scenario_spread``), drawn independently."""
    from flexarm.identification.time_domain.report import scenario_spread

    spread = scenario_spread(result.to_dict(), scenario)
    b = from_paths(scenario, spread, n, seed=seed)
    b.warnings.append(
        "the fit's parameters are not scenario paths (the servo rig's names): drawn "
        "independently from their std on the scenario's paths, without their correlations"
    )
    b.info["source"] = "the fit's std on scenario paths (scenario_spread), independent"
    return b


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
