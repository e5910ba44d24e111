"""Specs of a planar multi-link flexible arm in a vertical plane (De Luca & Siciliano).

Values are stored in SI (kg, m, s, rad, N*m); TOML may give them with units ("0.5 m",
"15 N*m**2"). Link i is driven by the motor at joint i, whose hub (mass, inertia) sits
at the base of link i; the payload sits at the tip of the last link. See
:mod:`flexarm.models.multilink` for the model built from these specs by
:func:`flexarm.models.multilink.build_multilink`.
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Field, model_validator

from flexarm.specs.arm import Friction
from flexarm.specs.quantity import Count, Q, Spec


class Link(Spec):
    """One link. ``model = "modes"`` (default): a uniform Euler–Bernoulli beam clamped in its
    hub, described by assumed modes; ``model = "torsional"``: a rigid body on a torsional
    spring at its root (the lumped model of many rig data sheets), with the deflection angle
    α (rad) as its one coordinate.

    Modes: give ``linear_density`` (kg/m) or ``mass`` (kg), not both. ``modes = 0`` makes the
    link rigid. ``mode_type``: ``clamped_mass`` (eigenfunctions with the distal load at the
    tip, the De Luca–Siciliano choice) or ``clamped_free``. Damping: one ``damping_ratio`` ζ
    for every mode (d_j = 2 ζ ω_j m, N·s/m) or ``modal_damping`` listing d_j (N·s/m) per mode.

    Torsional: ``mass`` (kg), ``center_of_mass`` (m from the joint, default ℓ/2), ``inertia``
    J_0 about the joint (kg·m², default that of a uniform rod, mℓ²/3), ``torsional_stiffness``
    K (N·m/rad) and ``torsional_damping`` (N·m·s/rad) or ``damping_ratio`` ζ
    (d = 2ζ√(K J_0)). The link's points move as w(x) = x α (small α), so it is the assumed
    mode φ(x) = x with δ = α: v = ∫ρφ = m c, w = ∫ρxφ = J_0, Z = ∫ρφ² = J_0, k = K,
    φ(ℓ) = ℓ, φ'(ℓ) = 1 (:func:`flexarm.models.multilink.build_multilink`).
    """

    model: Literal["modes", "torsional"] = "modes"
    length: Q("m", gt=0, what="link length")
    linear_density: Q("kg/m", gt=0) | None = None
    mass: Q("kg", gt=0) | None = None
    flexural_rigidity: Q("N*m**2", gt=0, what="flexural rigidity EI") | None = None
    modes: Count(ge=0, what="assumed modes of this link; 0 = rigid") | None = None
    mode_type: Literal["clamped_mass", "clamped_free"] = "clamped_mass"
    damping_ratio: Q("", ge=0, le=1) = 0.0
    modal_damping: list[Q("N*s/m", ge=0)] | None = None
    center_of_mass: Q("m", ge=0) | None = None
    inertia: Q("kg*m**2", gt=0, what="inertia about the joint") | None = None
    torsional_stiffness: Q("N*m/rad", gt=0) | None = None
    torsional_damping: Q("N*m*s/rad", ge=0) | None = None

    @model_validator(mode="after")
    def _consistent(self) -> Link:
        if self.model == "torsional":
            if self.mass is None or self.linear_density is not None:
                raise ValueError("a torsional link needs mass (kg) (not linear_density)")
            if self.torsional_stiffness is None:
                raise ValueError("a torsional link needs torsional_stiffness (N*m/rad)")
            for k in ("flexural_rigidity", "modal_damping"):
                if getattr(self, k) is not None:
                    raise ValueError(
                        f"{k} belongs to model = 'modes' links; a torsional link "
                        "takes torsional_stiffness and torsional_damping"
                    )
            if self.modes not in (None, 1):
                raise ValueError(
                    f"a torsional link has one coordinate (α); modes = {self.modes} is not allowed"
                )
            if self.torsional_damping is not None and self.damping_ratio != 0.0:
                raise ValueError("give either damping_ratio or torsional_damping, not both")
            if self.center_of_mass is not None and self.center_of_mass > self.length:
                raise ValueError(
                    f"center_of_mass = {self.center_of_mass:g} m lies beyond the "
                    f"link length {self.length:g} m"
                )
            return self
        for k in ("center_of_mass", "inertia", "torsional_stiffness", "torsional_damping"):
            if getattr(self, k) is not None:
                raise ValueError(f"{k} belongs to model = 'torsional' links")
        if (self.linear_density is None) == (self.mass is None):
            raise ValueError("give exactly one of linear_density (kg/m) and mass (kg)")
        if self.n_modes > 0 and self.flexural_rigidity is None:
            raise ValueError(
                f"a flexible link (modes = {self.n_modes}) needs flexural_rigidity (N*m**2); "
                "give modes = 0 for a rigid link"
            )
        if self.modal_damping is not None:
            if len(self.modal_damping) != self.n_modes:
                raise ValueError(
                    f"modal_damping has {len(self.modal_damping)} values for {self.n_modes} modes"
                )
            if self.damping_ratio != 0.0:
                raise ValueError("give either damping_ratio or modal_damping, not both")
        return self

    @property
    def n_modes(self) -> int:
        """Coordinates of the link's deflection (1 for a torsional link)."""
        if self.model == "torsional":
            return 1
        return 2 if self.modes is None else int(self.modes)

    @property
    def rho(self) -> float:
        """Mean linear density (kg/m)."""
        return self.linear_density if self.linear_density is not None else self.mass / self.length

    @property
    def link_mass(self) -> float:
        """Mass (kg)."""
        return self.rho * self.length

    @property
    def first_moment(self) -> float:
        """d = ∫ρx dx (kg·m) about the joint."""
        if self.model == "torsional":
            c = self.length / 2 if self.center_of_mass is None else self.center_of_mass
            return self.mass * c
        return self.rho * self.length**2 / 2.0

    @property
    def joint_inertia(self) -> float:
        """J_0 = ∫ρx² dx (kg·m²) about the joint."""
        if self.model == "torsional" and self.inertia is not None:
            return self.inertia
        return self.rho * self.length**3 / 3.0

    def inertia_about(self, r: float) -> float:
        """∫ρ(x + r)² dx: the inertia about a point r (m) before the joint, on the link line."""
        return self.joint_inertia + 2 * r * self.first_moment + r * r * self.link_mass


