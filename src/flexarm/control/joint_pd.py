"""A sampled PD per joint with constant gravity compensation (DLS law (8), sampled) and,
optionally, Feliu's Coulomb friction compensation per joint (FRB Sec. III-B).

At each sample k, for joint j with measured angle θ_j,k (after the encoder's quantisation):

    v̂_j,k  = (θ_j,k − θ_j,k−1) / T                                  (backward difference)
    τ_pd   = K_P,j (θ_d,j − θ_j,k) − K_D,j v̂_j,k
    τ_j,k  = τ_pd + g_j + C_f,j σ_j,k,        u_j,k = τ_j,k / k_u,j

with g = g_θ(θ_d, δ_d) the gravity torque at the target and its residual deflection
(DLS eqs. (8), (9); :func:`flexarm.control.regulation.residual_deflection`), computed once,
and the friction sign as in FRB's motor loop (:mod:`flexarm.control.inner_loop`):
σ = sgn v̂ while |v̂| > ``velocity_deadband``, else the sign of τ_pd when
|τ_pd| > ``rest_deadband``, else 0. A joint held by stiction F_s stops where
|τ_pd + g_j − g_θ,j(θ)| <= F_s; the compensation adds C_f in the direction the PD pushes,
so an error of a few encoder counts breaks the joint free again. u_j is the drive's command
(A or V): the law is designed in torque and divided by the drive's torque per unit command
k_u (the voltage drive's back-EMF then acts as extra damping k_ω θ̇).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from flexarm.control.discrete import Controller, Signals
from flexarm.control.friction_compensation import friction_sign


class JointPD(Controller):
    """See the module docstring. Arrays have one entry per joint (SI)."""

    kp: Array
    kd: Array
    target: Array
    gravity: Array  # g_θ(θ_d, δ_d), N·m
    coulomb: Array  # C_f, N·m (0: no friction compensation)
    k_u: Array  # N·m per unit command
    dt: Array
    velocity_deadband: Array
    rest_deadband: Array
    measured: tuple[str, ...] = eqx.field(static=True)

    @property
    def measured_signals(self) -> tuple[str, ...]:
        return self.measured

    def init(self):
        return jnp.zeros(len(self.measured)), jnp.zeros((), dtype=bool)

    def step(self, state, measured: Signals, reference: Signals):
        prev, started = state
        th = jnp.stack([measured[m] for m in self.measured])
        prev = jnp.where(started, prev, th)
        v = (th - prev) / self.dt
        tau_pd = self.kp * (self.target - th) - self.kd * v
        sigma = friction_sign(v, tau_pd, self.velocity_deadband, self.rest_deadband)
        tau = tau_pd + self.gravity + self.coulomb * sigma
        return (th, jnp.ones((), dtype=bool)), tau / self.k_u


def joint_pd_from_spec(spec, arm, model, dt: float) -> JointPD:
    """The :class:`JointPD` of a scenario's ``[controller] type = "joint_pd"`` on the
    assembled :class:`~flexarm.models.assembly.Arm` and its multi-link model."""
    import numpy as np

    from flexarm.control.regulation import gravity_torque, residual_deflection

    n = len(spec.target)
    if n != arm.n_joints:
        raise ValueError(f"controller.target has {n} joints; the arm has {arm.n_joints}")
    th_d = np.asarray(spec.target, float)
    if spec.gravity_compensation:
        delta_d = residual_deflection(model, th_d)
        g = np.asarray(gravity_torque(model, th_d, delta_d), float)[:n]
    else:
        g = np.zeros(n)
    cf = (
        np.zeros(n)
        if spec.friction_compensation is None
        else np.asarray(spec.friction_compensation, float)
    )

    def f(v):
        return jnp.asarray(np.asarray(v, float))

    return JointPD(
        kp=f(spec.kp),
        kd=f(spec.kd),
        target=f(th_d),
        gravity=f(g),
        coulomb=f(cf),
        k_u=jnp.asarray(arm.k_u),
        dt=jnp.asarray(float(dt)),
        velocity_deadband=jnp.asarray(spec.velocity_deadband),
        rest_deadband=jnp.asarray(spec.rest_deadband),
        measured=tuple(spec.measured or [f"theta_{i + 1}" for i in range(n)]),
    )
