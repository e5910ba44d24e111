"""A parametric bootstrap of any fit's uncertainty: :func:`bootstrap` → :class:`BootstrapSpread`.

    bootstrap(result, logs, n, *, seed=0, noise="residuals", executor=None, progress=None)

For each of ``n`` replicates k = 0 … n−1 (seed :func:`flexarm.sim.batch.chunk_seed`
``(seed, k)``):

1. each fitted log is predicted by the FITTED scenario (``result.scenario``; several
   sessions: each log by its session's, ``result.session_scenarios[s]``) on the log's own
   references, controller (or logged gain schedule), disturbances and length: the one
   prediction, :func:`~.predict.predict` (whole logs; the fit's windows are applied again
   by the refit);
2. noise for each measured channel the prediction simulates:
   ``noise="residuals"``: a Gaussian AR(1) series e_k = ρ e_{k−1} + σ √(1−ρ²) w_k
   (:func:`ar1_noise`) with the fit's residual std σ and lag-1 autocorrelation ρ of that
   log and channel (residual = logged − predicted over the fitted window; on a channel the
   scenario quantises, σ² less the rounding's q²/12); ``"declared"``: white Gaussian noise
   of the scenario's ``sensors.X.noise`` (SI); either rounded to the channel's quantisation
   step (``quantum``, or ``range / 2**bits``) where it declares one, as the sensor reads;
3. the replicate is the same :class:`flexarm.io.logs.Log` with those channels replaced
   (same time stamps, references, command, disturbances; same windows), and it is refitted
   by the one fit, :func:`flexarm.fit`, with the original free list and options
   (``predict=False``, no figures, no nested bootstrap), started from the fitted values
   (the fitted scenario with the free list given) or, for a preset whose engine starts
   from its own data sheet (the servo rig), as the original.

Where the noise goes: ``"declared"`` noise is fed through the closed loop (each replicate
is simulated again with it, :func:`_in_loop`: the controller reads the noisy measurement,
as in the scenario's own noisy simulation and on the rig), so the replicates carry the
loop's response to the sensor noise too (where the logged controller amplifies it into
the plant: issue #44's linear axis, the rotary unit's gauge). ``"residuals"`` noise is
added to the noise-free prediction: the residuals already hold the loop's response to
the rig's noise (their AR(1) correlation), which feeding them through the loop again
would count twice.

The spread (:class:`BootstrapSpread`): per parameter path the refitted values, their std
(ddof 1) and the correlation of the refits' log-values (signed parameters: the values),
the replicates that ran and those that failed (their error line), and the seconds.
Replicates run through the batch executor protocol (:func:`flexarm.sim.batch.map_chunks`:
in-process with ``executor=None``, on a Dask cluster through
:class:`flexarm.distributed.DaskExecutor`), one replicate a task.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from flexarm.identification.time_domain.options import BOOTSTRAP_NOISES, FitOptions
from flexarm.sim.batch import chunk_seed, map_chunks

__all__ = ["BootstrapSpread", "bootstrap", "ar1_noise", "residual_noise"]


@dataclass
class BootstrapSpread:
    """The refits of a parametric bootstrap (module docstring). ``values``: per parameter
    path, the refitted value of each replicate that ran (SI); ``std``: their standard
    deviation (ddof 1, SI; NaN with fewer than 2); ``correlation``: of the replicates'
    ln |value| (a parameter fitted in log space) in the order of ``free``; ``failed``: one
    line per replicate that raised; ``seconds``: wall time; ``noise``: the noise model and,
    for ``"residuals"``, its (σ, ρ) per log and channel."""

    free: list[str]
    values: dict[str, list[float]]
    std: dict[str, float]
    correlation: np.ndarray
    n: int
    n_ok: int
    failed: list[str]
    seconds: float
    seed: int
    noise: str
    noise_model: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The record the fit result keeps under ``stages["bootstrap"]``."""
        return {
            "n": self.n,
            "n_ok": self.n_ok,
            "n_failed": len(self.failed),
            "failed": list(self.failed),
            "seed": self.seed,
            "noise": self.noise,
            "noise_model": {
                k: {c: [float(s), float(r)] for c, (s, r) in v.items()}
                for k, v in self.noise_model.items()
            },
            "loop": (
                "declared noise fed through the loop (the controller reads it)"
                if self.noise == "declared"
                else "residual noise added to the simulated measurements (the residuals "
                "hold the loop's response to the noise already)"
            ),
            "std": dict(self.std),
            "values": {p: [float(x) for x in v] for p, v in self.values.items()},
            "correlation": np.round(np.asarray(self.correlation, float), 4).tolist(),
            "seconds": round(self.seconds, 2),
        }


