"""The physical parameter vector of a bench fit: names, units, bounds, scales, and its
mapping to the model numbers of :mod:`flexarm.sim.rig_loop` and to a
scenario.

Estimated (SI): hub inertia J (kg·m², equivalent at the output shaft), hub-clamped link
frequency ω_c (rad/s), link inertia J_l (kg·m²; stiffness C = J_l ω_c²), link damping
ratio ζ, the tip sensor's calibration gain |g| (m per m of tip deflection) and sign, and
per recording session the viscous B (N·m·s/rad), Coulomb F_c (N·m), breakaway excess
F_s − F_c (N·m) and bias torque (N·m) at the hub; integer sensor delays (samples) of the
hub angle and tip deflection channels.

Every torque-unit parameter scales with the drive gain k_u = η_g η_m K_g K_m / R the user
gives (data-sheet efficiencies): the closed loop depends on J/k_u, C/k_u, ... only, so
wrong efficiencies give proportionally wrong J, J_l, C, B, F; ω_c, ζ, g are unaffected.

A continuous parameter p in [lo, hi] is searched as u in [0, 1]:
``log``: p = lo (hi/lo)^u; ``lin``: p = lo + (hi − lo) u; ``loglin`` (parameters that may be
0): p = lo + (hi − lo) (e^{a u} − 1)/(e^a − 1), a = ln 1000 (three decades plus zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

A_LOGLIN = math.log(1000.0)


@dataclass(frozen=True)
class ParamDef:
    """One continuous parameter: name, unit, bounds (SI), scale, session index or None."""

    name: str
    unit: str
    lo: float
    hi: float
    scale: str = "log"
    session: int | None = None
    doc: str = ""

    def to_phys(self, u):
        u = np.asarray(u, float)
        if self.scale == "log":
            return self.lo * (self.hi / self.lo) ** u
        if self.scale == "lin":
            return self.lo + (self.hi - self.lo) * u
        return self.lo + (self.hi - self.lo) * np.expm1(A_LOGLIN * u) / np.expm1(A_LOGLIN)

    def to_unit(self, p):
        p = np.asarray(p, float)
        if self.scale == "log":
            return np.log(p / self.lo) / np.log(self.hi / self.lo)
        if self.scale == "lin":
            return (p - self.lo) / (self.hi - self.lo)
        return np.log1p((p - self.lo) / (self.hi - self.lo) * np.expm1(A_LOGLIN)) / A_LOGLIN

    def dphys_du(self, u):
        """Derivative of the physical value with respect to the unit coordinate."""
        u = np.asarray(u, float)
        if self.scale == "log":
            return self.to_phys(u) * math.log(self.hi / self.lo)
        if self.scale == "lin":
            return np.full_like(u, self.hi - self.lo)
        return (self.hi - self.lo) * A_LOGLIN * np.exp(A_LOGLIN * u) / np.expm1(A_LOGLIN)


MECHANICS = ("hub_inertia", "link_frequency", "link_inertia", "link_damping", "tip_gain")
FRICTION = ("viscous", "coulomb", "static_excess", "bias")
UNITS = {
    "hub_inertia": "kg*m**2",
    "link_frequency": "rad/s",
    "link_inertia": "kg*m**2",
    "link_damping": "",
    "tip_gain": "m/m",
    "viscous": "N*m*s/rad",
    "coulomb": "N*m",
    "static_excess": "N*m",
    "bias": "N*m",
}
DOCS = {
    "hub_inertia": "J: hub inertia at the output shaft",
    "link_frequency": "omega_c: link frequency with the hub held (clamped)",
    "link_inertia": "J_l = m L^2: link inertia about the hub",
    "link_damping": "zeta: damping ratio of the link mode",
    "tip_gain": "|g|: strain-gauge calibration, measured m per m of tip deflection",
    "viscous": "B: viscous friction at the hub",
    "coulomb": "F_c: Coulomb friction",
    "static_excess": "F_s - F_c: breakaway above the Coulomb level",
    "bias": "constant bias torque at the hub",
}


@dataclass
class ParamSpace:
    """Continuous parameters (searched in unit coordinates) and the discrete ones
    (sensor delays in samples, tip-gain sign) with their allowed ranges."""

    defs: list[ParamDef]
    n_sessions: int
    max_delay: int = 5
    sign: int | None = None  # fixed sign of the tip gain, or None to search it
    friction: bool = True
    fixed_delays: tuple[int | None, int | None] = (None, None)
    extras: dict = field(default_factory=dict)
    #: search range (lo, hi) of each free delay (hub, tip), samples; None: 0 ... max_delay
    delay_ranges: tuple[tuple[int, int] | None, tuple[int, int] | None] = (None, None)
    #: priors: index into :attr:`defs` → (mean p̄ in SI, relative std σ_p), as eq. (2) of
    #: :mod:`~flexarm.identification.time_domain.general`: r_p = (ln p − ln p̄) / σ_p
    priors: dict[int, tuple[float, float]] = field(default_factory=dict)
    #: each session's tip-gauge sign relative to session 0's (+1 / −1; empty: all +1): a
    #: gauge whose wiring or calibration changed between sessions
    #: (:func:`~flexarm.identification.time_domain.guesses.session_signs`); the gauge's size
    #: |g| is shared, its sign g / |g| for session s is ``sign · session_signs[s]``
    session_signs: tuple[int, ...] = ()

    @property
    def rigid(self) -> bool:
        """No link parameters: the arm is fitted as a rigid hub (logs without a tip
        channel)."""
        return not any(d.name == "link_frequency" for d in self.defs)

    @property
    def names(self) -> list[str]:
        return [
            d.name if d.session is None or self.n_sessions == 1 else f"{d.name}[{d.session}]"
            for d in self.defs
        ]

    def index(self, name: str, session: int | None = None) -> int:
        for i, d in enumerate(self.defs):
            if d.name == name and (d.session is None or d.session == (session or 0)):
                return i
        raise KeyError(name)

    @property
    def n_cont(self) -> int:
        return len(self.defs)

    def discrete_bounds(self) -> list[tuple[int, int]]:
        """Bounds of the integer DE coordinates: angle delay, tip delay, sign (0/1)."""
        b = []
        for fixed, rng in zip(self.fixed_delays, self.delay_ranges, strict=True):
            if fixed is not None:
                b.append((fixed, fixed))
            else:
                lo, hi = rng if rng is not None else (0, self.max_delay)
                b.append((max(int(lo), 0), min(int(hi), self.max_delay)))
        b.append((0, 1) if self.sign is None else ((self.sign + 1) // 2,) * 2)
        return b

    def physical(self, u: np.ndarray) -> dict[str, np.ndarray]:
        """Unit coordinates (..., n_cont) → dict of physical values keyed by :attr:`names`."""
        return {
            n: d.to_phys(u[..., i])
            for i, (n, d) in enumerate(zip(self.names, self.defs, strict=True))
        }

    def session_values(self, u: np.ndarray, name: str) -> np.ndarray:
        """(..., n_sessions) physical values of a per-session parameter."""
        return np.stack(
            [
                self.defs[self.index(name, s)].to_phys(u[..., self.index(name, s)])
                for s in range(self.n_sessions)
            ],
            axis=-1,
        )

    def prior_residuals(self, u: np.ndarray) -> np.ndarray:
        """(..., n_priors) r_p = (ln p − ln p̄) / σ_p of :attr:`priors` (eq. (2) of the
        general engine; p floored at 1e-12 p̄ where a bound reaches 0)."""
        u = np.asarray(u, float)
        cols = [
            (np.log(np.maximum(self.defs[i].to_phys(u[..., i]), 1e-12 * m)) - math.log(m)) / s
            for i, (m, s) in sorted(self.priors.items())
        ]
        return np.stack(cols, -1) if cols else np.zeros((*u.shape[:-1], 0))

    def value(self, u: np.ndarray, name: str) -> np.ndarray:
        i = self.index(name)
        return self.defs[i].to_phys(u[..., i])


def derived(p: dict[str, float], length: float) -> dict[str, float]:
    """Stiffness, frequencies and lumped-beam numbers from the fitted parameters."""
    if "link_frequency" not in p:  # a rigid arm
        return {}
    J, wc, Jl = p["hub_inertia"], p["link_frequency"], p["link_inertia"]
    C = Jl * wc**2
    return {
        "link_stiffness": C,
        "link_frequency_free_hub": wc * math.sqrt(1.0 + Jl / J),
        "tip_mass": Jl / length**2,
        "flexural_rigidity": C * length / 3.0,
    }
