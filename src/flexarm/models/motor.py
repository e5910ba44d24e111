"""DC motor drives: the torque at the output shaft for a command u.

* current drive (FRB eq. 1): τ = K i, i the commanded current (A);
* voltage drive (geared servo): τ = η_g η_m K_g K_m (v − K_g K_m ω) / R, v in V
  (armature inductance neglected: L/R is far below the mechanical time constants of
  teaching rigs).

Both are ``τ = k_u u − k_ω ω``: current drive k_u = K, k_ω = 0; voltage drive
k_u = η_g η_m K_g K_m / R, k_ω = k_u K_g K_m.
"""

from __future__ import annotations

import equinox as eqx
from jax import Array

from flexarm.specs.arm import CurrentMotor, VoltageMotor


class Drive(eqx.Module):
    """τ = k_u u − k_ω ω (N*m), with u in A (current drive) or V (voltage drive)."""

    kind: str = eqx.field(static=True)
    k_u: Array | float
    k_omega: Array | float
    limit: Array | float

    @classmethod
    def from_spec(cls, motor: CurrentMotor | VoltageMotor) -> Drive:
        if isinstance(motor, CurrentMotor):
            return cls("current", motor.torque_constant, 0.0, motor.current_limit)
        ke = motor.gear_ratio * motor.motor_constant
        ku = motor.gear_efficiency * motor.motor_efficiency * ke / motor.armature_resistance
        return cls("voltage", ku, ku * ke, motor.voltage_limit)

    @property
    def input_name(self) -> str:
        return "current" if self.kind == "current" else "voltage"

    def torque(self, u: Array, omega: Array) -> Array:
        return self.k_u * u - self.k_omega * omega
