"""Continuous-time closed loops of a multi-link arm: ẋ = f(x, sat(law(params, x, t))).

The law is evaluated at every integration stage (no sampling, no hold): the setting of De
Luca & Siciliano's regulation results (DLS eqs. (8), (30); the laws live in
:mod:`flexarm.control.regulation`). For sampled-data loops with sensors, converters and
delays see :mod:`flexarm.sim.sampled`.

* :func:`simulate_continuous`: one rollout, fixed-step RK4 (:func:`flexarm.sim.integrate.rk4_path`,
  default step 0.1 ms) or diffrax Tsit5 with a PID step-size controller; outputs every ``dt``.
  Raises :class:`~flexarm.errors.SimulationDiverged` naming the first time and state variable
  that is non-finite or beyond ``bound``.
* :func:`simulate_continuous_batch`: N rollouts of one law with batched parameters (gain
  sweeps), vectorised in chunks; diverged rollouts are flagged, not raised.

Results are python-control :class:`control.TimeResponseData` objects (``.time``,
``.states`` (n_x, T), ``.inputs`` (n_u, T), ``.outputs`` = q = (θ, δ), ``.plot()``), with
time-major named accessors: ``run.theta`` (T, n_links) rad, ``run.delta`` (T, n_δ) m,
``run.torque`` (T, n_links) N·m, ``run["theta_1"]``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import control
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.errors import SimulationDiverged
from flexarm.io.logs import write_log
from flexarm.models.multilink import MultiLinkModel
from flexarm.sim.integrate import rk4_path


class _ArmResponse(control.TimeResponseData):
    """What one rollout and a batch share: python-control's arrays with the variable first
    (``states`` (n_x, [N,] T): rad, m, rad/s, m/s; ``inputs`` (n_links, [N,] T): applied
    joint torques, N·m; ``outputs`` q = (θ, δ)) and views with the variable last."""

    def __init__(self, time, x, u, state_names, n_links: int, title: str):
        self.n_links = int(n_links)
        self.state_names = tuple(state_names)
        nq = x.shape[0] // 2
        super().__init__(np.asarray(time), x[:nq], states=x, inputs=u,
                         output_labels=list(state_names[:nq]), state_labels=list(state_names),
                         input_labels=[f"torque_{k + 1}" for k in range(self.n_links)],
                         title=title, issiso=False)

    @property
    def state_array(self) -> np.ndarray:
        """The states with the variable last: ([N,] T, n_x)."""
        return np.moveaxis(self.states, 0, -1)

    @property
    def torque(self) -> np.ndarray:
        """Applied joint torques (after saturation), ([N,] T, n_links), N·m."""
        return np.moveaxis(self.inputs, 0, -1)

    @property
    def theta(self) -> np.ndarray:
        """Joint angles, ([N,] T, n_links), rad."""
        return self.state_array[..., :self.n_links]

    @property
    def delta(self) -> np.ndarray:
        """Modal deflections, ([N,] T, n_δ), m."""
        nq = self.states.shape[0] // 2
        return self.state_array[..., self.n_links:nq]


class ContinuousRun(_ArmResponse):
    """One closed-loop rollout (see :class:`_ArmResponse`); ``run["theta_1"]`` by name."""

    def __init__(self, time, states_tx, torque_tu, state_names, n_links: int,
                 title: str = "flexarm continuous closed loop"):
        super().__init__(time, np.asarray(states_tx).T, np.asarray(torque_tu).T, state_names,
                         n_links, title)

    def to_csv(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write ``time``, every state and every torque as columns (SI: s, rad, m, rad/s,
        m/s, N·m) through :func:`flexarm.io.logs.write_log`; refuses to overwrite unless asked."""
        cols = {nm: self.states[k] for k, nm in enumerate(self.state_names)}
        cols.update({nm: self.inputs[k] for k, nm in enumerate(self.input_labels)})
        return write_log(path, self.time, cols, overwrite=overwrite, fmt="%.10g",
                         required=("time",), comments=[
                             f"{self.title}: {self.n_links} links",
                             "units: time [s], theta [rad], delta [m], theta_dot [rad/s], "
                             "delta_dot [m/s], torque [N*m]"])

    def __getitem__(self, name: str) -> np.ndarray:
        if name in self.state_names:
            return self.states[self.state_names.index(name)]
        if name in self.input_labels:
            return self.inputs[self.input_labels.index(name)]
        raise KeyError(f"{name!r}: no such signal; states: {', '.join(self.state_names)}; "
                       f"inputs: {', '.join(self.input_labels)}")


