"""Continuous-time closed loops of a multi-link arm, ẋ = f(x, sat(law(params, x, t))): thin
front-ends of the one sampled-data loop (:mod:`flexarm.sim.sampled`).

The law is evaluated at every integration stage (no sampling, no hold): the setting of De
Luca & Siciliano's regulation results (DLS eqs. (8), (30); the laws live in
:mod:`flexarm.control.regulation`). Both functions build a
:class:`~flexarm.sim.sampled.SampledLoop` whose controller is the law
(:class:`~flexarm.control.continuous_law.ContinuousLaw`, alone: no sampled part), with no
sensors, the plant's torque limits as the actuator's saturation, one sample per output
period ``dt`` and ``dt / step`` RK4 substeps per sample, and run it.

* :func:`simulate_continuous`: one rollout, fixed-step RK4 (default step 0.1 ms) or the
  loop's adaptive ``tsit5`` (diffrax Tsit5 with PID step-size control within each output
  period); outputs every ``dt``. Raises :class:`~flexarm.errors.SimulationDiverged` naming
  the first time and state variable that is non-finite or beyond ``bound``.
* :func:`simulate_continuous_batch`: N rollouts of one law with batched parameters (gain
  sweeps), the loop with the state carried batch-last in chunks
  (:func:`flexarm.sim.sampled.simulate_law_batch`); diverged rollouts are flagged, not raised.

Both return the one result type, :class:`flexarm.sim.result.SimulationResult` (a
python-control :class:`control.TimeResponseData`: ``.time``, ``.states`` (n_x, [N,] T),
``.inputs`` (n_links, [N,] T)), with time-major named accessors ``res.theta`` ([N,] T, n_links)
rad, ``res.delta`` ([N,] T, n_δ) m, ``res.torque`` ([N,] T, n_links) N·m, ``res["theta_1"]``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import jax.numpy as jnp
import numpy as np

from flexarm.control.continuous_law import ContinuousLaw
from flexarm.errors import SimulationDiverged
from flexarm.models.multilink import MultiLinkModel
from flexarm.sim import sampled
from flexarm.sim.result import SimulationResult


def law_loop(
    model: MultiLinkModel,
    law: Callable,
    params,
    dt: float,
    substeps: int,
    *,
    solver: str = "rk4",
    tolerances: tuple[float, float] = (1e-8, 1e-10),
) -> sampled.SampledLoop:
    """The sampled-data loop that runs ``law(params, x, t)`` continuously on the arm's plant:
    no sensors, saturation at the plant's torque limits, sample period ``dt`` (s) with
    ``substeps`` integration steps each."""
    plant = model.plant
    limit = jnp.asarray(plant.command_limit, float)
    return sampled.SampledLoop(
        plant,
        ContinuousLaw(law, params, jnp.asarray(float(dt)), plant.n_inputs),
        sampled.Sensors.make(plant, {}),
        sampled.Actuator(limit, jnp.zeros_like(limit)),
        jnp.asarray(float(dt)),
        int(substeps),
        0,
        solver,
        cast("tuple[float, float]", tuple(tolerances)),
    )  # (rtol, atol)


def _result(loop, ts, xs, sig, us, title: str, diverged=None) -> SimulationResult:
    plant = loop.plant
    return SimulationResult(
        ts,
        {n: sig[..., i] for i, n in enumerate(plant.signal_names)},
        {},
        {"reference": np.zeros_like(ts)},
        us,
        plant.input_names,
        xs,
        plant.state_names,
        title=title,
        meta={"output_period_s": float(ts[1] - ts[0]) if len(ts) > 1 else 0.0},
        diverged=diverged,
    )


def _times(t_final: float, dt: float) -> int:
    if not (t_final > 0 and dt > 0):
        raise ValueError(f"t_final and dt must be > 0; got {t_final}, {dt}")
    n_out = int(round(t_final / dt))
    if n_out < 1:
        raise ValueError(f"dt = {dt} s is longer than t_final = {t_final} s")
    return n_out


def _bad(xs: np.ndarray, bound: float) -> np.ndarray:
    return ~np.isfinite(xs) | (np.abs(np.nan_to_num(xs, nan=np.inf)) > bound)


def simulate_continuous(
    model: MultiLinkModel,
    law: Callable,
    x0,
    t_final: float,
    dt: float = 1e-3,
    *,
    params=None,
    method: str = "rk4",
    step: float = 1e-4,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    bound: float = 1e4,
) -> SimulationResult:
    """Continuous-time closed loop ẋ = f(x, sat(law(params, x, t))) from x0 over [0, t_final].

    Outputs every ``dt`` (s), n = round(t_final/dt) + 1 of them. ``method``: ``rk4`` (fixed
    step ``step``, default 0.1 ms; dt is rounded to a whole number of steps) or ``tsit5``
    (adaptive within each output period, ``rtol``/``atol``, first step ``min(dt, step)``).
    Raises :class:`SimulationDiverged` naming the first time and state variable that is
    non-finite or larger than ``bound`` in absolute value (SI units); an adaptive run whose
    solver gave up reads as non-finite from then on."""
    plant = model.plant
    x0 = np.asarray(x0, float)
    if x0.size != 2 * model.n_q:
        raise ValueError(
            f"x0 has {x0.size} values; this arm's state has {2 * model.n_q}: "
            f"{', '.join(plant.state_names)} (model.state(theta=...) builds one)"
        )
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 holds NaN or infinite values: {x0.ravel().tolist()}")
    n_out = _times(t_final, dt)
    if method == "rk4":
        n_sub = max(1, int(round(dt / step)))
    elif method == "tsit5":
        n_sub = max(1, int(round(dt / min(dt, step))))
    else:
        raise ValueError(f"method must be 'rk4' or 'tsit5'; got {method!r}")
    loop = law_loop(model, law, params, dt, n_sub, solver=method, tolerances=(rtol, atol))
    xs, sig, us = run_law(loop, x0.reshape(-1), n_out + 1)
    ts = np.arange(n_out + 1) * float(dt)
    bad = _bad(xs, bound)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        j = int(np.argmax(bad[k]))
        raise SimulationDiverged(
            f"closed loop diverged at t = {ts[k]:.6g} s: {plant.state_names[j]} = {xs[k, j]:.4g} "
            f"(bound ±{bound:g}); reduce the gains or the step ({method}, step "
            f"{step if method == 'rk4' else 'adaptive'}), or use an interpolating trajectory"
            + (
                "; the adaptive solver's step size may have collapsed (the closed loop is stiff "
                "or diverging)"
                if method == "tsit5"
                else ""
            )
        )
    return _result(loop, ts, xs, sig, us, "flexarm continuous closed loop")


def run_law(loop: sampled.SampledLoop, x0: np.ndarray, n_samples: int):
    """States (n, n_x), signals (n, p) and applied commands (n, m) at the samples of a law
    loop: the loop's
    compiled run (:func:`flexarm.sim.sampled._run_all`) without its signal bound check
    (the front-ends check the states against their own ``bound``)."""
    refs = sampled._prepare_refs({}, n_samples)
    xs, sig, _, us, _ = sampled._run_all(loop, x0, refs, np.asarray(0, dtype=np.int64))
    return np.asarray(xs), np.asarray(sig), np.asarray(us)


def simulate_continuous_batch(
    model: MultiLinkModel,
    law: Callable,
    x0,
    t_final: float,
    dt: float = 1e-3,
    *,
    params,
    axes,
    step: float = 1e-4,
    chunk: int = 128,
    bound: float = 1e4,
) -> SimulationResult:
    """N closed loops ẋ = f(x, sat(law(params_i, x, t))) at once, fixed-step RK4 (``step``,
    default 0.1 ms), outputs every ``dt``: what :func:`simulate_continuous` does for one.

    ``params``/``axes``: a parameter pytree and its vmap-style batch axes (0 on the leaves
    that hold the batch along their first axis, None on shared ones), e.g. from
    :func:`flexarm.control.regulation.regulation_params_batch`. ``x0``: (n_x,) shared, or
    (N, n_x) one per rollout. The
    batch runs in the one loop with the state carried batch-last, in chunks of ``chunk``
    rollouts (:func:`flexarm.sim.sampled.simulate_law_batch`). Gains are traced: any sweep of the
    same size compiles once.
    Returns one :class:`SimulationResult` holding the N rollouts as python-control traces;
    a run that diverges is flagged in ``diverged`` rather than raised."""
    plant = model.plant
    nx = 2 * model.n_q
    n_out = _times(t_final, dt)
    n_sub = max(1, int(round(dt / step)))
    x0 = np.asarray(x0, float)
    if x0.shape[-1:] != (nx,) or x0.ndim > 2 or not np.all(np.isfinite(x0)):
        raise ValueError(
            f"x0 must be ({nx},) or (N, {nx}) finite values "
            f"({', '.join(plant.state_names)}); got shape {x0.shape}"
        )
    loop = law_loop(model, law, params, dt, n_sub)
    xs, sig, us = sampled.simulate_law_batch(loop, x0, n_out + 1, axes, chunk=chunk)
    ts = np.arange(n_out + 1) * float(dt)
    return _result(
        loop,
        ts,
        xs,
        sig,
        us,
        "flexarm continuous closed loops",
        diverged=_bad(xs, bound).any(axis=(1, 2)),
    )
