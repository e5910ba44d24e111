"""Discrete-time controllers that the sampled-data simulator runs at the sample instants.

A controller is an ``equinox.Module`` (a pytree: its gains may be traced and batched with
``vmap``) with

* ``init() -> state``: its initial state (any pytree of arrays);
* ``step(state, measured, reference) -> (state, u)``: one sample. ``measured`` and
  ``reference`` are dicts of scalars keyed by signal name (``"motor_angle"``,
  ``"tip_angle"``, ... and ``"reference"``, plus any named reference channel); ``u`` has
  shape (m,) (the plant's command: current in A or voltage in V).

Built-in: :class:`LinearController` (any discrete state-space or transfer function on
the error e = reference − measured; :func:`pd`, :func:`pid`, :func:`lead`,
:func:`from_transfer_function` build it), :class:`Sum`, :class:`Cascade`, and
:class:`FunctionController` for a user's own JAX-traceable law.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from typing import Any

import control
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax import Array

Signals = dict[str, Array]


class Controller(eqx.Module):
    """Base class (see module docstring)."""

    @abc.abstractmethod
    def init(self) -> Any:
        """Initial controller state."""

    @abc.abstractmethod
    def step(self, state: Any, measured: Signals, reference: Signals) -> tuple[Any, Array]:
        """One sample: new state and the command u, shape (m,)."""


class LinearController(Controller):
    """x⁺ = A x + B e,  u = C x + D e,  e = reference[ref] − measured[measured].

    ``A, B, C, D`` are a discrete single-input single-output realisation (arrays (n, n),
    (n,), (n,), scalar). Build it with :func:`pd`, :func:`pid`, :func:`lead` or
    :func:`from_transfer_function`.
    """

    A: Array
    B: Array
    C: Array
    D: Array
    measured: str = eqx.field(static=True, default="motor_angle")
    reference: str = eqx.field(static=True, default="reference")

    def init(self) -> Array:
        return jnp.zeros(self.B.shape[-1:])

    def step(self, state: Array, measured: Signals, reference: Signals) -> tuple[Array, Array]:
        e = reference[self.reference] - measured[self.measured]
        u = self.C @ state + self.D * e
        return self.A @ state + self.B * e, jnp.reshape(u, (1,))

    def transfer_function(self, dt: float) -> control.TransferFunction:
        """The controller as a discrete python-control transfer function e → u."""
        A, B, C, D = (np.asarray(v, float) for v in (self.A, self.B, self.C, self.D))
        ss = control.ss(A, B.reshape(-1, 1), C.reshape(1, -1), D.reshape(1, 1), dt)
        return control.ss2tf(ss)


def _lin(A, B, C, D, measured: str, reference: str) -> LinearController:
    def f(v):
        return jnp.asarray(v, dtype=float)

    return LinearController(f(A), f(B), f(C), f(D), measured, reference)


def pd(
    kp: float, kd: float, dt: float, *, measured: str = "motor_angle", reference: str = "reference"
) -> LinearController:
    """u_k = kp e_k + kd (e_k − e_{k−1}) / T  (backward-difference derivative)."""
    return _lin([[0.0]], [1.0], [-kd / dt], kp + kd / dt, measured, reference)


def pid(
    kp: float,
    ki: float,
    kd: float,
    dt: float,
    *,
    measured: str = "motor_angle",
    reference: str = "reference",
) -> LinearController:
    """u_k = kp e_k + ki T Σ_{j<=k} e_j + kd (e_k − e_{k−1}) / T  (backward rectangles)."""
    return _lin(
        [[1.0, 0.0], [0.0, 0.0]],
        [dt, 1.0],
        [ki, -kd / dt],
        kp + ki * dt + kd / dt,
        measured,
        reference,
    )


def lead(
    gain: float,
    zero: float,
    pole: float,
    *,
    measured: str = "motor_angle",
    reference: str = "reference",
) -> LinearController:
    """u = gain (z − zero)/(z − pole) e, i.e. x⁺ = pole x + e, u = gain((pole − zero) x + e)."""
    return _lin([[pole]], [1.0], [gain * (pole - zero)], gain, measured, reference)


def from_transfer_function(
    tf: control.TransferFunction | tuple,
    dt: float | None = None,
    *,
    measured: str = "motor_angle",
    reference: str = "reference",
) -> LinearController:
    """Any proper discrete SISO transfer function C(z) (python-control, or (num, den) in
    descending powers of z) acting on the error."""
    if not isinstance(tf, control.TransferFunction):
        num, den = tf
        tf = control.tf(num, den, dt if dt is not None else True)
    if not tf.issiso():
        raise ValueError("from_transfer_function: the controller must be SISO")
    if tf.isctime():
        raise ValueError(
            "from_transfer_function: C(s) is continuous; discretise it first, e.g. "
            "tf.sample(T, method='tustin')"
        )
    num = np.trim_zeros(np.asarray(tf.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(tf.den[0][0], float), "f")
    if len(num) > len(den):
        raise ValueError(f"from_transfer_function: C(z) = {tf} is improper (not causal)")
    ss = control.tf2ss(tf)
    n = ss.nstates
    if n == 0:
        return _lin(np.zeros((1, 1)), [0.0], [0.0], float(ss.D[0, 0]), measured, reference)
    return _lin(ss.A, ss.B[:, 0], ss.C[0], float(ss.D[0, 0]), measured, reference)


class Sum(Controller):
    """u = Σ u_i: controllers acting in parallel (feedback + feedforward terms)."""

    parts: tuple

    def __init__(self, *parts: Controller):
        self.parts = tuple(parts)

    def init(self) -> tuple:
        return tuple(p.init() for p in self.parts)

    def step(self, state, measured, reference):
        new, total = [], None
        for p, s in zip(self.parts, state, strict=True):
            s2, u = p.step(s, measured, reference)
            new.append(s2)
            total = u if total is None else total + u
        return tuple(new), total


class Cascade(Controller):
    """Nested loops: the outer controller's output is the inner one's reference channel
    ``via`` (e.g. the commanded motor angle θ_mr of FRB Fig. 3)."""

    outer: Controller
    inner: Controller
    via: str = eqx.field(static=True, default="inner_reference")

    def init(self) -> tuple:
        return self.outer.init(), self.inner.init()

    def step(self, state, measured, reference):
        so, si = state
        so2, r_inner = self.outer.step(so, measured, reference)
        ref = dict(reference)
        ref[self.via] = r_inner[0]
        si2, u = self.inner.step(si, measured, ref)
        return (so2, si2), u


class FunctionController(Controller):
    """A user's law: ``fn(params, state, measured, reference) -> (state, u)``, JAX-traceable.
    ``params`` is any pytree (batched by ``vmap`` like the built-in gains)."""

    fn: Callable = eqx.field(static=True)
    params: Any
    state0: Any

    def init(self):
        return self.state0

    def step(self, state, measured, reference):
        state, u = self.fn(self.params, state, measured, reference)
        return state, jnp.reshape(jnp.asarray(u, dtype=float), (-1,))
