"""Joint friction at the output shaft, as JAX functions of one joint.

τ_a is the applied torque on the joint without friction (motor torque − V ω − C_t + bias).
The joint accelerates with J ω̇ = τ_a − F.

* ``coulomb`` (FRB eq. 1 with stiction, Karnopp's model): moving, F = F_c sign(ω); in the
  velocity band |ω| < Δv, F = sat(τ_a, ±F_s), so a stuck joint stays stuck while
  |τ_a| <= F_s (breakaway). After each integration substep :meth:`Friction.project` sets
  ω to exactly 0 when the velocity crossed zero or entered the band and |τ_a| <= F_s:
  no creep, and no denormal velocities (docs/performance.md).
* ``stribeck``: as ``coulomb``, moving level F_c + (F_s − F_c) exp(−(ω/ω_s)²).
* ``lugre`` (Canudas de Wit et al. 1995): bristle state z,
  ż = ω − |ω| z σ0 / g(ω),  g(ω) = F_c + (F_s − F_c) exp(−(ω/ω_s)²),  F = σ0 z + σ1 ż.
  Stiff when σ0|ω|/F_c is large: choose substeps h with h σ0 |ω|max / F_c < 1.
* ``none``: F = 0.

Viscous friction is the motor's V (FRB eq. 1), not part of this model.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from flexarm.specs.arm import Friction as FrictionSpec

MODELS = ("none", "coulomb", "stribeck", "lugre")


class Friction(eqx.Module):
    """Friction parameters (SI) and the model's name (static)."""

    model: str = eqx.field(static=True)
    coulomb: Array | float = 0.0
    static: Array | float = 0.0
    stribeck_velocity: Array | float = 0.1
    velocity_tolerance: Array | float = 1e-3
    stiffness: Array | float = 1e3
    damping: Array | float = 1.0
    bias: Array | float = 0.0

    @classmethod
    def from_spec(cls, spec: FrictionSpec) -> Friction:
        return cls(
            model=spec.model,
            coulomb=spec.coulomb,
            static=spec.breakaway,
            stribeck_velocity=spec.stribeck_velocity,
            velocity_tolerance=spec.velocity_tolerance,
            stiffness=spec.stiffness,
            damping=spec.damping,
            bias=spec.bias,
        )

    @property
    def n_states(self) -> int:
        return 1 if self.model == "lugre" else 0

    def _level(self, omega: Array) -> Array:
        if self.model == "coulomb":
            return jnp.asarray(self.coulomb)
        return self.coulomb + (self.static - self.coulomb) * jnp.exp(
            -((omega / self.stribeck_velocity) ** 2)
        )

    def torque(self, omega: Array, tau_applied: Array, z: Array | None) -> tuple[Array, Array]:
        """Friction torque F (N*m) and the friction state derivative (shape (0,) or (1,))."""
        if self.model == "none":
            return jnp.zeros_like(omega), jnp.zeros((0,) + jnp.shape(omega))
        if self.model == "lugre":
            assert z is not None  # LuGre has its one state
            zz = z[0]
            g = self._level(omega) / self.stiffness
            zdot = omega - jnp.abs(omega) * zz / g
            return self.stiffness * zz + self.damping * zdot, zdot[None]
        moving = self._level(omega) * jnp.sign(omega)
        stuck = jnp.clip(tau_applied, -self.static, self.static)
        f = jnp.where(jnp.abs(omega) < self.velocity_tolerance, stuck, moving)
        return f, jnp.zeros((0,) + jnp.shape(omega))

    def sticks(self, omega_prev: Array, omega_next: Array, tau_applied: Array) -> Array:
        """True where the joint is (or becomes) stuck after a substep (Karnopp models)."""
        if self.model not in ("coulomb", "stribeck"):
            return jnp.zeros_like(omega_next, dtype=bool)
        crossed = omega_prev * omega_next <= 0.0
        slow = jnp.abs(omega_next) < self.velocity_tolerance
        return (crossed | slow) & (jnp.abs(tau_applied) <= self.static)
