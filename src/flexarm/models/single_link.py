"""A motor and hub driving one flexible link: linear transfer functions and the nonlinear plant.

Hub (FRB eq. 1, with the drive of :mod:`flexarm.models.motor`):

    J θ̈m = k_u u − k_ω θ̇m − V θ̇m − C_t + τ_bias − F_friction

and the link block of :mod:`flexarm.models.lumped_beam` (θm, θ̇m → θt, C_t, w_tip).
Linear part (friction off), FRB eq. (12):

    G_m(s) = θm/u = k_u / (J s² + (V + k_ω) s + C_t(s)/θm(s))
    C_t(s)/θm(s) = H(s) (1 − G_b(s))      (= C (1 − G_b) for the single-mass arm)

State of the nonlinear plant: x = (θm, θ̇m, z_beam..., z_friction...).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.models.friction import Friction
from flexarm.models.lumped_beam import BeamBlock, _clean, beam_block, rigid_beam_inertia
from flexarm.models.motor import Drive
from flexarm.sim.plant import Plant
from flexarm.specs.arm import RigidBeam, SingleLinkArm

SIGNALS = ("motor_angle", "motor_velocity", "tip_angle", "tip_deflection",
           "coupling_torque", "friction_torque")


def _mv(A: Array, x: Array) -> Array:
    """A @ x for tiny matrices: the column products A[:, j] x[j], summed pairwise.

    Only elementwise operations, which XLA fuses into the right-hand side's kernel. On CPU
    ``@`` is a library call per product (~30x slower), and ``jnp.sum(A * x, -1)`` becomes,
    under ``vmap``, separate reduction kernels with a (batch, rows, cols) broadcast of
    ``A`` per RK stage (docs/performance.md). The pairwise order ((t1 + t0) + (t3 + t2))
    reproduces the results of that ``jnp.sum`` form bit for bit (XLA's reduce order)."""
    terms = [A[..., j] * x[j] for j in range(A.shape[-1])]
    if not terms:
        return jnp.zeros(A.shape[:-1])
    while len(terms) > 1:
        pairs = [terms[i + 1] + terms[i] for i in range(0, len(terms) - 1, 2)]
        terms = pairs + ([terms[-1]] if len(terms) % 2 else [])
    return terms[0]


class SingleLinkPlant(Plant):
    """The nonlinear single-link plant (see module docstring). All fields SI."""

    J: Array | float
    V: Array | float
    drive: Drive
    friction: Friction
    Ab: Array
    Bb: Array
    Cb: Array
    Db: Array

    def _split(self, x: Array):
        nb = self.Ab.shape[0]
        return x[0], x[1], x[2:2 + nb], x[2 + nb:]

    def _forces(self, x: Array, u: Array):
        theta, omega, zb, zf = self._split(x)
        hub = jnp.stack([theta, omega])
        yb = _mv(self.Cb, zb) + _mv(self.Db, hub)
        tau_a = self.drive.torque(u[0], omega) - self.V * omega - yb[1] + self.friction.bias
        f, zf_dot = self.friction.torque(omega, tau_a, zf)
        return hub, zb, yb, tau_a, f, zf_dot

    def rhs(self, x: Array, u: Array) -> Array:
        hub, zb, yb, tau_a, f, zf_dot = self._forces(x, u)
        zb_dot = _mv(self.Ab, zb) + _mv(self.Bb, hub)
        alpha = (tau_a - f) / self.J
        return jnp.concatenate([jnp.stack([hub[1], alpha]), zb_dot, zf_dot])

    def signals(self, x: Array, u: Array) -> Array:
        hub, zb, yb, tau_a, f, _ = self._forces(x, u)
        return jnp.stack([hub[0], hub[1], yb[0], yb[2], yb[1], f])

    def project(self, x_prev: Array, x_next: Array, u: Array) -> Array:
        if self.friction.model not in ("coulomb", "stribeck"):
            return x_next
        _, _, _, tau_a, _, _ = self._forces(x_next, u)
        stuck = self.friction.sticks(x_prev[1], x_next[1], tau_a)
        return x_next.at[1].set(jnp.where(stuck, 0.0, x_next[1]))

    @property
    def command_limit(self) -> Array:
        return jnp.reshape(jnp.asarray(self.drive.limit, dtype=float), (1,))


@dataclass(frozen=True)
class SingleLinkModel:
    """The arm spec turned into numbers: hub, drive, friction and the beam block."""

    arm: SingleLinkArm
    J: float
    V: float
    drive: Drive
    friction: Friction
    beam: BeamBlock

    @classmethod
    def from_spec(cls, arm: SingleLinkArm, *, hold_tip: bool = False) -> "SingleLinkModel":
        J = arm.motor.inertia
        if isinstance(arm.beam, RigidBeam):
            J += rigid_beam_inertia(arm.beam)
        block = beam_block(arm.beam)
        if hold_tip:
            block = block.held()
        return cls(arm, J, arm.motor.viscous, Drive.from_spec(arm.motor),
                   Friction.from_spec(arm.friction), block)

    # ----------------------------------------------------------------- linear part
    def beam_tf(self) -> control.TransferFunction:
        """G_b(s) = θt/θm (FRB eq. 13/14)."""
        return self.beam.transfer_functions()[0]

    def coupling_tf(self) -> control.TransferFunction:
        """C_t(s)/(θm(s) − θt(s)) (FRB eq. 15; a constant C for the single-mass arm)."""
        return self.beam.coupling_tf()

    def motor_tf(self) -> control.TransferFunction:
        """G_m(s) = θm/u (FRB eq. 12), friction off; u in A or V by the drive."""
        _, ct = self.beam.transfer_functions()
        s = control.tf("s")
        d = self.drive
        g = float(d.k_u) / (self.J * s**2 + (self.V + float(d.k_omega)) * s + ct)
        return _clean(control.minreal(g, tol=1e-7, verbose=False))

    def tip_tf(self) -> control.TransferFunction:
        """θt/u = G_m G_b."""
        return _clean(control.minreal(self.motor_tf() * self.beam_tf(), tol=1e-7, verbose=False))

    # ----------------------------------------------------------------- nonlinear plant
    def plant(self) -> SingleLinkPlant:
        b = self.beam
        names = ("motor_angle", "motor_velocity") + tuple(
            f"beam_{k}" for k in range(b.n_states)) + (("friction_z",) if self.friction.n_states else ())
        return SingleLinkPlant(
            state_names=names, signal_names=SIGNALS, input_names=(self.drive.input_name,),
            J=self.J, V=self.V, drive=self.drive, friction=self.friction,
            Ab=jnp.asarray(b.A), Bb=jnp.asarray(b.B), Cb=jnp.asarray(b.C), Db=jnp.asarray(b.D),
        )

    def initial_state(self, motor_angle: float = 0.0, motor_velocity: float = 0.0,
                      tip_deflection: float = 0.0) -> np.ndarray:
        """State with the hub at ``motor_angle`` and the link statically bent so that its
        tip deflection is ``tip_deflection`` (m), at rest relative to the hub."""
        b = self.beam
        zb = np.zeros(b.n_states)
        if b.mass_dofs:
            n = b.mass_dofs
            # absolute coordinates y = x̄ θm + w, w the static shape of the tip deflection;
            # the link at rest relative to the hub: ẏ = x̄ θ̇m
            zb[:n] = b.xbar * motor_angle + b.tip_shape * tip_deflection
            zb[n:] = b.xbar * motor_velocity
        elif b.n_states and (motor_angle != 0.0 or tip_deflection != 0.0):
            raise ValueError(
                "initial motor_angle / tip_deflection need a lumped (physical) beam; a "
                "transfer-function beam starts at rest at zero"
            )
        zf = np.zeros(self.friction.n_states)
        return np.concatenate([[motor_angle, motor_velocity], zb, zf])
