"""Scenario spec of the Coulomb friction compensation added to a controller
(``[controller.friction_compensation]``; :mod:`flexarm.control.friction_compensation`).

    u = u_fb + level · σ,   σ = sgn v̂ moving, sgn u_fb at rest beyond ``rest_deadband``, else 0

``level`` in the drive's command units (A for a current drive, V for a voltage servo): the
joint's Coulomb torque divided by the torque per unit command. ``measured``: the angle
channel whose backward difference v̂ tells moving from resting (default the hub encoder).
``velocity_deadband`` (rad/s; default half an encoder count per sample).
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

from flexarm.specs.quantity import Q, Spec


class FrictionCompensationSpec(Spec):
    """Feliu's Coulomb feedforward (FRB Sec. III-B) on top of the controller's command."""

    level: Q("", ge=0, what="Coulomb level in command units (A or V)")
    measured: str = "motor_angle"
    velocity_deadband: (
        Q(
            "rad/s",
            ge=0,
            what="below it the joint is at rest; default half an encoder count per sample",
        )
        | None
    ) = None
    rest_deadband: Q(
        "", ge=0, what="feedback command below which no compensation acts at rest (command units)"
    ) = 0.0
