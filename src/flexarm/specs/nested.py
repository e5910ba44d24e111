"""Scenario spec of Feliu's two nested loops (``[controller] type = "nested"``;
Feliu, Rattan & Brown (1993), Figs. 3-5; :mod:`flexarm.control.inner_loop`,
:mod:`flexarm.control.outer_loop`).

Per sample (angles rad, command u in the drive's units, A or V):

    θ_mr = θ̂_mr + G_cb(z) (θ_tr − θt)                               (outer, FRB Fig. 5)
    u    = G_cm1(z) [θ_mr − G_cm2(z) θm] + ĉ (θm − θt) + c_f σ         (inner, FRB Fig. 4)

θ_tr the tip trajectory (the ``reference`` channel: ``[reference] type = "parabolic"`` or
``"quasi_parabolic"``), θ̂_mr = N(s) θ_tr the Wiener feedforward (FRB eq. (11)) sent
``feedforward_advance`` s early, computed before the run into the ``feedforward`` channel
(:func:`flexarm.sim.build.nested_feedforward`). ĉ = ``coupling_gain`` (command units per
rad of bending: the link's static stiffness Ĉ over the drive's torque per unit command),
c_f σ the Coulomb feedforward of ``[controller.friction_compensation]`` (level in command
units, the one sign rule :func:`flexarm.control.friction_compensation.friction_sign` on
the inner feedback G_cm1[...]).

θt: the ``tip_angle`` channel, or with ``tip = "tip_deflection"`` the hub encoder plus the
strain gauge, θt = θm + ``deflection_to_angle`` · d (``deflection_to_angle`` = 1/(gain · L)
rad per unit of the channel, the gauge's calibration gain and the link length).
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from flexarm.specs.friction_compensation import FrictionCompensationSpec
from flexarm.specs.quantity import Coefficients, Q, Spec


class NestedController(Spec):
    """Feliu's nested loops (FRB Figs. 3-5): θ_mr = θ̂_mr + G_cb(z)(θ_tr − θt) and
    u = G_cm1(z)[θ_mr − G_cm2(z) θm] + ``coupling_gain``·(θm − θt) + c_f σ (command units;
    c_f σ from ``friction_compensation``). θ̂_mr = N(s) θ_tr (``feedforward_num/den``, in
    s; a dynamic N needs a ``parabolic`` / ``quasi_parabolic`` [reference]) is sent
    ``feedforward_advance`` s early. θt: the ``tip_angle`` channel, or with ``tip =
    "tip_deflection"`` θt = θm + ``deflection_to_angle``·d (1/(gain·L) rad per unit).
    G_cm1, G_cm2, G_cb in z (descending powers) at the sampling period.
    ``flexarm.design.nested.design_nested`` writes it."""

    type: Literal["nested"]
    friction_compensation: FrictionCompensationSpec | None = None
    gcm1_num: Coefficients()
    gcm1_den: Coefficients(denominator=True)
    gcm2_num: Coefficients()
    gcm2_den: Coefficients(denominator=True)
    coupling_gain: Q("", what="command units per rad of bending θm − θt") = 0.0
    tip: Literal["tip_angle", "tip_deflection"] = "tip_angle"
    deflection_to_angle: Q(
        "", what="rad of θt − θm per unit of the tip_deflection channel, 1/(gain·L)"
    ) = 0.0
    gcb_num: Coefficients()
    gcb_den: Coefficients(denominator=True)
    feedforward_num: Coefficients() = [1.0]
    feedforward_den: Coefficients(denominator=True) = [1.0]
    feedforward_advance: Q("s", ge=0, what="the feedforward is sent this much early") = 0.0

    @property
    def measured(self) -> str:
        """The hub angle the inner loop closes on."""
        return "motor_angle"

    @model_validator(mode="after")
    def _tip_source(self) -> NestedController:
        if self.tip == "tip_deflection" and self.deflection_to_angle == 0.0:
            raise ValueError(
                "tip = 'tip_deflection' needs deflection_to_angle = 1/(gain·L) "
                "(rad per unit of the channel), e.g. 1/0.42 for a gauge "
                "calibrated in m on a 0.42 m link"
            )
        if self.tip == "tip_angle" and self.deflection_to_angle != 0.0:
            raise ValueError(
                f"deflection_to_angle = {self.deflection_to_angle:g} is read "
                "only with tip = 'tip_deflection'; drop it or set tip"
            )
        return self