class TorqueDrive(Spec):
    """An ideal torque source at the joint: u is the joint torque (N·m)."""

    drive: Literal["torque"] = "torque"
    limit: Q("N*m", gt=0) | None = None


class CurrentDrive(Spec):
    """A current amplifier: τ = K_t i at the joint's output (N·m), u = i (A), no back EMF;
    ``torque_constant`` is the torque per ampere at the drive output (gear ratio and
    efficiency included)."""

    drive: Literal["current"]
    torque_constant: Q("N*m/A", gt=0)
    current_limit: Q("A", gt=0) | None = None


class VoltageDrive(Spec):
    """A voltage-driven geared DC servo (FRB eq. 1 with the electrical equation, inductance
    neglected): τ = η_g η_m K_g K_m (v − K_g K_m θ̇) / R at the output shaft, u = v (V).
    ``rotor_inertia`` (at the motor shaft) adds K_g² J_m to the hub inertia."""

    drive: Literal["voltage"]
    motor_constant: Q("V*s/rad", gt=0, what="back-EMF / torque constant K_m")
    armature_resistance: Q("ohm", gt=0)
    gear_ratio: Q("", gt=0) = 1.0
    gear_efficiency: Q("", gt=0, le=1) = 1.0
    motor_efficiency: Q("", gt=0, le=1) = 1.0
    voltage_limit: Q("V", gt=0) | None = None
    rotor_inertia: Q("kg*m**2", ge=0) = 0.0


JointDrive = Annotated[TorqueDrive | CurrentDrive | VoltageDrive, Field(discriminator="drive")]


class Joint(Spec):
    """What acts at one joint: its drive, viscous friction V (N·m·s/rad), joint friction
    (Coulomb with stiction, Stribeck or LuGre, :class:`flexarm.specs.arm.Friction`) and a
    cable spring.

    ``cable_stiffness`` k_c (N·m/rad, default 0): a spring across the joint from its stator
    (the base, or the previous link's tip) to the far end of its link, parallel to the drive
    and to the link's own spring, at rest with the joint at 0: the cables and hoses that run
    along the link to the next joint's motor and sensors. It adds ½ k_c a² to the potential,
    a = θ + φ'(ℓ)ᵀδ the turn from the stator to the link's tip
    (:meth:`flexarm.models.multilink.MultiLinkPlant.cable_angles`). Its torque reaches the
    link's tip, past the strain gauge at the root: at rest the gauge reads the static
    deflection α = −k_c θ / (K + k_c) of a torsional link (K its stiffness), a reading that
    follows the joint angle (../shared/data/two-link-rig: −2.3 mrad per rad on the
    shoulder link; estimated by ``flexarm.identification.time_domain.estimates.cable_springs``)."""

    drive: JointDrive = TorqueDrive()
    viscous: Q("N*m*s/rad", ge=0) = 0.0
    friction: Friction = Friction(model="none")
    cable_stiffness: Q("N*m/rad", ge=0) = 0.0


class Hub(Spec):
    """Hub (motor rotor, clamp) at a joint: mass (kg) and inertia (kg·m²) about the joint
    axis; the inertia turns with the link it drives."""

    mass: Q("kg", ge=0) = 0.0
    inertia: Q("kg*m**2", ge=0) = 0.0


class Payload(Spec):
    """Payload at the tip of the last link: mass (kg) and inertia about the tip (kg·m²);
    it turns with the tip slope of the last link."""

    mass: Q("kg", ge=0) = 0.0
    inertia: Q("kg*m**2", ge=0) = 0.0


