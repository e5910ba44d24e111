"""The linear model of any assembled arm about a point: a python-control ``StateSpace``.

For an :class:`~flexarm.models.assembly.Arm` ẋ = f(x, u) with signals s = h(x, u), the
Jacobians at (x₀, u₀),

    A = ∂f/∂x,  B = ∂f/∂u,  C = ∂h/∂x,  D = ∂h/∂u   (jax.jacfwd, exact to round-off),

give ẋ̃ = A x̃ + B ũ, s̃ = C x̃ + D ũ for x̃ = x − x₀, ũ = u − u₀. Joint friction is left out
(:func:`frictionless`): Coulomb friction and stiction have no linearisation at rest (the
friction torque is a set there), and a controller designed on the linear model meets them
in simulation, not in the design. The drives' viscous and back-EMF damping stay in A.

The inputs are the joints' commands (A, V or N·m, :attr:`Arm.input_names`), the states the
arm's (:attr:`Arm.state_names`), the outputs the signals asked for by name
(:attr:`Arm.signal_names`), so python-control's named-signal tools (``interconnect``,
indexing by name) work on the result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import control
import jax
import jax.numpy as jnp
import numpy as np

from flexarm.models.assembly import Arm
from flexarm.models.friction import Friction


def frictionless(arm: Arm) -> Arm:
    """The same arm with every joint's friction model set to ``none`` (a LuGre joint's
    bristle state is dropped); viscous friction and the drives are kept."""
    n_fric = sum(f.n_states for f in arm.frictions)
    names = arm.state_names[: len(arm.state_names) - n_fric]
    none = tuple(Friction(model="none", bias=f.bias) for f in arm.frictions)
    return dataclasses.replace(arm, frictions=none, state_names=names)


def linearize(
    arm: Arm,
    x0: Sequence[float] | np.ndarray | None = None,
    u0: Sequence[float] | np.ndarray | None = None,
    outputs: Sequence[str] | None = None,
) -> control.StateSpace:
    """The continuous-time linear model of ``arm`` (friction left out) about the state
    ``x0`` (default: rest at zero) and command ``u0`` (default zero), with the signals
    ``outputs`` (names of :attr:`Arm.signal_names`; default: the joint angles, i.e. the
    first ``n_joints`` signals) as outputs.

    Raises ValueError naming an unknown output or a state / command of the wrong size."""
    lin = frictionless(arm)
    n, m = lin.n_states, lin.n_inputs
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)[:n]
    u0 = np.zeros(m) if u0 is None else np.asarray(u0, dtype=float)
    if x0.shape != (n,):
        raise ValueError(
            f"linearize: x0 has {x0.size} entries; the arm has {n} states "
            f"({', '.join(lin.state_names)})"
        )
    if u0.shape != (m,):
        raise ValueError(
            f"linearize: u0 has {u0.size} entries; the arm has {m} inputs "
            f"({', '.join(lin.input_names)})"
        )
    names = list(outputs) if outputs is not None else list(lin.signal_names[: arm.n_joints])
    for name in names:
        if name not in lin.signal_names:
            raise ValueError(
                f"linearize: output {name!r} is not a signal of the arm; its "
                f"signals: {', '.join(lin.signal_names)}"
            )
    idx = [lin.signal_names.index(k) for k in names]
    x, u = jnp.asarray(x0), jnp.asarray(u0)
    A, B = jax.jacfwd(lin.rhs, argnums=(0, 1))(x, u)
    C, D = jax.jacfwd(lambda x, u: lin.signals(x, u)[jnp.asarray(idx)], argnums=(0, 1))(x, u)
    return control.ss(
        np.asarray(A),
        np.asarray(B),
        np.asarray(C),
        np.asarray(D),
        states=list(lin.state_names),
        inputs=list(lin.input_names),
        outputs=names,
        name="linearised arm",
    )
