"""Scenario spec of the bench rigs' state-feedback controller (``type = "state_feedback"``).

    u = k1 (r − θ) − k2 d − k3 θ̇ − k4 ḋ

θ the measured hub angle (rad), d the measured tip deflection (m), rates from the
measured signals by ``rate``: ``backward`` difference or a ``filtered`` first-order
derivative s/(τ s + 1) with τ = ``rate_time_constant`` (s). See
:mod:`flexarm.control.state_feedback`. A hub PD (derivative on the measured angle) is
k2 = k4 = 0.
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

from typing import Literal

from pydantic import model_validator

from flexarm.specs.friction_compensation import FrictionCompensationSpec
from flexarm.specs.quantity import Q, Spec


class StateFeedbackController(Spec):
    """u = k1 (r − θ) − k2 d − k3 θ̇ − k4 ḋ on measured hub angle θ and tip deflection d."""

    type: Literal["state_feedback"]
    friction_compensation: FrictionCompensationSpec | None = None
    k1: Q("", what="V/rad (or A/rad) on the hub-angle error")
    k2: Q("", what="V/m on the tip deflection") = 0.0
    k3: Q("", what="V*s/rad on the hub rate") = 0.0
    k4: Q("", what="V*s/m on the tip-deflection rate") = 0.0
    rate: Literal["backward", "filtered"] = "backward"
    rate_time_constant: Q("s", ge=0, what="filter time constant of the filtered rate") = 0.0
    #: names of four input channels (like references: arrays at the samples, e.g. a log's
    #: gain columns) carrying K1..K4 per sample: a law whose gains change during the run
    #: (a lab's logger records them); k1..k4 are then the gains at the first sample and the
    #: channels default to them where no array is given. None: k1..k4 throughout
    gain_signals: tuple[str, str, str, str] | None = None

    @property
    def measured(self) -> str:
        """The angle the law closes on (the scenario checks it is a known signal)."""
        return "motor_angle"

    @model_validator(mode="after")
    def _filter_has_tau(self) -> StateFeedbackController:
        if self.rate == "filtered" and not self.rate_time_constant > 0:
            raise ValueError(
                "rate = 'filtered' needs rate_time_constant > 0 s "
                "(e.g. 0.02 s for a 50 rad/s derivative filter)"
            )
        return self
