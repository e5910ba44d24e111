"""A motor and hub driving one flexible link: linear transfer functions and the nonlinear plant.

Hub (FRB eq. 1, with the drive of :mod:`flexarm.models.motor`):

    J θ̈m = k_u u − k_ω θ̇m − V θ̇m − C_t + τ_bias − F_friction

and the link block of :mod:`flexarm.models.lumped_beam` (θm, θ̇m → θt, C_t, w_tip).
Linear part (friction off), FRB eq. (12):

    G_m(s) = θm/u = k_u / (J s² + (V + k_ω) s + C_t(s)/θm(s))
    C_t(s)/θm(s) = H(s) (1 − G_b(s))      (= C (1 − G_b) for the single-mass arm)

State of the nonlinear plant: x = (θm, θ̇m, z_beam..., z_friction...); the plant is the
one-link case of :class:`flexarm.models.assembly.Arm` (:meth:`SingleLinkModel.plant`).

A linear axis (``arm.joint = "prismatic"``, a rigid carriage) is the same equations in
linear units: m θ̈ = k_u u − k_ω θ̇ − V θ̇ + b − F with the position θ in m, the mass m in
kg (``J``: the motor's ``inertia`` plus the carriage's masses), forces in N.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import control
import jax.numpy as jnp
import numpy as np

from flexarm.models.assembly import Arm, SingleLinkBody
from flexarm.models.friction import Friction
from flexarm.models.lumped_beam import BeamBlock, _clean, beam_block, rigid_beam_inertia
from flexarm.models.motor import Drive
from flexarm.specs.arm import RigidBeam, SingleLinkArm

SIGNALS = SingleLinkBody.signal_names + SingleLinkBody.friction_names


def _named(
    g: control.TransferFunction, name: str, input: str, output: str
) -> control.TransferFunction:
    """``g`` with a name and signal names (python-control prints and connects by them)."""
    return control.TransferFunction(g.num, g.den, g.dt, name=name, inputs=[input], outputs=[output])


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
    def from_spec(cls, arm: SingleLinkArm, *, hold_tip: bool = False) -> SingleLinkModel:
        J = arm.motor.inertia
        if isinstance(arm.beam, RigidBeam):
            # a linear axis (prismatic joint): the carriage's masses move with it (kg)
            J += (
                sum(m.mass for m in arm.beam.masses)
                if arm.joint == "prismatic"
                else rigid_beam_inertia(arm.beam)
            )
        block = beam_block(arm.beam)
        if hold_tip:
            block = block.held()
        return cls(
            arm,
            J,
            arm.motor.viscous,
            Drive.from_spec(arm.motor),
            Friction.from_spec(arm.friction),
            block,
        )

    # ----------------------------------------------------------------- linear part
    def beam_tf(self) -> control.TransferFunction:
        """G_b(s) = θt/θm (FRB eq. 13/14), rad/rad; named ``G_b`` (input ``motor_angle``,
        output ``tip_angle``)."""
        return _named(self.beam.transfer_functions()[0], "G_b", "motor_angle", "tip_angle")

    def coupling_tf(self) -> control.TransferFunction:
        """C_t(s)/(θm(s) − θt(s)) (FRB eq. 15; a constant C for the single-mass arm)."""
        return self.beam.coupling_tf()

    def motor_tf(self) -> control.TransferFunction:
        """G_m(s) = θm/u (FRB eq. 12), friction off; u in A or V by the drive."""
        _, ct = self.beam.transfer_functions()
        s = control.tf("s")
        d = self.drive
        g = float(d.k_u) / (self.J * s**2 + (self.V + float(d.k_omega)) * s + ct)
        return _named(
            _clean(control.minreal(g, tol=1e-7, verbose=False)), "G_m", d.input_name, "motor_angle"
        )

    def tip_tf(self) -> control.TransferFunction:
        """θt/u = G_m G_b (rad/A or rad/V); named ``G_t`` (input the drive's, output
        ``tip_angle``)."""
        g = _clean(control.minreal(self.motor_tf() * self.beam_tf(), tol=1e-7, verbose=False))
        return _named(g, "G_t", self.drive.input_name, "tip_angle")

    # ----------------------------------------------------------------- nonlinear plant
    def plant(self) -> Arm:
        """The one-link case of :class:`flexarm.models.assembly.Arm`: the hub and beam block
        as its body, the drive and friction at its one joint."""
        b = self.beam
        body_names = ("motor_angle", "motor_velocity") + tuple(
            f"beam_{k}" for k in range(b.n_states)
        )
        names = body_names + (("friction_z",) if self.friction.n_states else ())
        fr = self.arm.friction
        pushed = fr.pushed_stiffening > 0
        if pushed and b.xbar is None:
            raise ValueError(
                f"arm.friction.pushed_stiffening = {fr.pushed_stiffening:g}: the stiffer "
                "clamp acts on a lumped beam's elastic terms; this beam "
                f"({self.arm.beam.model}) has none: use a lumped beam or set it to 0"
            )
        body = SingleLinkBody(
            J=self.J,
            Ab=jnp.asarray(b.A),
            Bb=jnp.asarray(b.B),
            Cb=jnp.asarray(b.C),
            Db=jnp.asarray(b.D),
            state_names=body_names,
            push_stiffening=float(fr.pushed_stiffening) if pushed else 0.0,
            push_threshold=float(fr.push_threshold) if pushed else float("inf"),
            push_full=float(fr.push_full if fr.push_full is not None else fr.push_threshold)
            if pushed
            else float("inf"),
            pushed=pushed,
        )

        def vec(v) -> Any:  # plain numbers stay Python floats: constants in the compiled loop
            if isinstance(v, (int, float, np.floating, np.integer)):
                return (float(v),)
            return jnp.reshape(jnp.asarray(v, dtype=float), (1,))

        return Arm(
            state_names=names,
            signal_names=SIGNALS,
            input_names=(self.drive.input_name,),
            body=body,
            k_u=vec(self.drive.k_u),
            k_omega=vec(self.drive.k_omega),
            viscous=vec(self.V),
            bias=vec(self.friction.bias),
            limit=vec(self.drive.limit),
            frictions=(self.friction,),
            kind="single",
        )

    def initial_state(
        self, motor_angle: float = 0.0, motor_velocity: float = 0.0, tip_deflection: float = 0.0
    ) -> np.ndarray:
        """State with the hub at ``motor_angle`` and the link statically bent so that its
        tip deflection is ``tip_deflection`` (m), at rest relative to the hub."""
        b = self.beam
        zb = np.zeros(b.n_states)
        if b.mass_dofs:
            n = b.mass_dofs
            assert b.xbar is not None and b.tip_shape is not None  # set for a lumped beam
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
