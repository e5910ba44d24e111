"""Specs of an experiment on an arm: sampling, sensors, actuator, reference, initial state.

Sensor channels are named after the signals of the plant (``motor_angle``, ``tip_angle``,
``tip_deflection``, ``motor_velocity``); see :mod:`flexarm.sim.sampled`.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, FiniteFloat, field_validator

from flexarm.specs.controllers_bench import StateFeedbackController
from flexarm.specs.quantity import Coefficients, Count, Q, Spec


class Sampling(Spec):
    """Controller sampling: period T (s) and computation delay in whole samples."""

    period: Q("s", gt=0, what="sampling period")
    delay: Count(ge=0, le=100, what="computation delay in samples") = 0


class Sensor(Spec):
    """One measured channel: y = gain·x + noise, then A/D quantisation, optional pure
    delay (samples). ``bits = 0`` means no quantisation; ``range`` is the full span
    of the converter (the count is range / 2**bits); ``noise`` is a standard deviation.
    ``bandwidth`` f_c > 0 puts an analog first-order low-pass in front of the A/D,
    y_f' = 2π f_c (gain·x − y_f) integrated with the plant between samples (y_f = gain·x
    at t = 0), and y = y_f + noise (0: no filter); in Hz (angular units are refused), with
    2π f_c T / simulation.substeps <= 0.5."""

    bits: Count(ge=0, le=32) = 0
    range: Q("", gt=0) = 2 * 3.141592653589793
    noise: Q("", ge=0) = 0.0
    gain: Q("") = 1.0
    delay: Count(ge=0, le=1000, what="sensor delay in samples") = 0
    bandwidth: Q("Hz", ge=0, what="first-order low-pass cutoff; 0 = no filter") = 0.0

    @field_validator("bandwidth", mode="before")
    @classmethod
    def _not_angular(cls, v: object) -> object:
        # pint takes the radian as 1, so "100 rad/s" would silently become 100 Hz
        if isinstance(v, str) and "rad" in v:
            from flexarm.units import to_si

            w = to_si(v, "Hz", field="bandwidth")
            raise ValueError(f"got {v!r}: an angular frequency; the cutoff is in Hz, "
                             f"f_c = ω_c / 2π: write \"{w / 6.283185307179586:.6g} Hz\"")
        return v


class Actuator(Spec):
    """D/A conversion of the command and its saturation. ``limit`` defaults to the
    motor's current or voltage limit; the D/A spans [-limit, limit] with 2**bits levels."""

    bits: Count(ge=0, le=32) = 0
    limit: Q("", gt=0) | None = None


class Simulation(Spec):
    """Length of the run, integration substeps per sample, and options."""

    duration: Q("s", gt=0)
    substeps: Count(ge=1, le=10000) = 10
    hold_tip: bool = False
    seed: Count(ge=0) = 0


class Initial(Spec):
    """Initial state. A single link: motor angle and velocity, and a static tip deflection
    (m). Several links: ``joint_angles`` and ``joint_velocities`` (one per joint; the links
    start straight, or at their static deflection under gravity with ``equilibrium``)."""

    motor_angle: Q("rad") = 0.0
    motor_velocity: Q("rad/s") = 0.0
    tip_deflection: Q("m") = 0.0
    joint_angles: list[Q("rad")] | None = None
    joint_velocities: list[Q("rad/s")] | None = None
    equilibrium: bool = False


class Reference(Spec):
    """Reference for the controlled angle.

    type: ``step`` (amplitude after ``start``), ``square`` (between offset and
    offset + amplitude, period ``period``), ``sine`` (offset + amplitude·sin(2π t/period)),
    ``constant`` (offset)."""

    type: Literal["step", "square", "sine", "constant"] = "step"
    amplitude: Q("rad") = 0.0
    offset: Q("rad") = 0.0
    start: Q("s", ge=0) = 0.0
    period: Q("s", gt=0) = 1.0


class PDController(Spec):
    """u = kp·e + kd·(e_k − e_{k−1})/T with e = reference − measured (discrete PD)."""

    type: Literal["pd"]
    kp: Q("")
    kd: Q("") = 0.0
    measured: str = "motor_angle"


class PIDController(Spec):
    """u = kp·e + ki·T·Σe + kd·(e_k − e_{k−1})/T (discrete PID, backward rectangles)."""

    type: Literal["pid"]
    kp: Q("")
    ki: Q("") = 0.0
    kd: Q("") = 0.0
    measured: str = "motor_angle"


class LeadController(Spec):
    """u = gain·(z − zero)/(z − pole)·e (discrete lead/lag)."""

    type: Literal["lead"]
    gain: Q("")
    zero: FiniteFloat
    pole: FiniteFloat
    measured: str = "motor_angle"


class TFController(Spec):
    """u = C(z)·e with C(z) = num/den in descending powers of z, at the sampling period."""

    type: Literal["tf"]
    num: Coefficients()
    den: Coefficients(denominator=True)
    measured: str = "motor_angle"


ControllerSpec = (PDController | PIDController | LeadController | TFController
                  | StateFeedbackController)
