"""Coulomb friction from pairs of sinusoidal experiments at ω0 and 3ω0 (FRB Sec. II-B).

Model (FRB eq. (1), printed with K·ï where K·i is meant), divided by K so that every term
is a current (A):

    i = G⁻¹ θm + C_f sign(θ̇m),        G(s) = θm/i of the linear part (beam coupling included),

with C_f the Coulomb level *as a current* (the torque is K·C_f).  Phasors follow
x(t) = Re{X e^{jωt}} (see :mod:`flexarm.identification.frequency_domain.harmonics`).

Square wave.  For θm = a sin(ω0 t + φ), i.e. ∠θm(ω0) = φ − π/2, sign(θ̇m) = sign(cos(ω0t+φ))
= (4/π) Σ_{n odd} (−1)^{(n−1)/2} cos(n(ω0t + φ))/n, so its harmonic n has the phasor

    S_n = (4/(nπ)) e^{j(n∠θm(ω0) + π/2)}    (n odd; nφ + (n−1)π/2 = n∠θm + π/2 mod 2π).

(FRB eq. (2) writes the same series with cosine amplitudes 2C_f(1 − (−1)^i)/(iπ) and a
particular time origin.)

Equations used (C_f in A):

* (3)  i(ω0)  = G⁻¹(ω0) θm(ω0) + C_f S_1,              S_1 = (4/π) e^{j(∠θm(ω0) + π/2)}.
* (4)  i(3ω0) = G⁻¹(3ω0) θm(3ω0) + (4C_f/(3π)) e^{j(3∠θm(ω0) + π/2)}
       — harmonics 3 of the ω0 experiment.  **Corrected**: the paper prints the phase as
       ∠θm(ω0) + π/2; with an arbitrary time origin the third harmonic of the square wave
       has the phase 3∠θm(ω0) + π/2 (derivation above).
* (5)  i'(3ω0) = G⁻¹(3ω0) θ'm(3ω0) + (4C_f/π) e^{j(∠θ'm(3ω0) + π/2)}
       — fundamentals of the 3ω0 ("partner") experiment.
* (6)  cost(C_f) = (ln|C_f'/C_f|)² + (∠C_f')², where, as in FRB Fig. 2, for a trial C_f
       G'⁻¹(3ω0) is solved from (5) and C_f' from (4) with that G'.

C_f is found by a direct search on ln C_f: a log-spaced grid over eight decades below to one
above the current amplitude, then bounded Brent (``scipy.optimize.minimize_scalar``) around
the best grid point.  Each ω0 with a partner within ``tol`` (1 %) of 3ω0 gives one
estimate; the result is their mean (FRB: "take the average"), with the spread.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from flexarm.identification.frequency_domain.harmonics import HarmonicAnalysis, _warn
from flexarm.identification.frequency_domain.harmonics import (
    ideal_friction_phasor as square_wave_phasor,  # eq. 2
)

# Eq. (6) where C_f' vanishes (ln 0): (ln 1e-300)² ≈ 5e5, so 1e6 is worse than any real
# cost yet finite, which Brent's parabolic steps need.
_INFEASIBLE_COST = 1e6

#: Relative tolerance for matching a 3ω0 partner experiment.
PARTNER_TOL = 0.01


@dataclass(frozen=True)
class PairPhasors:
    """The five phasors eqs. (4)-(5) need (SI: rad and A).

    ``theta1``, ``theta3``, ``current3``: harmonics 1, 3, 3 of θm, θm, i in the ω0
    experiment; ``theta1_partner``, ``current1_partner``: fundamentals of θm and i in the
    3ω0 experiment.
    """

    theta1: complex
    theta3: complex
    current3: complex
    theta1_partner: complex
    current1_partner: complex
    shape3: complex | None = None  # harmonic 3 of the friction shape, ω0 experiment
    shape1_partner: complex | None = None  # fundamental of the shape, 3ω0 experiment

    @classmethod
    def from_analyses(cls, base: HarmonicAnalysis, partner: HarmonicAnalysis) -> PairPhasors:
        return cls(
            base.phasor("motor_angle", 1),
            base.phasor("motor_angle", 3),
            base.phasor("current", 3),
            partner.phasor("motor_angle", 1),
            partner.phasor("current", 1),
            base.friction(3),
            partner.friction(1),
        )

    def g_inv_3w0(self, cf: float) -> complex:
        """G'⁻¹(3ω0) (A/rad) from eq. (5) for a trial C_f (A)."""
        s1 = (
            square_wave_phasor(self.theta1_partner, 1)
            if self.shape1_partner is None
            else self.shape1_partner
        )
        return (self.current1_partner - cf * s1) / self.theta1_partner

    def cf_prime(self, cf: float) -> complex:
        """C_f' (complex, A) from eq. (4) (corrected phase) with G' from eq. (5)."""
        lin = self.g_inv_3w0(cf) * self.theta3
        s3 = square_wave_phasor(self.theta1, 3) if self.shape3 is None else self.shape3
        return (self.current3 - lin) / s3

    def cost(self, cf: float) -> float:
        """FRB eq. (6): (ln|C_f'/C_f|)² + (∠C_f')²."""
        r = self.cf_prime(cf)
        if not (r != 0 and np.isfinite(r)):  # ln 0: the search gets a large finite cost
            return _INFEASIBLE_COST
        return math.log(abs(r) / cf) ** 2 + float(np.angle(r)) ** 2


