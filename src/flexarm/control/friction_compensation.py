r"""Coulomb friction compensation of Feliu, Rattan & Brown (1993), Sec. III-B, for any
feedback controller and any drive.

At each sample k, per driven joint j with measured angle θ_j,k (after the encoder):

    v̂_j,k = (θ_j,k − θ_j,k−1) / T                          (backward difference, rad/s)
    σ_j,k = sgn v̂_j,k                        if |v̂_j,k| >  velocity_deadband
          = sgn u_fb,j,k                     if |v̂_j,k| <= velocity_deadband and
                                                |u_fb,j,k| > rest_deadband
          = 0                                otherwise
    u_j,k = u_fb,j,k + c_j σ_j,k

u_fb the feedback controller's command (A or V), c_j the Coulomb level in command units
(the joint's Coulomb torque C_f divided by the drive's torque per unit command: K for a
current drive, η K_g K_m / R_m for a geared voltage servo). Moving, the compensation
cancels the sliding friction; at rest it pushes in the direction the feedback pushes, so an
error of a few encoder counts breaks the joint free again (what makes the steady-state error
vanish, FRB Fig. 11). The rest deadband stops it from chattering when the feedback is below
what half an encoder count gives; the velocity deadband (default half a count per sample)
tells a joint at rest from a moving one.

:func:`friction_sign` is the one rule; :class:`~flexarm.control.inner_loop.InnerLoop`
(FRB Fig. 4), :class:`~flexarm.control.joint_pd.JointPD` and :class:`FrictionCompensated`
(any feedback controller + this feedforward, the ``[controller.friction_compensation]`` of a
scenario) use it.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from flexarm.control.discrete import Controller, Signals

__all__ = ["FrictionCompensated", "friction_sign", "friction_compensated"]


def friction_sign(v: Array, u_fb: Array, velocity_deadband, rest_deadband) -> Array:
    """σ of the module docstring (elementwise): the sign of the velocity estimate ``v``
    (rad/s) when the joint moves, else of the feedback command ``u_fb`` beyond the rest
    deadband, else 0."""
    rest = jnp.where(jnp.abs(u_fb) > rest_deadband, jnp.sign(u_fb), 0.0)
    return jnp.where(jnp.abs(v) > velocity_deadband, jnp.sign(v), rest)


class FrictionCompensated(Controller):
    """``feedback`` (any :class:`Controller`) plus c σ per output (module docstring).

    Fields: ``level`` c (command units per output, shape (m,)), ``velocity_deadband``
    (rad/s, (m,)), ``rest_deadband`` (command units, (m,)), ``dt`` (s), ``measured`` the
    angle channel read for output j (one name per output)."""

    feedback: Controller
    level: Array
    velocity_deadband: Array
    rest_deadband: Array
    dt: Array
    measured: tuple[str, ...] = eqx.field(static=True)

    @property
    def measured_signals(self) -> tuple[str, ...]:
        inner = tuple(getattr(self.feedback, "measured_signals", ()) or ())
        return tuple(dict.fromkeys(inner + self.measured))

    def init(self):
        return (self.feedback.init(), jnp.zeros(len(self.measured)), jnp.zeros((), dtype=bool))

    def step(self, state, measured: Signals, reference: Signals):
        inner, prev, started = state
        inner, u_fb = self.feedback.step(inner, measured, reference)
        th = jnp.stack([measured[m] for m in self.measured])
        prev = jnp.where(started, prev, th)
        v = (th - prev) / self.dt
        sigma = friction_sign(v, u_fb, self.velocity_deadband, self.rest_deadband)
        return (inner, th, jnp.ones((), dtype=bool)), u_fb + self.level * sigma


def friction_compensated(
    feedback: Controller,
    level,
    *,
    dt: float,
    measured=("motor_angle",),
    quantum=0.0,
    velocity_deadband=None,
    rest_deadband=0.0,
) -> FrictionCompensated:
    """Build a :class:`FrictionCompensated`. ``level``: c per output (A or V; a number for
    one output); ``quantum``: the encoder count of each measured angle (rad), giving the
    default ``velocity_deadband`` = quantum / (2 T) (below half a count per sample the joint
    is taken to be at rest); ``rest_deadband`` in command units (default 0)."""
    measured = (measured,) if isinstance(measured, str) else tuple(measured)
    m = len(measured)

    def f(v):
        return jnp.broadcast_to(jnp.asarray(v, dtype=float), (m,))

    if velocity_deadband is None:
        velocity_deadband = 0.5 * jnp.asarray(quantum, dtype=float) / dt
    return FrictionCompensated(
        feedback, f(level), f(velocity_deadband), f(rest_deadband), jnp.asarray(float(dt)), measured
    )
