"""``design --method tune``: a controller's gains optimised in simulation over a batch of
plants drawn from the fit's uncertainty (:mod:`flexarm.design.plants`).

Structure: the numeric fields of the scenario's ``[controller]`` named by path
(``"controller.k1"``, ``"controller.friction_compensation.level"``, any controller type's
fields); by default, for the rig's state feedback u = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ + c σ,
the gains K1..K4, the Coulomb compensation level c (V) of
:mod:`flexarm.control.friction_compensation` and its rest deadband (V: below it a resting
hub gets no push, which stops the compensation from hunting around the reference against
the delayed encoder); added when the controller has none, starting at the fitted Coulomb
torque over the drive's torque per volt, c = F_c / k_u, and one count's feedback K1 q.

Experiment (as :func:`flexarm.design.compare.compare`): the plants at rest, a reference step
Δ (default the scenario's step) at ``start``, ``duration`` s (2 s by default), through the
one sampled-data loop with friction, delays, quantisation and saturation; one
:func:`~flexarm.sim.sampled.simulate_batch` call per cost evaluation over the nominal plant
and the N drawn plants.

Cost. Per plant j (metrics of :func:`flexarm.design.compare.batch_metrics`, T_h the
duration after the step, band b·|Δ|):

    c_j = t_s,j / T_h                           tip settling to ±b|Δ| of its final value
        + w_os · OS_j / 100                      tip overshoot (% of the step)
        + w_ss · max(0, e_j − e_max)             hub steady-state error (counts) beyond e_max
        + w_u · t_lim,j / T_h                    time at the voltage limit
        + w_osc · rms_j / (b|Δ| L)               residual tip oscillation (tail rms of d)
        + w_ch · ch_j / 0.1 V                    command chatter (rms change per sample)

with a plant that does not settle within the run charged t_s = T_h (1 + ε_j / (b|Δ|)),
ε_j the largest |θ_t − θ̄_t| over the last quarter (so the optimiser still sees which way
is better), and a diverged plant c_j = 1000. The design cost is the ``quantile`` (0.9 by
default; 1.0 the worst case) of c over the nominal and the drawn plants: the design must
be good on the batch, not on the nominal plant only.

Optimiser: SciPy's Nelder–Mead, in coordinates scaled by each gain's start value
(x_i = (p_i − p0_i)/s_i, s_i = |p0_i|, or 1 where p0_i = 0), initial simplex
±``simplex_step`` (30 %), bounds clipped (a tuned value at a bound is warned: widen it
with ``bounds=``); the budget ``maxfev`` is shared by the first search and ``restarts``
fresh simplices about the best point so far (a simplex that collapsed onto a ridge of the
discontinuous cost starts over). Why: the cost is piecewise constant and discontinuous in the gains
(encoder counts, stick-slip stops, the last sample outside a band), so gradient methods
and finite differences fail; with five or so parameters Nelder–Mead needs one or two batch
evaluations per iteration where differential evolution or CMA-ES would need a population
(15·n evaluations per generation) of 200-plant batches; it is deterministic for a given
start, and the batch's seed fixes the plants, so a run is reproducible.
"""

from __future__ import annotations

import copy
import time as _time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from flexarm.design.compare import (
    batch_metrics,
    build_controller,
    encoder_count,
    experiment,
    units_of,
)
from flexarm.design.plants import PlantBatch, chunk_plants, nominal_batch
from flexarm.design.result import Design
from flexarm.specs import paths as scenario_paths

if TYPE_CHECKING:
    from flexarm.sim.batch import BatchExecutor, ChunkOptions

__all__ = ["design_tune", "TuneCost", "ChunkedTuneCost", "DEFAULT_WEIGHTS"]

DEFAULT_WEIGHTS = {
    "overshoot": 1.0,
    "hub_error": 0.5,
    "at_limit": 1.0,
    "oscillation": 0.5,
    "chatter": 0.3,
}
#: the command chatter's scale in the cost (V per sample, rms)
CHATTER_SCALE = 0.1
DIVERGED_COST = 1000.0


def _get(d: dict, path: str):
    return scenario_paths.get(d, path, "tuned parameter")


def _set(d: dict, path: str, v: float) -> None:
    scenario_paths.set(d, path, float(v), "tuned parameter")