@dataclass(frozen=True)
class PairEstimate:
    """One C_f estimate (A) from the experiments at ``omega`` and ``partner_omega`` (rad/s)."""

    omega: float
    partner_omega: float
    coulomb_current: float
    cost: float
    cf_prime: complex
    g_3w0: complex
    name: str = ""
    partner_name: str = ""
    at_search_bound: bool = False


def estimate_pair(
    ph: PairPhasors,
    *,
    scale: float | None = None,
    omega: float = math.nan,
    partner_omega: float = math.nan,
    name: str = "",
    partner_name: str = "",
) -> PairEstimate:
    """Minimise eq. (6) over C_f > 0 (direct search on ln C_f, see module docstring).

    ``scale`` (A) centres the search; by default the larger fundamental current amplitude
    of the pair's experiments, or the third harmonic's if larger.
    """
    if scale is None:
        scale = max(abs(ph.current1_partner), abs(ph.current3) * 3 * math.pi / 4, 1e-300)
    lo, hi = math.log(scale) - 8 * math.log(10), math.log(scale) + math.log(10)
    grid = np.linspace(lo, hi, 241)
    costs = np.array([ph.cost(math.exp(u)) for u in grid])
    k = int(np.argmin(costs))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    res: Any = minimize_scalar(
        lambda u: ph.cost(math.exp(u)),
        bounds=(a, b),
        method="bounded",
        options={"xatol": 1e-12, "maxiter": 500},
    )
    if not res.success:
        warnings.warn(
            f"Coulomb estimate {name or omega!s}: bounded Brent search stopped without "
            f"converging ({res.message}); the best grid point is used. Check the pair's "
            "phasors (a current amplitude near zero, or no 3ω0 response)",
            RuntimeWarning,
            stacklevel=2,
        )
    u = float(res.x) if res.success and res.fun <= costs[k] else float(grid[k])
    cf = math.exp(u)
    return PairEstimate(
        omega=omega,
        partner_omega=partner_omega,
        coulomb_current=cf,
        cost=ph.cost(cf),
        cf_prime=ph.cf_prime(cf),
        g_3w0=1.0 / ph.g_inv_3w0(cf),
        name=name,
        partner_name=partner_name,
        at_search_bound=k in (0, len(grid) - 1),
    )


@dataclass
class CoulombEstimate:
    """Coulomb friction as a current (A): mean over the ω0 with a 3ω0 partner.

    ``std``: population standard deviation of the per-pair values; ``max_rel_dev``:
    max |C_f,k − mean|/mean.  ``coulomb_current`` is None when no pair was found.
    """

    coulomb_current: float | None
    pairs: list[PairEstimate]
    std: float | None
    max_rel_dev: float | None
    unpaired: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    @property
    def values(self) -> np.ndarray:
        return np.array([p.coulomb_current for p in self.pairs])


def find_partners(
    analyses: Sequence[HarmonicAnalysis], tol: float = PARTNER_TOL
) -> list[tuple[int, int | None]]:
    """For each experiment k, the index of its 3ω0 partner (closest within ``tol``) or None."""
    w = np.array([a.omega0 for a in analyses])
    out = []
    for k, wk in enumerate(w):
        dev = np.abs(w - 3 * wk) / (3 * wk)
        dev[k] = np.inf
        j = int(np.argmin(dev)) if len(w) > 1 else None
        out.append((k, j if j is not None and dev[j] <= tol else None))
    return out


def estimate_coulomb(
    analyses: Sequence[HarmonicAnalysis], *, tol: float = PARTNER_TOL
) -> CoulombEstimate:
    """C_f (A) from every ω0/3ω0 pair among ``analyses`` (eqs. (4)-(6), module docstring).

    An experiment that has no 3ω0 partner and is not itself the partner of another one
    is reported by a warning naming its file and frequency; it is still usable for the
    frequency response.
    """
    pairs = find_partners(analyses, tol)
    partners = {j for _, j in pairs if j is not None}
    est: list[PairEstimate] = []
    unpaired: list[str] = []
    msgs: list[str] = []
    for k, j in pairs:
        a = analyses[k]
        if j is None:
            if k not in partners:
                unpaired.append(a.name)
                _warn(
                    f"{a.name}: no 3ω0 partner for ω0 = {a.omega0:.6g} rad/s (no experiment "
                    f"within {100 * tol:g} % of {3 * a.omega0:.6g} rad/s); this frequency "
                    "is not used to estimate the Coulomb friction",
                    msgs,
                )
            continue
        b = analyses[j]
        e = estimate_pair(
            PairPhasors.from_analyses(a, b),
            omega=a.omega0,
            partner_omega=b.omega0,
            name=a.name,
            partner_name=b.name,
        )
        if e.at_search_bound:
            _warn(
                f"{a.name}: the Coulomb estimate for ω0 = {a.omega0:.6g} rad/s lies at the "
                f"edge of the search range ({e.coulomb_current:.3g} A); the pair's data do "
                "not fit eqs. (4)-(5)",
                msgs,
            )
        est.append(e)
    if not est:
        if analyses:
            _warn(
                "no ω0/3ω0 pair of experiments: the Coulomb friction cannot be estimated "
                f"(frequencies: {', '.join(f'{a.omega0:.4g}' for a in analyses)} rad/s)",
                msgs,
            )
        return CoulombEstimate(None, [], None, None, unpaired, msgs)
    v = np.array([e.coulomb_current for e in est])
    mean = float(v.mean())
    return CoulombEstimate(
        mean, est, float(v.std()), float(np.max(np.abs(v - mean)) / mean), unpaired, msgs
    )