class MultiLinkArm(Spec):
    """A planar chain of flexible links in a vertical plane.

    ``hubs[i]`` is at joint i (the base of ``links[i]``); hub 1's mass does not move.
    Gravity: acceleration ``gravity`` (m/s²) along the unit vector ``gravity_direction``
    of the plane (default (0, −1): θ measured from the horizontal x axis, gravity along −y).
    ``torque_limit``: saturation per joint (N·m), none if omitted.
    """

    kind: Literal["multi_link"] = "multi_link"
    links: list[Link] = Field(min_length=1)
    hubs: list[Hub]
    payload: Payload = Payload()
    gravity: Q("m/s**2", ge=0) = 9.81
    gravity_direction: tuple[float, float] = (0.0, -1.0)
    torque_limit: list[Q("N*m", gt=0)] | None = None
    joints: list[Joint] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> MultiLinkArm:
        n = len(self.links)
        if len(self.hubs) != n:
            raise ValueError(f"{n} links need {n} hubs (one per joint); got {len(self.hubs)}")
        if self.joints is not None and len(self.joints) != n:
            raise ValueError(
                f"{n} links need {n} joints (drive and friction of each); got {len(self.joints)}"
            )
        if (
            self.joints is not None
            and self.torque_limit is not None
            and any(j.drive.drive != "torque" for j in self.joints)
        ):
            raise ValueError(
                "torque_limit applies to torque drives; give each joint's "
                "current_limit / voltage_limit in [[arm.joints]] instead"
            )
        gx, gy = self.gravity_direction
        if not (math.isfinite(gx) and math.isfinite(gy)) or math.hypot(gx, gy) == 0.0:
            raise ValueError(
                f"gravity_direction {self.gravity_direction!r} must be a finite non-zero "
                "vector in the plane"
            )
        if self.torque_limit is not None and len(self.torque_limit) != n:
            raise ValueError(f"torque_limit has {len(self.torque_limit)} values for {n} joints")
        return self

    @property
    def joint_specs(self) -> list[Joint]:
        """The joints (ideal torque drives without friction when ``joints`` is omitted; a
        ``torque_limit`` then becomes each drive's limit)."""
        if self.joints is not None:
            return list(self.joints)
        lim = self.torque_limit or [None] * len(self.links)
        return [Joint(drive=TorqueDrive(limit=x)) for x in lim]

    @property
    def gravity_unit(self) -> tuple[float, float]:
        gx, gy = self.gravity_direction
        r = math.hypot(gx, gy)
        return gx / r, gy / r


def benchmark_arm(
    flexural_rigidity: float = 15.0,
    *,
    gravity: float = 9.81,
    modes: int = 2,
    mode_type: Literal["clamped_mass", "clamped_free"] = "clamped_mass",
    damping_ratio: float = 0.0,
) -> MultiLinkArm:
    """De Luca & Siciliano's two-link arm (IEEE SMC 1991 data) in a vertical plane: ℓ = 0.5 m,
    ρ = 0.2 kg/m, hub 2 of 1 kg, hub inertias 0.1 kg·m², payload 0.1 kg / 0.0005 kg·m².
    The project's gravity benchmark uses EI = 15 N·m² (the 1991 paper had 1 N·m²)."""
    link = Link(
        length=0.5,
        linear_density=0.2,
        flexural_rigidity=flexural_rigidity,
        modes=modes,
        mode_type=mode_type,
        damping_ratio=damping_ratio,
    )
    return MultiLinkArm(
        links=[link, link],
        hubs=[Hub(mass=0.0, inertia=0.1), Hub(mass=1.0, inertia=0.1)],
        payload=Payload(mass=0.1, inertia=0.0005),
        gravity=gravity,
    )


class JointPDController(Spec):
    """A sampled PD per joint on the measured joint angles, with constant gravity
    compensation (DLS law (8) sampled) and optionally Feliu's Coulomb friction
    compensation per joint (FRB Sec. III-B), :class:`flexarm.control.joint_pd.JointPD`:

        τ_j = K_P,j (θ_d,j − θ_j) − K_D,j v̂_j + g_j(θ_d, δ̄_d) + C_f,j σ_j,   u_j = τ_j / k_u,j

    v̂ the backward difference of the measured angle, σ_j the friction sign (moving: sgn v̂;
    at rest: the sign of the PD torque beyond ``rest_deadband``), k_u the drive's torque per
    unit command. ``target`` θ_d (rad per joint); ``measured``: the channels of the joint
    angles (default ``theta_i``)."""

    type: Literal["joint_pd"]
    kp: list[Q("N*m/rad", gt=0)]
    kd: list[Q("N*m*s/rad", ge=0)]
    target: list[Q("rad")]
    gravity_compensation: bool = True
    friction_compensation: list[Q("N*m", ge=0)] | None = None
    velocity_deadband: Q("rad/s", ge=0) = 0.0
    rest_deadband: Q("N*m", ge=0) = 0.0
    measured: list[str] | None = None

    @model_validator(mode="after")
    def _sizes(self) -> JointPDController:
        n = len(self.target)
        for name in ("kp", "kd", "friction_compensation", "measured"):
            v = getattr(self, name)
            if v is not None and len(v) != n:
                raise ValueError(f"{name} has {len(v)} entries; target has {n} (one per joint)")
        return self
