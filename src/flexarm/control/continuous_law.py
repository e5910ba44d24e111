"""A continuous-time control law in the sampled-data loop: evaluated at every integration stage.

De Luca & Siciliano's regulation laws (DLS eqs. (8), (30); :mod:`flexarm.control.regulation`)
are continuous: the torque follows the plant state between samples, with no sampling and no
hold. :class:`ContinuousLaw` is the controller kind that runs them in the one sampled-data
loop (:mod:`flexarm.sim.sampled`): the loop evaluates, at every stage of its integrator,

    u(t) = sat( u_s,k + law(params, x(t), t) ),      t_k <= t < t_k + T,

where x is the plant state (rad, m, rad/s, m/s; the plant's own state vector), ``law`` any
JAX function ``law(params, x, t) -> u`` (shape (m,), the plant's command units, e.g. N·m),
u_s,k the held command of an optional sampled part (any :class:`~flexarm.control.discrete.
Controller`, stepped at the samples on the sensors' readings, after the computation delay,
saturation and D/A of the actuator), and sat the actuator's limit ±u_max. Without the sampled
part u_s = 0 and u(t) = sat(law(x(t), t)): the continuous closed loop ẋ = f(x, sat(law(x, t))).
The sensors still read at the samples.

The controller's state carries the sample count k, so the law sees t = k T + τ (τ the time
within the period).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import Array

from flexarm.control.discrete import Controller, Signals


class ContinuousLaw(Controller):
    """``law(params, x, t)`` evaluated inside the integrator (module docstring), plus the held
    command of ``sampled`` (None: the law alone). ``n_inputs``: the plant's command size m;
    ``dt``: the sample period T (s)."""

    law: Callable = eqx.field(static=True)
    params: Any
    dt: Array
    n_inputs: int = eqx.field(static=True)
    sampled: Controller | None = None
    #: a batch carried batch-last (the loop's state (n_x, B)): the batch axis (0 or None)
    #: of each leaf of ``params`` (in ``jax.tree.leaves`` order); None: no such batch
    batch_axes: tuple | None = eqx.field(static=True, default=None)

    @property
    def measured_signals(self) -> tuple[str, ...]:
        return ()

    def init(self):
        return (() if self.sampled is None else self.sampled.init()), jnp.zeros(())

    def step(self, state, measured: Signals, reference: Signals):
        """The sampled part's command (zeros without one); the sample count advances."""
        s, k = state
        if self.sampled is None:
            u = jnp.zeros((self.n_inputs,))
        else:
            s, u = self.sampled.step(s, measured, reference)
        return (s, k + 1.0), u

    def time(self, state) -> Array:
        """t_k = k T (s) of the sample a state (before its step) belongs to."""
        return state[1] * self.dt

    def command(self, x: Array, t: Array) -> Array:
        """law(params, x, t): the continuous part of the command (before saturation); for
        a batch carried batch-last, x (n_x, B) → (m, B), the law vmapped over B."""
        if self.batch_axes is None:
            return self.law(self.params, x, t)
        axes = jax.tree.unflatten(jax.tree.structure(self.params), list(self.batch_axes))
        return jax.vmap(self.law, in_axes=(axes, -1, None), out_axes=-1)(self.params, x, t)
