"""Specs of a single-link flexible arm: motor and hub, drive, joint friction, beam.

All values are stored in SI (kg, m, s, rad, A, V, N*m). Equation numbers refer to
Feliu, Rattan & Brown (1993), "FRB".
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from flexarm.specs.quantity import Coefficients, Q, Spec


class CurrentMotor(Spec):
    """Current-driven DC motor and hub, FRB eq. (1): K i = J θ̈m + V θ̇m + C_t + C_f."""

    drive: Literal["current"] = "current"
    inertia: Q("kg*m**2", gt=0, what="hub and rotor inertia J")
    viscous: Q("N*m*s/rad", ge=0) = 0.0
    torque_constant: Q("N*m/A", gt=0, what="motor constant K")
    current_limit: Q("A", gt=0, what="amplifier current limit")

    @property
    def command_limit(self) -> float:
        return self.current_limit


class VoltageMotor(Spec):
    """Voltage-driven geared DC motor, torque at the output shaft
    τ = η_g η_m K_g K_m (v − K_g K_m ω) / R  (armature inductance neglected)."""

    drive: Literal["voltage"]
    inertia: Q("kg*m**2", gt=0, what="equivalent inertia at the output shaft")
    viscous: Q("N*m*s/rad", ge=0) = 0.0
    motor_constant: Q("V*s/rad", gt=0, what="back-EMF / torque constant K_m")
    armature_resistance: Q("ohm", gt=0)
    gear_ratio: Q("", gt=0) = 1.0
    gear_efficiency: Q("", gt=0, le=1) = 1.0
    motor_efficiency: Q("", gt=0, le=1) = 1.0
    voltage_limit: Q("V", gt=0, what="amplifier voltage limit")

    @property
    def command_limit(self) -> float:
        return self.voltage_limit


Motor = Annotated[CurrentMotor | VoltageMotor, Field(discriminator="drive")]


class Friction(Spec):
    """Joint friction at the output shaft.

    model: ``none``; ``coulomb`` (Coulomb + stiction, Karnopp: a stuck joint stays
    stuck while |applied torque| <= ``static``); ``stribeck`` (as coulomb, with the
    friction falling from ``static`` to ``coulomb`` as exp(-(ω/ω_s)²)); ``lugre``
    (bristle model with stiffness σ0 and damping σ1). Viscous friction is the motor's V.

    ``pushed_stiffening`` s (coulomb/stribeck, single link with a lumped beam): a gear
    train that clamps the link more stiffly while the motor pushes it stuck; while the
    joint is stuck the beam's elastic terms act (1 + s φ) times, φ rising linearly from 0
    to 1 as the drive torque goes from ``push_threshold`` to ``push_full`` (N·m; None: a
    step at the threshold), so the clamped link rings √(1 + s φ) times faster
    (:class:`flexarm.models.assembly.SingleLinkBody`; estimated by
    :func:`flexarm.identification.time_domain.guesses.pushed_ringing`). 0: none.
    """

    model: Literal["none", "coulomb", "stribeck", "lugre"] = "coulomb"
    coulomb: Q("N*m", ge=0) = 0.0
    static: Q("N*m", ge=0) | None = None
    stribeck_velocity: Q("rad/s", gt=0) = 0.1
    velocity_tolerance: Q("rad/s", gt=0) = 1e-3
    stiffness: Q("N*m/rad", gt=0) = 1e3
    damping: Q("N*m*s/rad", ge=0) = 1.0
    bias: Q("N*m") = 0.0
    pushed_stiffening: Q("", ge=0) = 0.0
    push_threshold: Q("N*m", ge=0) = 0.0
    push_full: Q("N*m", ge=0) | None = None

    @property
    def breakaway(self) -> float:
        return self.coulomb if self.static is None else self.static

    @model_validator(mode="after")
    def _static_above_coulomb(self) -> Friction:
        if self.static is not None and self.static < self.coulomb:
            raise ValueError(
                f"static (breakaway) friction {self.static:g} N*m is below the Coulomb "
                f"level {self.coulomb:g} N*m; breakaway must be >= coulomb"
            )
        return self

    @model_validator(mode="after")
    def _pushed_needs_stick(self) -> Friction:
        if self.pushed_stiffening > 0 and self.model not in ("coulomb", "stribeck"):
            raise ValueError(
                f"pushed_stiffening {self.pushed_stiffening:g} needs a joint that sticks: "
                f"model {self.model!r} has no stuck state; use model 'coulomb' or "
                "'stribeck', or set pushed_stiffening = 0"
            )
        return self


class PointMass(Spec):
    """A mass attached to the beam: ``pinned`` (no moment: only its mass counts, as the
    paper's disks) or ``clamped`` (it turns with the beam's slope; its rotary inertia counts)."""

    mass: Q("kg", gt=0)
    position: Q("m", gt=0) | None = None
    rotary_inertia: Q("kg*m**2", ge=0) = 0.0
    joint: Literal["pinned", "clamped"] = "pinned"


class LumpedBeam(Spec):
    """Massless Euler–Bernoulli beam clamped in the hub, carrying point masses.

    Give the flexural rigidity EI directly or as a round wire (diameter, Young's modulus).
    ``damping_ratio`` is the modal damping ratio of every mode.
    """

    model: Literal["lumped"] = "lumped"
    length: Q("m", gt=0)
    flexural_rigidity: Q("N*m**2", gt=0) | None = None
    wire_diameter: Q("m", gt=0) | None = None
    youngs_modulus: Q("Pa", gt=0) | None = None
    damping_ratio: Q("", ge=0, le=1) = 0.0
    masses: list[PointMass] = Field(min_length=1)

    @model_validator(mode="after")
    def _stiffness_given_once(self) -> LumpedBeam:
        wire = self.wire_diameter is not None or self.youngs_modulus is not None
        if self.flexural_rigidity is None and not (
            self.wire_diameter is not None and self.youngs_modulus is not None
        ):
            raise ValueError(
                "give flexural_rigidity (N*m**2), or both wire_diameter and youngs_modulus"
            )
        if self.flexural_rigidity is not None and wire:
            raise ValueError(
                "give either flexural_rigidity or wire_diameter + youngs_modulus, not both"
            )
        for k, m in enumerate(self.masses):
            if m.position is not None and m.position > self.length * (1 + 1e-12):
                raise ValueError(
                    f"masses[{k}].position = {m.position:g} m lies beyond the beam "
                    f"length {self.length:g} m"
                )
        return self

    @property
    def EI(self) -> float:
        if self.flexural_rigidity is not None:
            return self.flexural_rigidity
        import math

        # without flexural_rigidity both are given (validated)
        assert self.youngs_modulus is not None and self.wire_diameter is not None
        return self.youngs_modulus * math.pi * self.wire_diameter**4 / 64.0


class TransferFunctionBeam(Spec):
    """A beam known by its transfer functions (e.g. identified), FRB eqs. (13)-(15):
    θt/θm = G_b(s) = tip_num/tip_den, and C_t = C (θm − θt), or
    C_t = H(s) (θm − θt) with H = coupling_num/coupling_den when given.
    Coefficients in descending powers of s."""

    model: Literal["transfer_function"]
    stiffness: Q("N*m/rad", gt=0, what="coupling stiffness C") | None = None
    tip_num: Coefficients()
    tip_den: Coefficients(min_length=2, denominator=True)
    coupling_num: Coefficients() | None = None
    coupling_den: Coefficients(denominator=True) | None = None
    length: Q("m", gt=0) | None = None

    @model_validator(mode="after")
    def _coupling_given(self) -> TransferFunctionBeam:
        if self.stiffness is None and self.coupling_num is None:
            raise ValueError("give stiffness (C) or coupling_num/coupling_den")
        if (self.coupling_num is None) != (self.coupling_den is None):
            raise ValueError("coupling_num and coupling_den go together")
        return self


class RigidBeam(Spec):
    """A rigid link: its masses only add inertia to the hub."""

    model: Literal["rigid"]
    length: Q("m", gt=0)
    masses: list[PointMass] = Field(default_factory=list)


Beam = Annotated[LumpedBeam | TransferFunctionBeam | RigidBeam, Field(discriminator="model")]


#: A prismatic joint's quantities, by section and field: their linear SI units (the rotary
#: unit of the field otherwise). A prismatic axis is the rotary arm's equations with
#: positions in m, velocities in m/s, forces in N, masses in kg, viscous friction in N·s/m;
#: a rotary motor through a screw has ``gear_ratio`` in rad/m (2π / lead).
PRISMATIC_UNITS: dict[str, dict[str, str]] = {
    "motor": {
        "inertia": "kg",
        "viscous": "N*s/m",
        "torque_constant": "N/A",
        "gear_ratio": "rad/m",
    },
    "friction": {
        "coulomb": "N",
        "static": "N",
        "stribeck_velocity": "m/s",
        "velocity_tolerance": "m/s",
        "stiffness": "N/m",
        "damping": "N*s/m",
        "bias": "N",
        "push_threshold": "N",
        "push_full": "N",
    },
    "initial": {"motor_angle": "m", "motor_velocity": "m/s"},
    "reference": {"amplitude": "m", "offset": "m", "acceleration": "m/s**2", "snap": "m/s**4"},
}


def prismatic_values(table: object, section: str) -> object:
    """``table`` (a section as read from TOML) with the quantities given as text in a
    prismatic joint's units (:data:`PRISMATIC_UNITS`) turned into SI numbers, so that the
    rotary fields (kg·m², N·m, rad) take them: ``inertia = "2.1 kg"``, ``coulomb = "20 N"``,
    ``motor_angle = "5 mm"``. A value of another kind is a ValueError naming the field."""
    from flexarm.units import UnitError, to_si

    units = PRISMATIC_UNITS[section]
    if not isinstance(table, dict):
        return table
    out = dict(table)
    for k, unit in units.items():
        v = out.get(k)
        if isinstance(v, str):
            try:
                out[k] = to_si(v, unit, field=k)
            except UnitError as exc:
                raise ValueError(
                    f"{section}.{k}: {exc} (a prismatic joint's {k} is in {unit})"
                ) from None
    return out


class SingleLinkArm(Spec):
    """One motor driving one flexible link (FRB Sec. II, VI); or, with ``joint =
    "prismatic"``, one linear axis: a rigid carriage (``beam.model = "rigid"``, its
    ``masses`` added to the moving mass, its ``length`` unused) moved by the drive, positions
    in m, forces in N, masses in kg, viscous N·s/m (:data:`PRISMATIC_UNITS`; the channels
    keep their names: ``motor_angle`` is the position, m; ``motor_velocity`` m/s)."""

    kind: Literal["single_link"] = "single_link"
    joint: Literal["revolute", "prismatic"] = "revolute"
    motor: Motor
    friction: Friction = Friction(model="none")
    beam: Beam

    @model_validator(mode="before")
    @classmethod
    def _linear_units(cls, data: object) -> object:
        if not isinstance(data, dict) or data.get("joint") != "prismatic":
            return data
        data = dict(data)
        for section in ("motor", "friction"):
            if section in data:
                data[section] = prismatic_values(data[section], section)
        data.setdefault("beam", {"model": "rigid", "length": 1.0})
        return data

    @model_validator(mode="after")
    def _rigid_carriage(self) -> SingleLinkArm:
        if self.joint == "prismatic" and self.beam.model != "rigid":
            raise ValueError(
                f'joint = "prismatic": a linear axis carries a rigid carriage; beam.model = '
                f'{self.beam.model!r} is a flexible link: use beam.model = "rigid" (or '
                "leave [arm.beam] out)"
            )
        return self