def _default_params(ctrl: dict) -> list[str]:
    if ctrl.get("type") == "state_feedback":
        names = ["k1", "k2", "k3", "k4"]
    else:
        names = [
            k
            for k, v in ctrl.items()
            if isinstance(v, (int, float))
            and not isinstance(v, bool)
            and k not in ("rate_time_constant", "dt")
        ]
    return [f"controller.{k}" for k in names] + [
        "controller.friction_compensation.level",
        "controller.friction_compensation.rest_deadband",
    ]


class TuneCost:
    """The cost of the module doc as a function of the tuned parameters (SI values in the
    order of ``paths``); ``evaluate(P)`` returns (cost, per-plant costs, metrics)."""

    def __init__(
        self,
        scenario,
        plants: PlantBatch,
        paths: Sequence[str],
        *,
        step: float | None,
        start: float,
        duration: float,
        band: float,
        quantile: float,
        weights: Mapping[str, float],
        hub_error_max: float,
        count: float | None,
        seed: int,
    ):
        from flexarm.specs.scenario import scenario_from_dict

        self.paths = list(paths)
        self.q = encoder_count(plants.nominal, count)
        exp = experiment(
            plants.nominal,
            step=step,
            start=start,
            duration=duration,
            quantum=None if count is None else self.q,
        )
        pb = plants.with_overrides(exp)
        self.base = pb.loop()
        self.scn = pb.nominal
        self.template = scenario.model_dump(mode="json", exclude_none=True)
        self._validate = lambda d: scenario_from_dict(d, source="tuned controller")
        self.limit = float(np.ravel(np.asarray(self.base.loop.actuator.limit))[0])
        self.length = float(self.scn.arm.beam.length)
        self.delta = float(self.scn.reference.amplitude)
        self.horizon = duration - start
        self.band, self.quantile, self.seed = band, quantile, seed
        self.w = {**DEFAULT_WEIGHTS, **(weights or {})}
        self.hub_error_max = hub_error_max
        self.names = self.base.prepared.loop.plant.signal_names
        self.nfev = 0
        self.seconds = 0.0

    def scenario(self, p: Sequence[float] | np.ndarray):
        """The rig scenario with the parameters at ``p`` (validated)."""
        d = copy.deepcopy(self.template)
        for path, v in zip(self.paths, p, strict=False):
            _set(d, path, v)
        return self._validate(d)

    def evaluate(self, p: Sequence[float] | np.ndarray) -> tuple[float, np.ndarray, dict]:
        t0 = _time.perf_counter()
        spec = self.scenario(p).controller
        bl = self.base.with_controller(build_controller(self.base, spec, self.scn))
        out = bl.run(seed=self.seed)
        m = batch_metrics(
            out,
            self.names,
            bl.time,
            bl.references["reference"],
            count=self.q,
            limit=self.limit,
            length=self.length,
            band=self.band,
        )
        c = self.plant_costs(out, m, bl.time)
        self.nfev += 1
        self.seconds += _time.perf_counter() - t0
        return float(np.quantile(c, self.quantile)), c, m

    def plant_costs(self, out: dict, m: dict, t: np.ndarray) -> np.ndarray:
        w, T, tol = self.w, self.horizon, self.band * abs(self.delta)
        tip = out["signals"][..., self.names.index("tip_angle")]
        n = tip.shape[1]
        last, k_tail = max(1, n // 20), n - max(1, n // 4)
        with np.errstate(invalid="ignore", over="ignore"):
            fin = np.mean(tip[:, -last:], axis=1)
            eps = np.max(np.abs(tip[:, k_tail:] - fin[:, None]), axis=1)
            ts = np.where(
                np.isfinite(m["tip_settling_s"]), m["tip_settling_s"], T * (1 + eps / tol)
            )
            c = (
                ts / T
                + w["overshoot"] * m["tip_overshoot_pct"] / 100
                + w["hub_error"] * np.maximum(0.0, m["hub_error_counts"] - self.hub_error_max)
                + w["at_limit"] * m["time_at_limit_s"] / T
                + w["oscillation"] * 1e-3 * m["tip_oscillation_mm"] / (tol * self.length)
                + w["chatter"] * m["command_chatter_V"] / CHATTER_SCALE
            )
        return np.where(np.isfinite(c), c, DIVERGED_COST)


def _linear_part(spec, dt: float):
    """u = K1 r − (K1 + K3/T) θ + (K3/T) θ_{k−1} − (K2 + K4/T) d + (K4/T) d_{k−1} (backward
    rates) as a python-control discrete StateSpace on inputs (r, θ, d), states (θ_{k−1},
    d_{k−1}); None for other laws."""
    if getattr(spec, "type", None) != "state_feedback" or spec.rate != "backward":
        return None
    import control

    k1, k2, k3, k4 = spec.k1, spec.k2, spec.k3, spec.k4
    return control.ss(
        np.zeros((2, 2)),
        [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [[k3 / dt, k4 / dt]],
        [[k1, -(k1 + k3 / dt), -(k2 + k4 / dt)]],
        dt,
        inputs=["reference", "motor_angle", "tip_deflection"],
        outputs=["u"],
        states=["motor_angle_prev", "tip_deflection_prev"],
        name="tune",
    )


def design_tune(
    scenario,
    plants: PlantBatch,
    *,
    params: Sequence[str] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    step: float | None = None,
    start: float = 0.1,
    duration: float = 2.0,
    band: float = 0.02,
    quantile: float = 0.9,
    weights: Mapping[str, float] | None = None,
    hub_error_max: float = 1.0,
    maxfev: int = 150,
    simplex_step: float = 0.3,
    restarts: int = 1,
    count: float | None = None,
    seed: int = 0,
    callback: Callable[[dict], Any] | None = None,
    client: BatchExecutor | None = None,
    chunks: ChunkOptions | None = None,
) -> Design:
    """Tune ``params`` (paths into ``scenario``, default K1..K4 and the friction
    compensation level) over ``plants`` (module doc); ``bounds``: path → (lo, hi) SI
    (default p0 ± 4|p0|, K1 in [p0/5, 5 p0], levels in [0, 5 c0]); ``callback`` receives
    {"nfev", "cost", "best", "params"} after every evaluation (progress). Returns a
    :class:`~flexarm.design.result.Design` whose scenario is ``scenario`` with the tuned
    ``[controller]``. With ``client``, a :class:`flexarm.sim.batch.BatchExecutor` (e.g.
    :class:`flexarm.distributed.DaskExecutor`; or ``chunks``, a
    :class:`flexarm.sim.batch.ChunkOptions`, in-process) each evaluation runs the plants in
    chunks, one task each (:class:`ChunkedTuneCost`)."""
    from scipy.optimize import minimize

    from flexarm.models.single_link import SingleLinkModel
    from flexarm.specs.scenario import scenario_from_dict

    if scenario.controller is None:
        raise ValueError(
            f"scenario {scenario.name!r}: no [controller] to tune; give the "
            "rig's controller (its structure and starting gains)"
        )
    if not 0.0 < quantile <= 1.0:
        raise ValueError(f"quantile = {quantile}: give a number in (0, 1] (1 = worst case)")
    d = scenario.model_dump(mode="json", exclude_none=True)
    ctrl = d["controller"]
    warn: list[str] = []
    if params is None:
        params = _default_params(ctrl)
    params = list(params)
    if (
        any(p.startswith("controller.friction_compensation") for p in params)
        and "friction_compensation" not in ctrl
    ):
        model = SingleLinkModel.from_spec(plants.nominal.arm)
        fr = plants.nominal.arm.friction
        c0 = float(getattr(fr, "coulomb", 0.0) or 0.0) / float(model.drive.k_u)
        k1 = abs(float(ctrl.get("k1", ctrl.get("kp", 0.0)) or 0.0))
        q = encoder_count(plants.nominal, count)
        ctrl["friction_compensation"] = {"level": c0, "rest_deadband": k1 * q}
        u = units_of(plants.nominal)["command"]
        force = "force" if getattr(plants.nominal, "prismatic", False) else "torque"
        warn.append(
            f"friction compensation added: level starts at the fitted Coulomb "
            f"{force} / k_u = {c0:.4g} {u}, rest deadband at one encoder count's "
            f"feedback K1 q = {k1 * q:.4g} {u}"
        )
    scenario = scenario_from_dict(d, source=f"scenario {scenario.name!r} to tune")
    d = scenario.model_dump(mode="json", exclude_none=True)
    p0 = np.array([float(_get(d, p)) for p in params])
    scale = np.where(p0 != 0, np.abs(p0), 1.0)
    lo, hi = p0 - 4 * scale, p0 + 4 * scale
    for i, p in enumerate(params):
        if p.endswith(".level") or p.endswith("deadband"):
            lo[i], hi[i] = 0.0, 5 * max(p0[i], 1e-3)
        elif p.endswith(".k1") or p.endswith(".kp"):
            lo[i], hi[i] = p0[i] / 5, 5 * p0[i]
            lo[i], hi[i] = min(lo[i], hi[i]), max(lo[i], hi[i])
    for p, (a, b) in (bounds or {}).items():
        if p not in params:
            raise ValueError(f"bounds[{p!r}]: not a tuned parameter; tuned: {', '.join(params)}")
        if not a < b:
            raise ValueError(f"bounds[{p!r}] = ({a}, {b}): lo must be below hi")
        i = params.index(p)
        lo[i], hi[i] = a, b
    if len(plants) == 0:
        warn.append("no drawn plants: tuned on the nominal plant only")
    cost_kw: dict[str, Any] = dict(
        step=step,
        start=start,
        duration=duration,
        band=band,
        quantile=quantile,
        weights=weights or {},
        hub_error_max=hub_error_max,
        count=count,
        seed=seed,
    )
    if client is not None or chunks is not None:  # in chunks, on the executor given
        cost = ChunkedTuneCost(scenario, plants, params, client=client, options=chunks, **cost_kw)
    else:
        cost = TuneCost(scenario, plants, params, **cost_kw)
    hist: list[float] = []
    best = {"cost": np.inf, "x": None}
    t0 = _time.perf_counter()

    def f(x):
        p = np.clip(p0 + scale * x, lo, hi)
        try:
            J = cost.evaluate(p)[0]
        except ValueError:  # a controller spec the schema refuses (e.g. a negative level)
            J = DIVERGED_COST
        hist.append(J)
        if J < best["cost"]:
            best.update(cost=J, x=np.array(x))
        if callback is not None:
            callback(
                {
                    "nfev": len(hist),
                    "cost": J,
                    "best": best["cost"],
                    "params": dict(zip(params, map(float, p), strict=True)),
                }
            )
        return J

    J0 = f(np.zeros(len(params)))
    xb = ((lo - p0) / scale, (hi - p0) / scale)
    messages = []
    x_start = np.zeros(len(params))
    for r in range(restarts + 1):  # each restart: a fresh simplex about the best point
        left = maxfev - len(hist)
        if left <= len(params) + 1:
            break
        simplex = np.vstack([x_start, x_start + simplex_step * np.eye(len(params))])
        simplex = np.clip(simplex, xb[0], xb[1])
        res = minimize(
            f,
            x_start,
            method="Nelder-Mead",
            bounds=list(zip(xb[0], xb[1], strict=True)),
            options={
                "maxfev": left
                if r == restarts
                else max(left // (restarts + 1 - r), len(params) + 2),
                "initial_simplex": simplex,
                "xatol": 1e-3,
                "fatol": 1e-4,
            },
        )
        messages.append(str(res.message))
        x_start = best["x"] if best["x"] is not None else res.x
    xbest = best["x"] if best["x"] is not None else np.zeros(len(params))
    pbest = np.clip(p0 + scale * xbest, lo, hi)
    tuned = cost.scenario(pbest)
    Jb, cj, m = cost.evaluate(pbest)
    seconds = _time.perf_counter() - t0
    stable = np.asarray(m["stable"], bool)
    if not stable.all():
        warn.append(
            f"{int((~stable).sum())} of {stable.size} plants (nominal included) do "
            "not settle within the tuning run with the tuned gains"
        )
    for p, v, a, b in zip(params, pbest, lo, hi, strict=True):
        if np.isclose(v, a, rtol=1e-9, atol=1e-12) or np.isclose(v, b, rtol=1e-9, atol=1e-12):
            warn.append(
                f"{p} = {v:.4g} lies at a bound of [{a:.4g}, {b:.4g}]; widen it with "
                f"bounds={{'{p}': (lo, hi)}}"
            )
    if Jb >= J0:
        warn.append("tuning did not lower the cost: the starting gains are returned")
        tuned, pbest, Jb = cost.scenario(p0), p0, J0
    info = {
        "optimiser": "scipy.optimize.minimize(method='Nelder-Mead'), scaled coordinates "
        "(x = (p - p0)/|p0|), bounds clipped",
        "parameters": {
            p: {"start": float(a), "tuned": float(b), "bounds": [float(low), float(high)]}
            for p, a, b, low, high in zip(params, p0, pbest, lo, hi, strict=True)
        },
        "cost": {
            "start": float(J0),
            "tuned": float(Jb),
            "quantile": quantile,
            "weights": cost.w,
            "hub_error_max_counts": hub_error_max,
            "band_fraction": band,
            "definition": "see flexarm.design.tune",
        },
        "experiment": {
            "step_rad": cost.delta,
            "start_s": start,
            "duration_s": duration,
            "count_rad": cost.q,
        },
        "plants": {**plants.info, "batch_size": cost.base.size},
        "evaluations": len(hist),
        "seconds": seconds,
        "seconds_per_evaluation": cost.seconds / max(cost.nfev, 1),
        "history": [float(h) for h in hist],
        "restarts": restarts,
        "message": messages,
    }
    assert tuned.sampling is not None  # the rig scenario is a sampled-data one
    return Design(
        "tune",
        tuned,
        _linear_part(tuned.controller, float(tuned.sampling.period)),
        info,
        warn + list(plants.warnings),
    )


# ------------------------------------------------------------------ in chunks, on an executor
#: a worker's prepared chunk costs, by (cost token, chunk), kept between evaluations
_WORKER_COSTS: dict = {}


def _tune_chunk(token, plants, j, a, b, p, *, scenario, paths, kwargs):
    """Chunk j's per-plant costs at parameters p; the chunk's prepared plants are kept in
    the worker between evaluations (keyed by ``token`` and j)."""
    key = (token, j)
    cost = _WORKER_COSTS.get(key)
    if cost is None:
        cost = TuneCost(scenario, chunk_plants(plants, j, a, b), paths, **kwargs)
        _WORKER_COSTS.clear() if len(_WORKER_COSTS) > 64 else None
        _WORKER_COSTS[key] = cost
    _, c, m = cost.evaluate(p)
    return c, {k: np.asarray(v) for k, v in m.items()}


class ChunkedTuneCost:
    """:class:`TuneCost` with the plants in chunks on ``client``, a
    :class:`~flexarm.sim.batch.BatchExecutor` (None: in-process): each evaluation is one
    task per chunk (its plants prepared once per worker and kept), and the per-plant costs
    come back; the design cost is their ``quantile`` over the nominal plant and all drawn
    plants, as with one batch."""

    # copied from the nominal TuneCost in __init__
    q: Any
    scn: Any
    limit: Any
    length: Any
    delta: Any
    horizon: Any
    w: Any
    names: Any

    def __init__(
        self,
        scenario,
        plants,
        paths: Sequence[str],
        *,
        client: BatchExecutor | None = None,
        options: ChunkOptions | None = None,
        **kwargs,
    ):
        import dataclasses

        from flexarm.sim.batch import ChunkOptions, as_executor, chunk_bounds

        self.o = options or ChunkOptions()
        self.client = as_executor(client)
        self.nominal = TuneCost(scenario, nominal_batch(plants), paths, **kwargs)
        self.plants = plants
        self.bounds = chunk_bounds(len(plants), self.o.chunk) or [(0, 0)]
        self.token = f"{id(self)}-{_time.time_ns()}"
        self.scenario_ = scenario
        self.paths = list(paths)
        self.kwargs = kwargs
        self.quantile = kwargs["quantile"]
        for k in ("q", "scn", "limit", "length", "delta", "horizon", "w", "names"):
            setattr(self, k, getattr(self.nominal, k))
        self.size = len(plants) + 1
        self.nfev, self.seconds = 0, 0.0
        self._base = dataclasses.make_dataclass("B", [("size", int)])(self.size)

    @property
    def base(self):  # the batch size, as TuneCost.base.size reports it
        return self._base

    def scenario(self, p):
        return self.nominal.scenario(p)

    def evaluate(self, p) -> tuple[float, np.ndarray, dict]:
        from flexarm.sim.batch import map_chunks

        t0 = _time.perf_counter()
        self.scenario(p)  # a spec the schema refuses raises here, on the client
        src = self.plants if len(self.plants) else nominal_batch(self.plants)
        parts = map_chunks(
            _tune_chunk,
            [
                (self.token, src, j, a, b, np.asarray(p, float))
                for j, (a, b) in enumerate(self.bounds)
            ],
            self.client,
            retries=self.o.retries,
            workers=self.o.workers,
            shared=dict(scenario=self.scenario_, paths=self.paths, kwargs=self.kwargs),
        )
        c = np.concatenate([parts[0][0]] + [q[0][1:] for q in parts[1:]])
        m = {
            k: np.concatenate([parts[0][1][k]] + [q[1][k][1:] for q in parts[1:]])
            for k in parts[0][1]
        }
        self.nfev += 1
        self.seconds += _time.perf_counter() - t0
        return float(np.quantile(c, self.quantile)), c, m
