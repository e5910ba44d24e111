r"""Feliu's two nested loops, built from numbers (a scenario's ``[controller] type =
"nested"``, :mod:`flexarm.specs.nested`): the inner hub loop
:class:`~flexarm.control.inner_loop.InnerLoop` (FRB Fig. 4) inside the outer tip loop
:func:`~flexarm.control.outer_loop.tip_loop` (FRB Fig. 5),

    θ_mr = θ̂_mr + G_cb(z) (θ_tr − θt),
    u    = G_cm1(z) [θ_mr − G_cm2(z) θm] + ĉ (θm − θt) + c_f σ       (command units)

For a rig whose link carries a strain gauge instead of a tip sensor,
:class:`MeasuredTip` forms the measured tip angle from the hub encoder and the gauge,
θt = θm + s · d (rad; d the ``tip_deflection`` channel, s = 1/(gain · L) rad per unit), so
the coupling estimate is ĉ (θm − θt) = −ĉ s d: the link stiffness times the measured
deflection angle.
"""

from __future__ import annotations

import control
import jax.numpy as jnp
from jax import Array

from flexarm.control.discrete import Controller, Signals
from flexarm.control.inner_loop import inner_loop
from flexarm.control.outer_loop import tip_loop

__all__ = ["MeasuredTip", "nested_loops"]


class MeasuredTip(Controller):
    """Runs ``law`` with ``measured["tip_angle"]`` = θm + ``scale`` · d, θm the
    ``motor_angle`` channel (rad), d the ``tip_deflection`` channel (its units; ``scale``
    rad per unit). The law is kept in ``law`` (not walked for sensor names: the loop reads
    only the encoder and the gauge)."""

    law: Controller
    scale: Array

    measured_signals = ("motor_angle", "tip_deflection")

    def init(self):
        return self.law.init()

    def step(self, state, measured: Signals, reference: Signals):
        m = dict(measured)
        m["tip_angle"] = measured["motor_angle"] + self.scale * measured["tip_deflection"]
        return self.law.step(state, m, reference)


def nested_loops(
    gcm1: control.TransferFunction,
    gcm2: control.TransferFunction,
    gcb: control.TransferFunction,
    *,
    dt: float,
    coupling_gain: float = 0.0,
    friction_level: float = 0.0,
    angle_resolution: float = 0.0,
    velocity_deadband: float | None = None,
    rest_deadband: float | None = None,
    deflection_to_angle: float | None = None,
) -> Controller:
    """The nested loops in command units (the inner loop's torque constant is 1: ĉ =
    ``coupling_gain`` per rad of bending, c_f = ``friction_level``). ``gcm1``, ``gcm2``,
    ``gcb``: discrete SISO transfer functions at ``dt`` (s). ``deflection_to_angle``: None
    reads the ``tip_angle`` channel, else the tip angle comes from the gauge
    (:class:`MeasuredTip`). Deadbands: see :func:`~flexarm.control.inner_loop.inner_loop`
    (``angle_resolution`` the hub encoder count, rad)."""
    inner = inner_loop(
        gcm1,
        gcm2,
        dt=dt,
        torque_constant=1.0,
        coulomb=friction_level,
        coupling=coupling_gain,
        friction_compensation=friction_level != 0.0,
        angle_resolution=angle_resolution,
        velocity_deadband=velocity_deadband,
        rest_deadband=rest_deadband,
        reference="motor_reference",
    )
    law = tip_loop(inner, gcb, dt)
    if deflection_to_angle is None:
        return law
    return MeasuredTip(law, jnp.asarray(float(deflection_to_angle)))