class ContinuousBatch(_ArmResponse):
    """N rollouts as python-control traces: ``states`` (n_x, N, T), ``inputs`` (n_links, N,
    T); the views put the rollout first (``theta`` (N, T, n_links), ``torque``,
    ``state_array`` (N, T, n_x)); ``diverged[i]`` when rollout i became non-finite or left
    the bound (its samples from then on are not meaningful); :meth:`run` gives one."""

    def __init__(self, time, states_ntx, torque_ntu, diverged, state_names, n_links: int):
        self.diverged = np.asarray(diverged)
        super().__init__(time, np.moveaxis(np.asarray(states_ntx), 2, 0),
                         np.moveaxis(np.asarray(torque_ntu), 2, 0), state_names, n_links,
                         "flexarm continuous closed loops")

    def run(self, i: int) -> ContinuousRun:
        """Rollout i as a :class:`ContinuousRun`."""
        return ContinuousRun(self.time, self.state_array[i], self.torque[i], self.state_names,
                             self.n_links)


def _saturate(plant, u: Array) -> Array:
    """Clip u (shape (n_u, *batch)) to the plant's torque limits."""
    lim = plant.command_limit
    lim = lim.reshape(lim.shape + (1,) * (jnp.ndim(u) - 1))
    return jnp.clip(u, -lim, lim)


@eqx.filter_jit
def _run_rk4(plant, law, params, x0, h, n_sub, n_out: int):
    def f(x, t):
        return plant.rhs(x, _saturate(plant, law(params, x, t)))

    xs = rk4_path(f, x0, h, n_sub, n_out)
    ts = jnp.arange(n_out + 1) * (h * n_sub)
    us = jax.vmap(lambda x, t: _saturate(plant, law(params, x, t)))(xs, ts)
    return ts, xs, us


