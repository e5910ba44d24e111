"""Assumed modes of one flexible link: clamped-mass (or clamped-free) Euler–Bernoulli
eigenfunctions.

A uniform link of length ℓ (m), linear density ρ (kg/m) and flexural rigidity EI (N·m²) is
clamped at its joint (x = 0) and carries at its tip (x = ℓ) the mass M_L (kg) and the
rotary inertia J_L (kg·m², about the tip) of everything distal. Free vibration
w(x, t) = φ(x) cos(ω t) satisfies

    EI φ'''' = ρ ω² φ,                       β⁴ = ρ ω² / EI,
    φ(0) = 0,   φ'(0) = 0,                                    (clamped joint)
    EI φ''(ℓ)  =  ω² J_L φ'(ℓ),                               (moment of the tip inertia)
    EI φ'''(ℓ) = −ω² M_L φ(ℓ),                                (shear of the tip mass)

(the natural boundary terms of L = ½∫ρẇ² + ½M_L ẇ(ℓ)² + ½J_L ẇ'(ℓ)² − ½∫EI w''²).
Clamped-free modes are the case M_L = J_L = 0.

Shape basis. With s = βx and b = βℓ, the classical basis cos, sin, cosh, sinh loses about
e^{b}·ε of relative accuracy (cosh and sinh cancel); we use the equivalent, well-scaled basis

    φ(x) = a₁ cos s + a₂ sin s + a₃ e^{−s} + a₄ e^{s−b},

whose 4×4 boundary matrix A(b) (rows: φ(0), φ'(0)/β, the moment and the shear condition at ℓ,
each row divided by a positive continuous scale) has entries O(1) for any b. With
μ = M_L/(ρℓ) and η = J_L/(ρℓ³) its tip rows are

    [−cos b + b³η sin b,  −sin b − b³η cos b,  e^{−b}(1 + b³η),  1 − b³η]
    [ sin b + bμ cos b,   −cos b + bμ sin b,   e^{−b}(bμ − 1),   1 + bμ ]

Frequency equation: det A(b) = 0, solved by scanning b on a fine grid (geometric near 0, then
steps of 0.005), bracketing sign changes and refining each root with ``scipy.optimize.brentq``;
ω = (b/ℓ)² √(EI/ρ). In the classical basis and with J_L = 0 the determinant reduces to

    1 + cos b cosh b + μ b (cos b sinh b − sin b cosh b) = 0,

and to 1 + cos b cosh b = 0 (b = 1.8751, 4.6941, 7.8548, …) for clamped-free.
The shape coefficients are the null vector of A(b) (smallest right singular vector).

Normalisation (the φ are dimensionless, the modal coordinates δ in metres):

    ∫₀ℓ ρ φ_j² dx + M_L φ_j(ℓ)² + J_L φ_j'(ℓ)² = m = ρℓ      (M_L = J_L = 0 for clamped-free)

and the sign is chosen so that φ_j(ℓ) > 0. The modes are then orthogonal in that inner
product and the modal stiffness is diagonal:

    k_ij = ∫₀ℓ EI φ_i'' φ_j'' dx = ω_j² m δ_ij.

Modal integrals (Gauss–Legendre quadrature, composite, 24 nodes per panel of βΔx ≤ 1):
v_j = ∫ρφ_j dx (kg), w_j = ∫ρxφ_j dx (kg·m), Z_ij = ∫ρφ_iφ_j dx (kg), k_ij (N/m),
and the end values φ_j(ℓ), φ_j'(ℓ) (1/m).

Resolution. Modes with βℓ > ``BETA_L_MAX`` (= 150, about the 48th clamped-free mode) are refused:
their wavelength 2πℓ/βℓ is below ℓ/24, far outside Euler–Bernoulli validity for any real link,
and the fixed quadrature is sized for it. Each computed set is checked a posteriori
(normalisation, orthogonality, k_jj = ω_j² m to 1e-8); a failing check is reported as an error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.polynomial.legendre import leggauss
from scipy.optimize import brentq

from flexarm.errors import FlexarmError  # the one error base (issue #25)

BETA_L_MAX = 150.0
_CHECK_TOL = 1e-8
_NODES_PER_PANEL = 24

ModeType = Literal["clamped_mass", "clamped_free"]


class ModeError(FlexarmError, ValueError):
    """Modes that cannot be computed for the given link (bad data or too many modes)."""


@dataclass(frozen=True)
class LinkModes:
    """The first ``n`` assumed modes of one link (see module docstring). SI units.

    Attributes
    ----------
    beta_l: βℓ of each mode (dimensionless).
    omega: natural frequencies ω_j (rad/s) of the clamped(-mass) beam.
    coeffs: (n, 4) coefficients (a₁..a₄) of φ_j in the basis cos s, sin s, e^{−s}, e^{s−b}.
    tip_value, tip_slope: φ_j(ℓ) (dimensionless), φ_j'(ℓ) (1/m).
    v: ∫ρφ_j dx (kg);  w: ∫ρxφ_j dx (kg·m);  Z: ∫ρφ_iφ_j dx (kg);  K: ∫EIφ_i''φ_j'' dx (N/m).
    """

    length: float
    linear_density: float
    flexural_rigidity: float
    tip_mass: float
    tip_inertia: float
    mode_type: str
    beta_l: np.ndarray
    omega: np.ndarray
    coeffs: np.ndarray
    tip_value: np.ndarray
    tip_slope: np.ndarray
    v: np.ndarray
    w: np.ndarray
    Z: np.ndarray
    K: np.ndarray

    @property
    def n_modes(self) -> int:
        return len(self.beta_l)

    @property
    def mass(self) -> float:
        """Link mass m = ρℓ (kg), the normalisation constant."""
        return self.linear_density * self.length

    @property
    def modal_mass(self) -> np.ndarray:
        """The generalised mass of each mode: ∫ρφ² + M_L φ(ℓ)² + J_L φ'(ℓ)² (= m), kg."""
        ml, jl = self._bc_loads()
        return np.diag(self.Z) + ml * self.tip_value**2 + jl * self.tip_slope**2

    def _bc_loads(self) -> tuple[float, float]:
        if self.mode_type == "clamped_free":
            return 0.0, 0.0
        return self.tip_mass, self.tip_inertia

    def shape(self, x: np.ndarray | float, derivative: int = 0) -> np.ndarray:
        """φ_j^(derivative)(x) for x in [0, ℓ] (m); shape (n_modes, len(x))."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        beta = self.beta_l / self.length
        return (
            np.stack(
                [
                    _shape(c, b, bl, x, derivative)
                    for c, b, bl in zip(self.coeffs, beta, self.beta_l, strict=False)
                ]
            )
            if self.n_modes
            else np.zeros((0, len(x)))
        )


def _shape(c: np.ndarray, beta: float, bl: float, x: np.ndarray, k: int) -> np.ndarray:
    """k-th x-derivative of a₁ cos s + a₂ sin s + a₃ e^{−s} + a₄ e^{s−b}, s = βx."""
    s = beta * x
    cs, sn = np.cos(s), np.sin(s)
    cos_k = (cs, -sn, -cs, sn)[k % 4]
    sin_k = (sn, cs, -sn, -cs)[k % 4]
    return beta**k * (
        c[0] * cos_k + c[1] * sin_k + c[2] * (-1.0) ** k * np.exp(-s) + c[3] * np.exp(s - bl)
    )


def boundary_matrix(b: np.ndarray | float, mu: float, eta: float) -> np.ndarray:
    """The row-scaled 4×4 boundary matrix A(b) (module docstring); shape (..., 4, 4)."""
    b = np.asarray(b, dtype=float)
    c, s, e = np.cos(b), np.sin(b), np.exp(-b)
    one, zero = np.ones_like(b), np.zeros_like(b)
    r3 = 1.0 + b**3 * eta
    r4 = 1.0 + b * mu
    rows = [
        [one, zero, one, e],
        [zero, one, -one, e],
        [
            (-c + b**3 * eta * s) / r3,
            (-s - b**3 * eta * c) / r3,
            e * (1.0 + b**3 * eta) / r3,
            (1.0 - b**3 * eta) / r3,
        ],
        [
            (s + b * mu * c) / r4,
            (-c + b * mu * s) / r4,
            e * (b * mu - 1.0) / r4,
            (1.0 + b * mu) / r4,
        ],
    ]
    return np.moveaxis(np.array(rows), (0, 1), (-2, -1))


def frequency_determinant(b: np.ndarray | float, mu: float, eta: float) -> np.ndarray:
    """det A(b): zero at the βℓ of the modes (module docstring)."""
    return np.linalg.det(boundary_matrix(b, mu, eta))


def _roots(n: int, mu: float, eta: float) -> np.ndarray:
    """The first n positive roots βℓ of det A(b) = 0."""
    if n == 0:
        return np.zeros(0)
    # Each interval (kπ − π/2, kπ + π/2] holds at most a few roots; scan to (n + 1)π.
    hi = (n + 1.5) * math.pi
    grid = np.unique(
        np.concatenate(
            [
                np.geomspace(1e-4, 1.0, 2000),
                np.arange(1.0, hi, 0.005),
            ]
        )
    )
    d = frequency_determinant(grid, mu, eta)
    roots: list[float] = []
    for k in range(len(grid) - 1):
        if d[k] == 0.0:
            roots.append(float(grid[k]))
        elif d[k] * d[k + 1] < 0.0:
            root: Any = brentq(
                lambda b: float(frequency_determinant(b, mu, eta)),
                grid[k],
                grid[k + 1],
                xtol=1e-15,
                rtol=1e-15,  # pyright: ignore[reportArgumentType]  (scipy: rtol is typed from its float64 default)
                maxiter=200,
            )
            roots.append(root)
        if len(roots) == n:
            break
    if len(roots) < n:
        raise ModeError(
            f"found only {len(roots)} of {n} roots of the frequency equation up to "
            f"βℓ = {hi:.1f}; the tip load (M_L/(ρℓ) = {mu:g}, J_L/(ρℓ³) = {eta:g}) "
            "may be degenerate"
        )
    return np.asarray(roots)


def _quadrature(length: float, bl_max: float) -> tuple[np.ndarray, np.ndarray]:
    panels = max(2, int(math.ceil(bl_max)))
    t, wt = leggauss(_NODES_PER_PANEL)
    edges = np.linspace(0.0, length, panels + 1)
    h = np.diff(edges)
    x = (edges[:-1, None] + 0.5 * h[:, None] * (t[None, :] + 1.0)).ravel()
    w = (0.5 * h[:, None] * wt[None, :]).ravel()
    return x, w


def link_modes(
    length: float,
    linear_density: float,
    flexural_rigidity: float,
    n_modes: int,
    *,
    tip_mass: float = 0.0,
    tip_inertia: float = 0.0,
    mode_type: ModeType = "clamped_mass",
) -> LinkModes:
    """The first ``n_modes`` modes of a uniform link (see module docstring).

    Parameters
    ----------
    length: ℓ (m), > 0.
    linear_density: ρ (kg/m), > 0.
    flexural_rigidity: EI (N·m²), > 0.
    n_modes: number of modes (≥ 0).
    tip_mass, tip_inertia: M_L (kg) and J_L (kg·m², about the tip), ≥ 0; used by the
        boundary conditions of ``clamped_mass`` modes (ignored by ``clamped_free``).
    """
    for name, val, unit in (
        ("length", length, "m"),
        ("linear_density", linear_density, "kg/m"),
        ("flexural_rigidity", flexural_rigidity, "N*m**2"),
    ):
        if not (isinstance(val, (int, float, np.floating)) and math.isfinite(val) and val > 0):
            raise ModeError(f"{name} must be a finite number > 0 {unit}; got {val!r}")
    for name, val in (("tip_mass", tip_mass), ("tip_inertia", tip_inertia)):
        if not (math.isfinite(val) and val >= 0):
            raise ModeError(f"{name} must be finite and >= 0; got {val!r}")
    if isinstance(n_modes, bool) or int(n_modes) != n_modes or n_modes < 0:
        raise ModeError(f"n_modes must be a whole number >= 0; got {n_modes!r}")
    if mode_type not in ("clamped_mass", "clamped_free"):
        raise ModeError(f"mode_type must be 'clamped_mass' or 'clamped_free'; got {mode_type!r}")
    n_modes = int(n_modes)
    ell, rho, EI = float(length), float(linear_density), float(flexural_rigidity)
    m = rho * ell
    ml, jl = (float(tip_mass), float(tip_inertia)) if mode_type == "clamped_mass" else (0.0, 0.0)
    mu, eta = ml / (rho * ell), jl / (rho * ell**3)

    # Roots only grow with the mode number and the (n−½)π estimate bounds the n-th clamped-free
    # root from below; refuse early what cannot be resolved.
    if (n_modes - 0.5) * math.pi > BETA_L_MAX + math.pi:
        raise ModeError(
            f"{n_modes} modes asked: mode {n_modes} would have "
            f"βℓ ≈ {(n_modes - 0.5) * math.pi:.0f} "
            f"> {BETA_L_MAX:g}, beyond what is resolved here (wavelength < ℓ/24, outside "
            "Euler–Bernoulli validity); use fewer modes"
        )
    bl = _roots(n_modes, mu, eta)
    if n_modes and bl[-1] > BETA_L_MAX:
        j = int(np.argmax(bl > BETA_L_MAX)) + 1
        raise ModeError(
            f"mode {j} of {n_modes} has βℓ = {bl[j - 1]:.1f} > {BETA_L_MAX:g}: beyond what is "
            "resolved here (wavelength < ℓ/24, outside Euler–Bernoulli validity); use at most "
            f"{j - 1} modes"
        )
    omega = (bl / ell) ** 2 * math.sqrt(EI / rho)

    coeffs = np.zeros((n_modes, 4))
    for j, b in enumerate(bl):
        _, sv, vt = np.linalg.svd(boundary_matrix(b, mu, eta))
        coeffs[j] = vt[-1]
        if sv[-1] > 1e-8 * sv[0]:
            raise ModeError(
                f"mode {j + 1}: boundary matrix not singular at the root "
                f"βℓ = {b:.6f} (σ_min/σ_max = {sv[-1] / sv[0]:.1e})"
            )

    xq, wq = _quadrature(ell, bl[-1] if n_modes else 1.0)
    raw = LinkModes(
        ell,
        rho,
        EI,
        float(tip_mass),
        float(tip_inertia),
        mode_type,
        bl,
        omega,
        coeffs,
        np.zeros(n_modes),
        np.zeros(n_modes),
        np.zeros(n_modes),
        np.zeros(n_modes),
        np.zeros((n_modes, n_modes)),
        np.zeros((n_modes, n_modes)),
    )
    phi = raw.shape(xq)
    phi_l = raw.shape(ell)[:, 0]
    dphi_l = raw.shape(ell, 1)[:, 0]
    gen = (phi**2 * rho) @ wq + ml * phi_l**2 + jl * dphi_l**2
    scale = np.sqrt(m / gen) * np.where(phi_l < 0, -1.0, 1.0)
    coeffs = coeffs * scale[:, None]
    modes = LinkModes(
        ell,
        rho,
        EI,
        float(tip_mass),
        float(tip_inertia),
        mode_type,
        bl,
        omega,
        coeffs,
        phi_l * scale,
        dphi_l * scale,
        np.zeros(n_modes),
        np.zeros(n_modes),
        np.zeros((n_modes, n_modes)),
        np.zeros((n_modes, n_modes)),
    )
    phi = modes.shape(xq)
    d2 = modes.shape(xq, 2)
    Z = (rho * phi * wq) @ phi.T
    K = (EI * d2 * wq) @ d2.T
    modes = LinkModes(
        ell,
        rho,
        EI,
        float(tip_mass),
        float(tip_inertia),
        mode_type,
        bl,
        omega,
        coeffs,
        modes.tip_value,
        modes.tip_slope,
        (rho * phi) @ wq,
        (rho * phi * xq) @ wq,
        0.5 * (Z + Z.T),
        0.5 * (K + K.T),
    )
    _check(modes)
    return modes


def _check(modes: LinkModes) -> None:
    """Orthonormality and k = ω² m: a mode that fails them is not resolved."""
    n = modes.n_modes
    if n == 0:
        return
    m = modes.mass
    ml, jl = modes._bc_loads()
    G = (
        modes.Z
        + ml * np.outer(modes.tip_value, modes.tip_value)
        + jl * np.outer(modes.tip_slope, modes.tip_slope)
    )
    err_g = np.abs(G / m - np.eye(n))
    kdiag = modes.omega**2 * m
    err_k = np.abs(modes.K - np.diag(kdiag)) / np.sqrt(np.outer(kdiag, kdiag))
    bad = np.maximum(err_g.max(axis=1), err_k.max(axis=1)) > _CHECK_TOL
    if bad.any():
        j = int(np.argmax(bad))
        raise ModeError(
            f"mode {j + 1} (βℓ = {modes.beta_l[j]:.2f}) is not resolved: orthonormality error "
            f"{err_g[j].max():.1e}, stiffness error {err_k[j].max():.1e} (> {_CHECK_TOL:g}); "
            "use fewer modes"
        )
