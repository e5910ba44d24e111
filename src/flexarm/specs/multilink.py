"""Specs of a planar multi-link flexible arm in a vertical plane (De Luca & Siciliano).

Values are stored in SI (kg, m, s, rad, N*m); TOML may give them with units ("0.5 m",
"15 N*m**2"). Link i is driven by the motor at joint i, whose hub (mass, inertia) sits
at the base of link i; the payload sits at the tip of the last link. See
:mod:`flexarm.models.multilink` for the model built from these specs by
:func:`flexarm.models.multilink.build_multilink`.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, model_validator

from flexarm.specs.quantity import Count, Q, Spec


class Link(Spec):
    """One uniform link: Euler–Bernoulli beam clamped in its hub.

    Give ``linear_density`` (kg/m) or ``mass`` (kg), not both. ``modes = 0`` makes the link
    rigid. ``mode_type``: ``clamped_mass`` (eigenfunctions with the distal load at the tip,
    the De Luca–Siciliano choice) or ``clamped_free``. Damping: one ``damping_ratio`` ζ for
    every mode (d_j = 2 ζ ω_j m, N·s/m) or ``modal_damping`` listing d_j (N·s/m) per mode.
    """

    length: Q("m", gt=0, what="link length")
    linear_density: Q("kg/m", gt=0) | None = None
    mass: Q("kg", gt=0) | None = None
    flexural_rigidity: Q("N*m**2", gt=0, what="flexural rigidity EI") | None = None
    modes: Count(ge=0, what="assumed modes of this link; 0 = rigid") = 2
    mode_type: Literal["clamped_mass", "clamped_free"] = "clamped_mass"
    damping_ratio: Q("", ge=0, le=1) = 0.0
    modal_damping: list[Q("N*s/m", ge=0)] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> "Link":
        if (self.linear_density is None) == (self.mass is None):
            raise ValueError("give exactly one of linear_density (kg/m) and mass (kg)")
        if self.modes > 0 and self.flexural_rigidity is None:
            raise ValueError(
                f"a flexible link (modes = {self.modes}) needs flexural_rigidity (N*m**2); "
                "give modes = 0 for a rigid link"
            )
        if self.modal_damping is not None:
            if len(self.modal_damping) != self.modes:
                raise ValueError(
                    f"modal_damping has {len(self.modal_damping)} values for "
                    f"{self.modes} modes"
                )
            if self.damping_ratio != 0.0:
                raise ValueError("give either damping_ratio or modal_damping, not both")
        return self

    @property
    def rho(self) -> float:
        """Linear density ρ (kg/m)."""
        return self.linear_density if self.linear_density is not None else self.mass / self.length

    @property
    def link_mass(self) -> float:
        """Mass ρℓ (kg)."""
        return self.rho * self.length


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

    @model_validator(mode="after")
    def _consistent(self) -> "MultiLinkArm":
        n = len(self.links)
        if len(self.hubs) != n:
            raise ValueError(f"{n} links need {n} hubs (one per joint); got {len(self.hubs)}")
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
    def gravity_unit(self) -> tuple[float, float]:
        gx, gy = self.gravity_direction
        r = math.hypot(gx, gy)
        return gx / r, gy / r


def benchmark_arm(flexural_rigidity: float = 15.0, *, gravity: float = 9.81,
                  modes: int = 2, mode_type: str = "clamped_mass",
                  damping_ratio: float = 0.0) -> MultiLinkArm:
    """De Luca & Siciliano's two-link arm (IEEE SMC 1991 data) in a vertical plane: ℓ = 0.5 m,
    ρ = 0.2 kg/m, hub 2 of 1 kg, hub inertias 0.1 kg·m², payload 0.1 kg / 0.0005 kg·m².
    The project's gravity benchmark uses EI = 15 N·m² (the 1991 paper had 1 N·m²)."""
    link = Link(length=0.5, linear_density=0.2, flexural_rigidity=flexural_rigidity,
                modes=modes, mode_type=mode_type, damping_ratio=damping_ratio)
    return MultiLinkArm(
        links=[link, link],
        hubs=[Hub(mass=0.0, inertia=0.1), Hub(mass=1.0, inertia=0.1)],
        payload=Payload(mass=0.1, inertia=0.0005),
        gravity=gravity,
    )