@eqx.filter_jit
def _run_rk4_batch(plant, law, params, axes, x0, h, n_sub, n_out: int, chunk: int):
    """Rollouts of a batch in chunks of ``chunk``: the leaves of ``params`` batched along
    axis 0 where the vmap-style prefix ``axes`` says 0, x0 of shape (N, n_x), N a multiple
    of chunk. Within a chunk the state is carried as (n_x, chunk), batch last: every layer
    of the plant's right-hand side is then one SIMD kernel over the chunk, and the law is
    vmapped over it. Chunks run one after the other (lax.map), so that a chunk's working set
    stays in cache. Returns t (T,), x (N, T, n_x), u (N, T, n_u)."""
    N = x0.shape[0]
    leaves, treedef = jax.tree.flatten(params)
    leaf_axes = _leaf_axes(params, axes)
    law_b = jax.vmap(law, in_axes=(axes, -1, None), out_axes=-1)
    ts = jnp.arange(n_out + 1) * (h * n_sub)

    def one_chunk(c):
        lv = [leaf if ax is None else jax.lax.dynamic_slice_in_dim(leaf, c * chunk, chunk, 0)
              for leaf, ax in zip(leaves, leaf_axes)]
        pc = jax.tree.unflatten(treedef, lv)
        xc = jax.lax.dynamic_slice_in_dim(x0, c * chunk, chunk, 0).T

        def f(x, t):
            return plant.rhs(x, _saturate(plant, law_b(pc, x, t)))

        xs = rk4_path(f, xc, h, n_sub, n_out, unroll=True)  # (T, n_x, chunk)
        us = jax.vmap(lambda x, t: _saturate(plant, law_b(pc, x, t)))(xs, ts)
        return jnp.moveaxis(xs, -1, 0), jnp.moveaxis(us, -1, 0)

    xs, us = jax.lax.map(one_chunk, jnp.arange(N // chunk))
    return ts, xs.reshape((N,) + xs.shape[2:]), us.reshape((N,) + us.shape[2:])


class _Axis:
    """A batch axis (0 or None) as an opaque pytree leaf."""

    def __init__(self, v):
        self.v = v


def _leaf_axes(tree, axes) -> list:
    """The vmap-style prefix ``axes`` (0 or None per subtree) broadcast to the leaves of tree."""
    full = jax.tree.map(lambda ax, sub: jax.tree.map(lambda _: _Axis(ax), sub), axes, tree,
                        is_leaf=lambda a: a is None)
    return [a.v for a in jax.tree.leaves(full, is_leaf=lambda a: isinstance(a, _Axis))]


@eqx.filter_jit
def _run_tsit5(plant, law, params, x0, ts, rtol, atol, dt0, max_steps: int):
    import diffrax

    def f(t, x, args):
        return plant.rhs(x, _saturate(plant, law(params, x, t)))

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(f), diffrax.Tsit5(), ts[0], ts[-1], dt0, x0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        max_steps=max_steps, throw=False)
    xs = sol.ys
    us = jax.vmap(lambda x, t: _saturate(plant, law(params, x, t)))(xs, ts)
    return xs, us, sol.result == diffrax.RESULTS.successful, sol.stats["num_steps"]


def simulate_continuous(model: MultiLinkModel, law: Callable, x0, t_final: float,
                        dt: float = 1e-3, *, params=None, method: str = "rk4",
                        step: float = 1e-4, rtol: float = 1e-8, atol: float = 1e-10,
                        max_steps: int = 2_000_000, bound: float = 1e4) -> ContinuousRun:
    """Continuous-time closed loop ẋ = f(x, sat(law(params, x, t))) from x0 over [0, t_final].

    Outputs every ``dt`` (s). ``method``: ``rk4`` (fixed step ``step``, default 0.1 ms; dt is
    rounded to a whole number of steps) or ``tsit5`` (diffrax, adaptive, ``rtol``/``atol``).
    Raises :class:`SimulationDiverged` naming the first time and state variable that is
    non-finite or larger than ``bound`` in absolute value (SI units), or the time at which
    the adaptive solver gave up."""
    plant = model.plant
    x0 = np.asarray(x0, float)
    if x0.size != 2 * model.n_q:
        raise ValueError(f"x0 has {x0.size} values; this arm's state has {2 * model.n_q}: "
                         f"{', '.join(plant.state_names)} (model.state(theta=...) builds one)")
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 holds NaN or infinite values: {x0.ravel().tolist()}")
    x0 = jnp.asarray(x0.reshape(2 * model.n_q))
    if not (t_final > 0 and dt > 0):
        raise ValueError(f"t_final and dt must be > 0; got {t_final}, {dt}")
    n_out = int(round(t_final / dt))
    if n_out < 1:
        raise ValueError(f"dt = {dt} s is longer than t_final = {t_final} s")
    if method == "rk4":
        n_sub = max(1, int(round(dt / step)))
        ts, xs, us = _run_rk4(plant, law, params, x0, jnp.asarray(dt / n_sub),
                              jnp.asarray(n_sub), n_out)
        ok, t_fail = True, None
    elif method == "tsit5":
        ts = jnp.linspace(0.0, n_out * dt, n_out + 1)
        xs, us, ok, _ = _run_tsit5(plant, law, params, x0, ts, rtol, atol,
                                   min(dt, step), max_steps)
        ok = bool(ok)
        t_fail = None
    else:
        raise ValueError(f"method must be 'rk4' or 'tsit5'; got {method!r}")
    ts, xs, us = np.asarray(ts), np.asarray(xs), np.asarray(us)
    bad = ~np.isfinite(xs) | (np.abs(np.nan_to_num(xs, nan=np.inf)) > bound)
    if bad.any():
        k = int(np.argmax(bad.any(axis=1)))
        j = int(np.argmax(bad[k]))
        raise SimulationDiverged(
            f"closed loop diverged at t = {ts[k]:.6g} s: {plant.state_names[j]} = {xs[k, j]:.4g} "
            f"(bound ±{bound:g}); reduce the gains or the step ({method}, step "
            f"{step if method == 'rk4' else 'adaptive'}), or use an interpolating trajectory"
        )
    if not ok:
        t_fail = ts[-1]
        raise SimulationDiverged(
            f"adaptive solver (tsit5) failed before t = {t_fail:.6g} s (step size collapsed "
            f"or max_steps = {max_steps} reached): the closed loop is stiff or diverging"
        )
    return ContinuousRun(ts, xs, us, plant.state_names, model.n_links)


def simulate_continuous_batch(model: MultiLinkModel, law: Callable, x0, t_final: float,
                              dt: float = 1e-3, *, params, axes, step: float = 1e-4,
                              chunk: int = 128, bound: float = 1e4) -> ContinuousBatch:
    """N closed loops ẋ = f(x, sat(law(params_i, x, t))) at once, fixed-step RK4 (``step``,
    default 0.1 ms), outputs every ``dt``: what :func:`simulate_continuous` does for one.

    ``params``/``axes``: a parameter pytree and its vmap-style batch axes (0 on the leaves
    that hold the batch along their first axis, None on shared ones), e.g. from
    :func:`flexarm.control.regulation.regulation_params_batch`. ``x0``: (n_x,) shared or (N, n_x). The batch runs in
    chunks of ``chunk`` rollouts, state carried batch-last (see ``_run_rk4_batch``); N is
    padded to a multiple of chunk with copies of the last rollout. Gains are traced: any
    sweep of the same size compiles once. A run that diverges is flagged in ``diverged``
    rather than raised."""
    plant = model.plant
    nx = 2 * model.n_q
    if not (t_final > 0 and dt > 0):
        raise ValueError(f"t_final and dt must be > 0; got {t_final}, {dt}")
    n_out = int(round(t_final / dt))
    if n_out < 1:
        raise ValueError(f"dt = {dt} s is longer than t_final = {t_final} s")
    n_sub = max(1, int(round(dt / step)))
    leaf_axes = _leaf_axes(params, axes)
    sizes = {int(leaf.shape[0]) for leaf, ax in zip(jax.tree.leaves(params), leaf_axes)
             if ax is not None}
    if any(ax not in (None, 0) for ax in leaf_axes):
        raise ValueError("axes must be 0 (batched along the first axis) or None")
    x0 = np.asarray(x0, float)
    if x0.shape[-1:] != (nx,) or x0.ndim > 2 or not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be ({nx},) or (N, {nx}) finite values ({', '.join(plant.state_names)}); "
                         f"got shape {x0.shape}")
    if x0.ndim == 2:
        sizes.add(x0.shape[0])
    if len(sizes) != 1:
        raise ValueError(f"batched leaves and x0 disagree on the batch size: {sorted(sizes)}")
    N = sizes.pop()
    x0 = np.broadcast_to(x0.reshape(-1, nx), (N, nx))
    chunk = max(1, min(int(chunk), N))
    pad = -N % chunk

    def padded(a, ax):
        if ax is None or pad == 0:
            return a
        return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)])

    leaves, treedef = jax.tree.flatten(params)
    params_p = jax.tree.unflatten(treedef, [padded(a, ax) for a, ax in zip(leaves, leaf_axes)])
    x0_p = padded(jnp.asarray(x0), 0)
    ts, xs, us = _run_rk4_batch(plant, law, params_p, axes, x0_p, jnp.asarray(dt / n_sub),
                                jnp.asarray(n_sub), n_out, chunk)
    ts, xs, us = np.asarray(ts), np.asarray(xs)[:N], np.asarray(us)[:N]
    bad = ~np.isfinite(xs) | (np.abs(np.nan_to_num(xs, nan=np.inf)) > bound)
    return ContinuousBatch(ts, xs, us, bad.any(axis=(1, 2)), plant.state_names, model.n_links)