# =============================================================================== noise
def ar1_noise(std: float, rho: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples of a stationary Gaussian AR(1) series with standard deviation ``std``
    (the channel's unit) and lag-1 autocorrelation ``rho`` (|rho| < 1; clipped to ±0.999):
    e_0 ~ N(0, σ²), e_k = ρ e_{k−1} + σ √(1 − ρ²) w_k, w_k ~ N(0, 1)."""
    rho = float(np.clip(rho if math.isfinite(rho) else 0.0, -0.999, 0.999))
    w = rng.standard_normal(int(n))
    if n == 0 or std == 0:
        return np.zeros(int(n))
    from scipy.signal import lfilter

    w[1:] *= math.sqrt(1.0 - rho * rho)
    return float(std) * np.asarray(lfilter([1.0], [1.0, -rho], w), float)


def residual_noise(measured: Any, simulated: Any) -> tuple[float, float]:
    """(σ, ρ) of the residual ``measured − simulated`` (non-finite samples dropped): its
    standard deviation about its mean and its lag-1 autocorrelation (0 for a constant)."""
    r = np.asarray(measured, float) - np.asarray(simulated, float)
    r = r[np.isfinite(r)]
    if r.size < 3:
        return 0.0, 0.0
    r = r - r.mean()
    s = float(r.std())
    den = float(r @ r)
    rho = float(r[1:] @ r[:-1]) / den if den > 0 else 0.0
    return s, rho


# =============================================================================== replicates
def _session_of(result, n_logs: int) -> list[int]:
    sess = (result.stages.get("sessions") or {}).get("of_log")
    return list(sess) if sess else [0] * n_logs


def _scenario_of(result, s: int):
    scs = list(getattr(result, "session_scenarios", None) or [])
    return scs[s] if s < len(scs) else result.scenario


def _predictions(result, logs: list, windows: list) -> list[tuple[dict, dict]]:
    """Per log: (the simulated channels of the whole log, the residuals' (σ, ρ) per
    channel over the fitted window), each log by its session's fitted scenario."""
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict

    sess = _session_of(result, len(logs))
    out = []
    for i, g in enumerate(logs):
        sc = _scenario_of(result, sess[i])
        whole = predict(sc, [g], PredictOptions(windows=[None]))
        tr = next(iter(whole.traces.values()))
        sim = {c: np.asarray(v, float) for c, v in tr["simulated"].items()}
        if windows[i] is not None:
            part = predict(sc, [g], PredictOptions(windows=[windows[i]]))
            tr = next(iter(part.traces.values()))
        stats = {c: residual_noise(tr["measured"][c], tr["simulated"][c]) for c in tr["simulated"]}
        out.append((sim, stats))
    return out


def _declared(scenario, channel: str) -> tuple[float, float | None]:
    """(noise std, quantisation step or None) the scenario declares for ``channel``
    (:func:`flexarm.sim.build.sensor_quanta`: ``quantum``, else ``range / 2**bits``), in the
    channel's SI unit."""
    from flexarm.sim.build import sensor_quanta

    sens = getattr(scenario, "sensors", None) or {}
    s = sens.get(channel)
    if s is None:
        return 0.0, None
    q = sensor_quanta({channel: s})[channel]
    return float(s.noise or 0.0), (q if q > 0 else None)


def replicate_logs(result, logs: list, sims: list, noise: str, seed: int) -> list:
    """The logs of one replicate: each log with its simulated channels plus fresh noise
    (module docstring), drawn from ``numpy.random.default_rng(seed)``: ``"residuals"``
    added to the noise-free prediction, ``"declared"`` fed through the loop."""
    rng = np.random.default_rng(int(seed))
    sess = _session_of(result, len(logs))
    out = []
    for i, (g, (sim, stats)) in enumerate(zip(logs, sims, strict=True)):
        sig = dict(g.signals)
        sc = _scenario_of(result, sess[i])
        if noise == "declared":
            out.append(replace(g, signals={**sig, **_in_loop(sc, g, sim, rng)}))
            continue
        for c, y in sim.items():
            if c not in sig or len(y) != len(sig[c]):
                continue
            s, q = _declared(sc, c)
            if noise == "residuals":
                # a quantised channel: its residual holds the rounding (q²/12), which the
                # re-quantisation below adds back; the noise before it is the rest
                s, rho = stats.get(c, (0.0, 0.0))
                s = math.sqrt(max(s * s - (q * q / 12.0 if q else 0.0), 0.0))
                v = y + ar1_noise(s, rho, len(y), rng)
            else:
                v = y + s * rng.standard_normal(len(y))
            sig[c] = np.round(v / q) * q if q else v
        out.append(replace(g, signals=sig))
    return out


def _in_loop(scenario, log, sim: dict, rng: np.random.Generator) -> dict:
    """The log's channels simulated by ``scenario`` with white noise of each sensor's
    declared std (``sensors.X.noise``, SI) added where the sensor reads, in the loop (the
    controller reads it; the sensor's A/D rounds it): the replicate's measured channels,
    as :func:`flexarm.sim.build.simulate` makes a noisy run."""
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict

    n = len(log.time)
    nz = {}
    for c in sim:  # the channels the noise-free prediction simulated, in its order
        s, _ = _declared(scenario, c)
        if s > 0:
            nz[c] = s * rng.standard_normal(n)
    pred = predict(scenario, [log], PredictOptions(windows=[None], noise=[nz]))
    tr = next(iter(pred.traces.values()))
    return {
        c: np.asarray(v, float)
        for c, v in tr["simulated"].items()
        if c in log.signals and len(v) == len(log.signals[c])
    }


def _refit(k: int, seed: int, *, refit, model, logs, sims, free, options, result, noise):
    """One replicate (a task of the executor): its logs, its refit; (k, values, error)."""
    try:
        reps = replicate_logs(result, logs, sims, noise, seed)
        res = refit(model, reps, free, options)
        return k, {p: float(v) for p, v in res.params.items()}, None
    except Exception as e:  # a failed replicate is counted and named, not fatal
        return k, None, f"replicate {k}: {type(e).__name__}: {e}"


def bootstrap(
    result,
    logs: Sequence[Any],
    n: int,
    *,
    seed: int = 0,
    noise: str = "residuals",
    executor: Any = None,
    progress: Callable[[str], None] | None = None,
    options: FitOptions | None = None,
    model: Any = None,
    refit: Callable[..., Any],
) -> BootstrapSpread:
    """Refit ``n`` replicates of ``logs`` simulated by ``result``'s fitted scenario with
    fresh noise (module docstring) and return their spread. ``options``: the original
    fit's :class:`~.options.FitOptions` (its windows are the fitted windows); ``model``:
    what each replicate refits, None: the fitted scenario with ``result.free`` given (started
    from the fitted values); a :class:`~.presets.Preset` refits with its own free list and
    starts (the servo rig). ``refit``: the one fit, ``refit(model, logs, free, options)``
    (:func:`flexarm.fit`; the front door passes itself, so that this module, which the
    front door calls, does not import it back). ``executor``: None (in-process) or a
    :class:`flexarm.sim.batch.BatchExecutor`; ``progress`` gets "bootstrap k of n"."""
    from flexarm.io.logformat import load_logs

    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise ValueError(f"bootstrap: n = {n!r}: give a whole number of replicates >= 2")
    if noise not in BOOTSTRAP_NOISES:
        raise ValueError(
            f"bootstrap: noise = {noise!r}: one of {', '.join(map(repr, BOOTSTRAP_NOISES))}"
        )
    if result.scenario is None:
        raise ValueError("bootstrap: this fit result has no fitted scenario (an interrupted fit)")
    t0 = time.perf_counter()
    opts = options if options is not None else FitOptions()
    logs = list(load_logs(list(logs)))
    wins = list(opts.windows) if opts.windows is not None else []
    wins += [None] * (len(logs) - len(wins))
    if progress is not None:
        progress(f"bootstrap: simulating the {len(logs)} fitted log(s) with the fitted scenario")
    sims = _predictions(result, logs, wins)
    refit_opts = dataclasses.replace(opts, predict=False, plots=None, bootstrap=None)
    from flexarm.identification.time_domain.presets import Preset

    free = None if isinstance(model, Preset) else list(result.free)
    target = model if model is not None else result.scenario
    shared = dict(
        refit=refit,
        model=target,
        logs=logs,
        sims=sims,
        free=free,
        options=refit_opts,
        result=result,
        noise=noise,
    )
    args = [(k, chunk_seed(seed, k)) for k in range(int(n))]
    done: list[tuple[int, dict | None, str | None]] = []
    if executor is None:  # in-process: one at a time, a progress line each
        for a in args:
            done.append(_refit(*a, **shared))
            if progress is not None:
                progress(f"bootstrap {a[0] + 1} of {n}")
    else:
        done = map_chunks(_refit, args, executor, shared=shared)
        if progress is not None:
            progress(f"bootstrap {n} of {n}")
    done.sort(key=lambda x: x[0])
    ok = [v for _, v, e in done if v is not None]
    failed = [e for _, v, e in done if e is not None]
    free_list = list(result.free)
    values = {p: [v[p] for v in ok if p in v] for p in free_list}
    std = {p: float(np.std(x, ddof=1)) if len(x) >= 2 else float("nan") for p, x in values.items()}
    corr = _correlation(values, free_list, len(ok))
    stats = {}
    from flexarm.io.logs import log_keys

    if noise == "residuals":
        stats = {k: dict(s) for k, (_, s) in zip(log_keys(logs), sims, strict=True)}
    return BootstrapSpread(
        free_list,
        values,
        std,
        corr,
        int(n),
        len(ok),
        failed,
        time.perf_counter() - t0,
        int(seed),
        noise,
        stats,
    )


def _correlation(values: dict[str, list[float]], free: list[str], m: int) -> np.ndarray:
    k = len(free)
    if m < 3 or any(len(values[p]) != m for p in free):
        return np.full((k, k), np.nan)
    cols = []
    for p in free:
        x = np.asarray(values[p], float)
        cols.append(np.log(np.abs(x)) if np.all(x > 0) or np.all(x < 0) else x)
    a = np.column_stack(cols)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.corrcoef(a, rowvar=False)
    return np.atleast_2d(c)
