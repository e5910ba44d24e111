"""The protocol every continuous plant follows to be simulated by :mod:`flexarm.sim.sampled`.

A plant is an ``equinox.Module`` (so it is a pytree: its numeric fields may be traced, stacked
and ``vmap``-ed, e.g. for parameter sweeps) with a flat float64 state vector ``x`` (shape (n,))
and a command vector ``u`` (shape (m,)), held constant between samples (zero-order hold).

* ``rhs(x, u)``: ẋ, one ``jnp.stack``/concatenate of the derivatives (no tuples of
  scalars: see docs/performance.md).
* ``signals(x, u)``: the physical signals named by ``signal_names`` (what sensors can read
  and what results record), shape (p,).
* ``project(x_prev, x_next, u)``: applied after each integration substep, for hybrid
  events (a joint that sticks). The default returns ``x_next``.
* ``command_limit``: saturation of u, shape (m,) (``inf`` for none).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
from jax import Array


class Plant(eqx.Module):
    """Base class of simulated plants (see module docstring)."""

    state_names: tuple[str, ...] = eqx.field(static=True)
    signal_names: tuple[str, ...] = eqx.field(static=True)
    input_names: tuple[str, ...] = eqx.field(static=True)

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @abc.abstractmethod
    def rhs(self, x: Array, u: Array) -> Array:
        """ẋ = f(x, u)."""

    @abc.abstractmethod
    def signals(self, x: Array, u: Array) -> Array:
        """The physical signals named by ``signal_names``."""

    def project(self, x_prev: Array, x_next: Array, u: Array) -> Array:
        return x_next

    @property
    def command_limit(self) -> Array:
        return jnp.full((self.n_inputs,), jnp.inf)
