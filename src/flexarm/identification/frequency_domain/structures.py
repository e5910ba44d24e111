"""Physical structures fitted to frequency-response data: one fitter, several structures.

A :class:`Structure` is

* ``parameters``: the names, in fit order; those in ``log`` are positive and fitted as
  logarithms, the others are non-negative (bounded at 0) and fitted linearly with a scale
  (``scale(p0, ω)``);
* ``response(p, ω)``: the model's FRF per output name (``motor_angle``, ``load_angle``,
  ``tip_angle``, ``tip_deflection`` per unit of the input, or a ratio of two outputs such
  as ``"tip_angle/motor_angle"``);
* ``guess(ω, data, given)``: start values from the measured FRF (one dict, or a list of
  candidates of which the one with the lowest cost is used);
* ``derived(p)``: quantities computed from the parameters (resonance, damping ratio, ...),
  reported with standard deviations by the delta method;
* ``given``: known constants the user passes (data-sheet values), with their meaning.

:func:`fit_structure` fits any structure to the FRFs of any subset of its outputs with the
maximum-likelihood cost of :func:`~flexarm.identification.frequency_domain.tfest.tfest`,

    V(θ) = Σ_outputs Σ_k |Ĝ_o(jω_k, θ) − G_o,k|² / σ²_o,k,

σ the FRF's standard deviation (noise or the BLA's total); without σ, relative weights
1/|G| and the covariance scaled by the residual variance. The χ² check, the covariance
½(JᵀJ)⁻¹ and the inflated standard deviations are those of ``tfest``.

Structures (``STRUCTURES``):

``two-mass``
    the two-mass drive (motor and load inertia, shaft stiffness and damping, viscous
    friction per side, delay) per unit of the input's torque constant: :func:`two_mass_response`.
``frb-single-mass``
    the current-driven arm of FRB with a massless beam and a pinned tip mass, FRB eqs.
    (1), (12), (13): hub inertia J, viscous V, link stiffness C, tip inertia J_t, the tip's
    viscous damping d_t, delay; the motor constant K given (:func:`frb_single_mass_response`).
``voltage-servo``
    the geared voltage-driven DC servo turning a flexible link (the rotary rig): J_eq,
    B_eq, link stiffness, link inertia, link damping, delay; K_m, R_m, K_g, η given
    (:func:`voltage_servo_response`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from flexarm.identification.frequency_domain.tfest import TFEstError, cost_verdict, inflate_std


@dataclass(frozen=True)
class Structure:
    """A physical model structure for :func:`fit_structure` (module docstring)."""

    name: str
    parameters: tuple[str, ...]
    log: frozenset[str]
    outputs: tuple[str, ...]
    response: Callable[[dict, np.ndarray], dict[str, np.ndarray]]
    guess: Callable[[np.ndarray, dict, dict], dict | list[dict]]  # one start or candidates
    scale: Callable[[dict, np.ndarray], dict]
    derived: Callable[[dict], dict] = lambda p: {}
    given: dict[str, str] = field(default_factory=dict)  # name → meaning and unit
    optional_given: dict[str, str] = field(default_factory=dict)
    units: str = ""


def _pair(cubic) -> tuple[float, float]:
    """Frequency (Hz) and damping ratio −Re p/|p| of the complex pole pair among the roots
    of ``cubic`` (descending coefficients); (|p|/2π, 1) when all roots are real."""
    roots = np.roots(cubic)
    p = roots[np.argmax(np.abs(roots.imag))]
    if abs(p.imag) == 0:
        return float(abs(p) / (2 * np.pi)), 1.0
    return float(abs(p) / (2 * np.pi)), float(-p.real / abs(p))


def _hub_link_starts(
    structure: str, omega, data, gain: float, damping: float, link: tuple[str, str], unit: str
) -> list[dict]:
    """Start candidates of a hub + link structure (one per inertia ratio r of
    :func:`_rigid_and_modes`): hub inertia J/(1+r), link inertia J r/(1+r) and stiffness
    ω_a² J r/(1+r), link damping at ζ = 0.02, no hub viscous friction, no delay; ``link``
    the structure's names of the link inertia and damping."""
    if data.get("motor_angle") is None:
        raise TFEstError(
            f"{structure}: the start values need the motor_angle FRF ({unit}); "
            "give it, or give every parameter in 'initial'"
        )
    J, wa, ratios = _rigid_and_modes(omega, data["motor_angle"], gain=gain, damping=damping)
    return [
        {
            "hub_inertia": J / (1 + r),
            "hub_viscous": 0.0,
            "link_stiffness": wa**2 * J * r / (1 + r),
            link[0]: J * r / (1 + r),
            link[1]: 2 * 0.02 * wa * J * r / (1 + r),
            "delay_s": 0.0,
        }
        for r in ratios
    ]


def _rigid_and_modes(omega, G, gain=1.0, damping=0.0):
    """Start values shared by the hub-driven structures, from the hub angle FRF G: the total
    inertia J_tot from the lowest lines (gain/(jω G) ≈ J_tot jω + damping below the modes),
    the antiresonance ω_a (the link's own frequency) at the minimum of
    |G| · |J_tot (jω)² + damping jω| / gain, and candidate link/hub inertia ratios: the one
    from the resonance (the maximum above ω_a, (ω_r/ω_a)² − 1) and a grid 0.1–10, since a
    resonance damped by back-EMF or viscous friction shows no clear peak. Returns
    (J_tot, ω_a, ratios)."""
    s = 1j * omega
    low = slice(0, max(3, len(omega) // 20))
    Y = gain / (s * G)
    J = float(np.median(Y[low].imag / omega[low]))
    if not np.isfinite(J) or J <= 0:
        J = float(np.median(gain / (np.abs(G[low]) * omega[low] ** 2)))
    n = np.abs(G) * np.abs(J * s**2 + damping * s) / gain
    ia = int(np.argmin(n))
    ir = ia + int(np.argmax(n[ia:])) if ia < len(n) - 1 else ia
    ratios = list(np.geomspace(0.1, 10, 9))
    if omega[ir] > 1.01 * omega[ia]:
        ratios.insert(0, (omega[ir] / omega[ia]) ** 2 - 1)
    return J, float(omega[ia]), ratios


# --- the two-mass drive ---------------------------------------------------------------

#: Parameters of the two-mass structure, in fit order (per unit of the input's torque
#: constant: inertias in A·s²/rad when the input is a current in A and the outputs in rad).
TWO_MASS = (
    "total_inertia",
    "inertia_ratio",
    "resonance_hz",
    "shaft_damping",
    "motor_viscous",
    "load_viscous",
    "delay_s",
)


def two_mass_response(p: dict, omega) -> tuple[np.ndarray, np.ndarray]:
    """Motor and load angle per unit input of the two-mass drive (viscous friction per side):

        J_m s² θm = u − (c s + k)(θm − θl) − d_m s θm,   J_l s² θl = (c s + k)(θm − θl) − d_l s θl

    with J_m = J/(1+r), J_l = J r/(1+r), k = ω_r² J_m J_l / J, c = 2 ζ_c k / ω_r (ζ_c the
    shaft's own damping ratio, ``shaft_damping``), times e^{−sτ}:
    G_m = (J_l s² + (c+d_l) s + k)/Δ, G_l = (c s + k)/Δ,
    Δ = (J_m s² + (c+d_m) s + k)(J_l s² + (c+d_l) s + k) − (c s + k)².
    """
    s = 1j * np.asarray(omega, float)
    J, r = p["total_inertia"], p["inertia_ratio"]
    wr = 2 * np.pi * p["resonance_hz"]
    Jm, Jl = J / (1 + r), J * r / (1 + r)
    k = wr**2 * Jm * Jl / J
    c = 2 * p["shaft_damping"] * k / wr
    dm, dl = p["motor_viscous"], p["load_viscous"]
    A = Jm * s**2 + (c + dm) * s + k
    B = Jl * s**2 + (c + dl) * s + k
    C = c * s + k
    D = A * B - C**2
    e = np.exp(-s * p["delay_s"])
    return B / D * e, C / D * e


def two_mass_derived(p: dict) -> dict:
    """Antiresonance, inertias, stiffness, and the damping ratio of the resonant pole pair
    (shaft and viscous damping together: −Re p/|p| of the complex roots of Δ/s)."""
    r = p["inertia_ratio"]
    J = p["total_inertia"]
    Jm, Jl = J / (1 + r), J * r / (1 + r)
    wr = 2 * np.pi * p["resonance_hz"]
    k = wr**2 * Jm * Jl / J
    c = 2 * p["shaft_damping"] * k / wr
    dm, dl = p["motor_viscous"], p["load_viscous"]
    cubic = [
        Jm * Jl,
        Jm * (c + dl) + Jl * (c + dm),
        k * J + (c + dm) * (c + dl) - c**2,
        k * (dm + dl),
    ]
    roots = np.roots(cubic)
    pair = roots[np.argmax(np.abs(roots.imag))]
    zeta = float(-pair.real / abs(pair)) if abs(pair.imag) > 0 else 1.0
    return {
        "resonance_damping": zeta,
        "antiresonance_hz": p["resonance_hz"] / np.sqrt(1 + r),
        "motor_inertia": p["total_inertia"] / (1 + r),
        "load_inertia": p["total_inertia"] * r / (1 + r),
        "stiffness": (2 * np.pi * p["resonance_hz"]) ** 2 * p["total_inertia"] * r / (1 + r) ** 2,
    }


def two_mass_guess(omega, Gm) -> dict:
    """Start values from the motor FRF: J from the lowest lines (G ≈ −1/(J ω²)), the
    antiresonance at the minimum and the resonance at the maximum of |G_m| ω² above it."""
    n = np.abs(Gm) * omega**2
    J = float(np.median(1 / n[: max(3, len(n) // 20)]))
    ia = int(np.argmin(n))
    ir = ia + int(np.argmax(n[ia:])) if ia < len(n) - 1 else ia
    fa, fr = omega[ia] / (2 * np.pi), omega[ir] / (2 * np.pi)
    if fr <= fa * 1.01:
        fr = fa * 1.5
    return {
        "total_inertia": J,
        "inertia_ratio": (fr / fa) ** 2 - 1,
        "resonance_hz": fr,
        "shaft_damping": 0.05,
        "motor_viscous": 0.0,
        "load_viscous": 0.0,
        "delay_s": 0.0,
    }


def _two_mass_guess(omega, data, given):
    g = data.get("motor_angle")
    return two_mass_guess(omega, g if g is not None else data["load_angle"])


def _two_mass_outputs(p, omega):
    gm, gl = two_mass_response(p, omega)
    return {"motor_angle": gm, "load_angle": gl}


TWO_MASS_STRUCTURE = Structure(
    name="two-mass",
    parameters=TWO_MASS,
    log=frozenset({"total_inertia", "inertia_ratio", "resonance_hz"}),
    outputs=("motor_angle", "load_angle"),
    response=_two_mass_outputs,
    guess=_two_mass_guess,
    scale=lambda p0, w: {
        "motor_viscous": p0["total_inertia"] * w.min(),
        "load_viscous": p0["total_inertia"] * w.min(),
        "delay_s": 1 / w.max(),
        "shaft_damping": 0.01,
    },
    derived=two_mass_derived,
    units="per unit of the input's torque constant (A·s²/rad for a current input and angles "
    "in rad)",
)


# --- FRB single-mass arm: eqs. (1), (12), (13) ------------------------------------------

FRB_SINGLE_MASS = (
    "hub_inertia",
    "hub_viscous",
    "link_stiffness",
    "tip_inertia",
    "tip_damping",
    "delay_s",
)


def frb_single_mass_response(p: dict, omega) -> dict[str, np.ndarray]:
    """The current-driven arm with a massless beam and a pinned tip mass (FRB eq. (1) with
    C_t = C (θm − θt), eqs. (12)–(13)); SI units, i in A, angles in rad:

        J θ̈m + V θ̇m + C (θm − θt) = K i,      J_t θ̈t + d_t θ̇t = C (θm − θt),

    G_b = θt/θm = C / (J_t s² + d_t s + C)                                   (13)
    G_m = θm/i = K (J_t s² + d_t s + C) / (s [J J_t s³ + (J d_t + V J_t) s² +
                 (J C + V d_t + C J_t) s + C (V + d_t)])  · e^{−sτ}          (12)

    The tip's damping d_t acts on the tip's absolute velocity: the paper's identified G_m
    (constant term 103.56 = 43.75·V/J + 0.06·C/J) has this form; damping across the link
    would give G_b a zero. Outputs ``motor_angle`` (G_m), ``tip_angle`` (G_b G_m) and
    ``tip_angle/motor_angle`` (G_b, no delay)."""
    s = 1j * np.asarray(omega, float)
    J, V, C = p["hub_inertia"], p["hub_viscous"], p["link_stiffness"]
    Jt, dt = p["tip_inertia"], p["tip_damping"]
    Db = Jt * s**2 + dt * s + C
    Gb = C / Db
    Gm = (
        p["motor_constant"]
        * Db
        / (s * (J * s * Db + V * Db + C * (Jt * s + dt)))
        * np.exp(-s * p["delay_s"])
    )
    return {"motor_angle": Gm, "tip_angle": Gb * Gm, "tip_angle/motor_angle": Gb}


def frb_single_mass_derived(p: dict) -> dict:
    """Resonance and its damping ratio (the complex pair of G_m's cubic), the tip's own
    frequency √(C/J_t) (G_m's antiresonance, G_b's pole) and damping ratio d_t/(2√(C J_t)),
    the total inertia J + J_t, and G_m's coefficients as FRB eq. (12) prints them
    (``gm_gain`` = K/J and the cubic's coefficients divided by J J_t)."""
    J, V, C = p["hub_inertia"], p["hub_viscous"], p["link_stiffness"]
    Jt, dt = p["tip_inertia"], p["tip_damping"]
    cubic = np.array([J * Jt, J * dt + V * Jt, J * C + V * dt + C * Jt, C * (V + dt)])
    fr, zr = _pair(cubic)
    c = cubic / (J * Jt)
    return {
        "resonance_hz": fr,
        "resonance_damping": zr,
        "antiresonance_hz": float(np.sqrt(C / Jt) / (2 * np.pi)),
        "tip_damping_ratio": float(dt / (2 * np.sqrt(C * Jt))),
        "total_inertia": J + Jt,
        "gm_gain": p["motor_constant"] / J,
        "gm_den_s2": float(c[1]),
        "gm_den_s1": float(c[2]),
        "gm_den_s0": float(c[3]),
    }


def _frb_guess(omega, data, given):
    K = given["motor_constant"]
    return _hub_link_starts(
        "frb-single-mass", omega, data, K, 0.0, ("tip_inertia", "tip_damping"), "θm/i"
    )


FRB_SINGLE_MASS_STRUCTURE = Structure(
    name="frb-single-mass",
    parameters=FRB_SINGLE_MASS,
    log=frozenset({"hub_inertia", "link_stiffness", "tip_inertia"}),
    outputs=("motor_angle", "tip_angle", "tip_angle/motor_angle"),
    response=frb_single_mass_response,
    guess=_frb_guess,
    scale=lambda p0, w: {
        "hub_viscous": (p0["hub_inertia"] + p0["tip_inertia"]) * w.min(),
        "tip_damping": p0["tip_inertia"] * w.min(),
        "delay_s": 1 / w.max(),
    },
    derived=frb_single_mass_derived,
    given={"motor_constant": "K, N·m/A (torque per ampere of the current drive)"},
    units="SI: kg·m², N·m·s/rad, N·m/rad; input current in A, angles in rad",
)


# --- the geared voltage-driven servo with a flexible link (rotary rig) -----------------

VOLTAGE_SERVO = (
    "hub_inertia",
    "hub_viscous",
    "link_stiffness",
    "link_inertia",
    "link_damping",
    "delay_s",
)


def servo_gains(given: dict) -> tuple[float, float]:
    """Input gain k_u = η K_g K_m / R_m (N·m/V) and back-EMF damping k_ω = η K_g² K_m² / R_m
    (N·m·s/rad) of the geared voltage drive τ = k_u v − k_ω ω (:mod:`flexarm.models.motor`;
    η = η_g η_m)."""
    ke = given["gear_ratio"] * given["motor_constant"]
    ku = given["efficiency"] * ke / given["armature_resistance"]
    return ku, ku * ke


def voltage_servo_response(p: dict, omega) -> dict[str, np.ndarray]:
    """Hub angle, tip angle and tip deflection per volt of the geared voltage-driven servo
    turning a flexible link (hub J_eq, viscous B_eq at the output shaft; link stiffness C,
    inertia J_l = m L², damping c across the link; SI units):

        J_eq θ̈ + (B_eq + k_ω) θ̇ + C (θ − θt) + c (θ̇ − θ̇t) = k_u v,
        J_l θ̈t = C (θ − θt) + c (θ̇ − θ̇t),

    k_u, k_ω from :func:`servo_gains`. With Z = c s + C and D_l = J_l s² + Z:
    θt/θ = Z/D_l, θ/v = k_u / (J_eq s² + (B_eq + k_ω) s + J_l s² Z/D_l) · e^{−sτ},
    tip deflection w = L (θt − θ) = −L J_l s²/D_l · θ (m; needs ``length``)."""
    s = 1j * np.asarray(omega, float)
    ku, kw = servo_gains(p)
    J, B = p["hub_inertia"], p["hub_viscous"] + kw
    Jl = p["link_inertia"]
    Z = p["link_damping"] * s + p["link_stiffness"]
    Dl = Jl * s**2 + Z
    G = ku * Dl / (s * ((J * s + B) * Dl + Jl * s * Z)) * np.exp(-s * p["delay_s"])
    out = {"motor_angle": G, "tip_angle": Z / Dl * G, "tip_angle/motor_angle": Z / Dl}
    if p.get("length") is not None:
        out["tip_deflection"] = -p["length"] * Jl * s**2 / Dl * G
    return out


def voltage_servo_derived(p: dict) -> dict:
    """The clamped-hub link frequency √(C/J_l) and damping ratio c/(2√(C J_l)), the
    resonance and its damping ratio (complex pair of J_eq J_l s³ + (J_eq c + B' J_l + J_l c)
    s² + (J_eq C + B' c + J_l C) s + B' C, B' = B_eq + k_ω), the drive's k_u and k_ω."""
    ku, kw = servo_gains(p)
    J, B = p["hub_inertia"], p["hub_viscous"] + kw
    C, Jl, c = p["link_stiffness"], p["link_inertia"], p["link_damping"]
    fr, zr = _pair([J * Jl, J * c + B * Jl + Jl * c, J * C + B * c + Jl * C, B * C])
    return {
        "resonance_hz": fr,
        "resonance_damping": zr,
        "link_frequency_hz": float(np.sqrt(C / Jl) / (2 * np.pi)),
        "link_damping_ratio": float(c / (2 * np.sqrt(C * Jl))),
        "input_gain": ku,
        "back_emf_damping": kw,
    }


def _servo_guess(omega, data, given):
    ku, kw = servo_gains(given)
    return _hub_link_starts(
        "voltage-servo", omega, data, ku, kw, ("link_inertia", "link_damping"), "hub angle per volt"
    )


VOLTAGE_SERVO_STRUCTURE = Structure(
    name="voltage-servo",
    parameters=VOLTAGE_SERVO,
    log=frozenset({"hub_inertia", "link_stiffness", "link_inertia"}),
    outputs=("motor_angle", "tip_angle", "tip_deflection", "tip_angle/motor_angle"),
    response=voltage_servo_response,
    guess=_servo_guess,
    scale=lambda p0, w: {
        "hub_viscous": (p0["hub_inertia"] + p0["link_inertia"]) * w.min(),
        "link_damping": p0["link_inertia"] * w.min(),
        "delay_s": 1 / w.max(),
    },
    derived=voltage_servo_derived,
    given={
        "motor_constant": "K_m, V·s/rad (= N·m/A)",
        "armature_resistance": "R_m, Ω",
        "gear_ratio": "K_g",
        "efficiency": "η = η_g η_m (gear times motor efficiency)",
    },
    optional_given={"length": "L, m (only for the tip_deflection output)"},
    units="SI at the output shaft: kg·m², N·m·s/rad, N·m/rad; input voltage in V",
)


STRUCTURES = {
    s.name: s for s in (TWO_MASS_STRUCTURE, FRB_SINGLE_MASS_STRUCTURE, VOLTAGE_SERVO_STRUCTURE)
}


def get_structure(name: str) -> Structure:
    """The structure named ``name``; a clear error listing the names otherwise."""
    if name not in STRUCTURES:
        raise TFEstError(f"structure {name!r} is unknown; choose one of {', '.join(STRUCTURES)}")
    return STRUCTURES[name]


# --- the one fitter ----------------------------------------------------------------------


@dataclass
class StructuredFit:
    """A structured fit: parameters and derived quantities (value, std; ``std_inflated``
    when the χ² check rejects), the given constants, the cost test."""

    structure: str
    parameters: dict[str, dict[str, float]]
    cost: float
    expected_cost: float | None
    cost_std: float | None
    n_frequencies: int
    n_parameters: int
    covariance: np.ndarray
    free: tuple[str, ...]
    residual: np.ndarray
    given: dict[str, float] = field(default_factory=dict)
    outputs: tuple[str, ...] = ()

    @property
    def verdict(self) -> str:
        return cost_verdict(self.cost, self.n_frequencies, self.n_parameters, self.expected_cost)

    @property
    def values(self) -> dict[str, float]:
        return {k: v["value"] for k, v in self.parameters.items()}

    def response(self, omega) -> dict[str, np.ndarray]:
        """The fitted model's FRF per output at ``omega`` (rad/s)."""
        return STRUCTURES[self.structure].response({**self.given, **self.values}, omega)

    def to_json(self) -> dict:
        return {
            "structure": self.structure,
            "units": STRUCTURES[self.structure].units,
            "given": dict(self.given),
            "free": list(self.free),
            "outputs": list(self.outputs),
            "cost": self.cost,
            "expected_cost": self.expected_cost,
            "cost_std": self.cost_std,
            "verdict": self.verdict,
            "parameters": self.parameters,
        }


#: Starts of the delay (× 1/ω_max): the phase e^{−jωτ} makes the cost multimodal in τ.
_DELAY_STARTS = (0.0, 0.25, 0.5, 1.0)


def fit_structure(
    structure: Structure | str,
    omega,
    data: dict,
    std: dict | None = None,
    *,
    free=None,
    initial: dict | None = None,
    given: dict | None = None,
) -> StructuredFit:
    """Fit ``structure`` to the FRFs ``data`` (output name → complex array at ``omega``,
    rad/s; any subset of ``structure.outputs``) weighted by ``std`` (output name → standard
    deviation per line; all or none), the ML cost of the module docstring.

    ``free``: the parameters fitted (default all; the others stay at ``initial``, whose
    missing entries come from ``structure.guess``); ``given``: the structure's known
    constants. Positive parameters are fitted as logarithms, the others bounded at 0; the
    delay is started at 0, ¼, ½ and 1 × 1/ω_max and the best fit kept. Standard deviations
    of parameters and derived quantities by the delta method."""
    st = get_structure(structure) if isinstance(structure, str) else structure
    omega = np.asarray(omega, float)
    given = dict(given or {})
    missing = [g for g in st.given if given.get(g) is None]
    if missing:
        raise TFEstError(
            f"{st.name}: give the known value(s) "
            + "; ".join(f"{g} ({st.given[g]})" for g in missing)
        )
    bad_given = [g for g in given if g not in st.given and g not in st.optional_given]
    if bad_given:
        raise TFEstError(
            f"{st.name}: unknown given value(s) {bad_given}; this structure takes "
            f"{', '.join(list(st.given) + list(st.optional_given)) or 'none'}"
        )
    for g, v in given.items():
        if v is not None and not (np.isfinite(v) and v > 0):
            raise TFEstError(f"{st.name}: given {g} = {v!r}: must be finite and positive")
    chans = {k: np.asarray(v, complex) for k, v in data.items() if v is not None}
    if not chans:
        raise TFEstError(f"{st.name}: no FRF given; give one or more of {', '.join(st.outputs)}")
    unknown = [k for k in chans if k not in st.outputs]
    if unknown:
        raise TFEstError(
            f"{st.name}: output(s) {unknown} are not outputs of the structure; "
            f"its outputs: {', '.join(st.outputs)}"
        )
    if "tip_deflection" in chans and given.get("length") is None:
        raise TFEstError(
            f"{st.name}: the tip_deflection output needs the link length: give length (m)"
        )
    std = {k: v for k, v in (std or {}).items() if v is not None and k in chans}
    known = len(std) == len(chans)
    if std and not known:
        raise TFEstError(
            f"{st.name}: std given for {sorted(std)} but not for "
            f"{sorted(set(chans) - set(std))}: give all or none"
        )
    for k, g in chans.items():
        if g.shape != omega.shape:
            raise TFEstError(f"{st.name}: output {k} has {g.size} values; omega has {omega.size}")
        if not np.all(np.isfinite(g)):
            raise TFEstError(f"{st.name}: output {k} has NaN or infinite values")
        if k in std and (np.shape(std[k]) != omega.shape or np.any(~(np.asarray(std[k]) > 0))):
            raise TFEstError(f"{st.name}: std of {k} must be positive and finite, one per line")
    free = tuple(st.parameters) if free is None else tuple(free)
    bad = [f for f in free if f not in st.parameters]
    if bad:
        raise TFEstError(
            f"free: unknown parameter(s) {bad}; choose from {', '.join(st.parameters)}"
        )
    init = dict(initial or {})
    bad = [f for f in init if f not in st.parameters]
    if bad:
        raise TFEstError(
            f"initial: unknown parameter(s) {bad}; choose from {', '.join(st.parameters)}"
        )
    w = {k: (1 / np.asarray(std[k], float) if known else 1 / np.abs(g)) for k, g in chans.items()}

    def start_cost(q):
        model = st.response(q, omega)
        return sum(float(np.sum(np.abs((model[k] - g) * w[k]) ** 2)) for k, g in chans.items())

    if all(k in init for k in st.parameters):
        p0 = {**init, **given}
    else:  # the structure's start (or the best of its candidate starts) under 'initial'
        cands = st.guess(omega, chans, given)
        cands = [{**c, **init, **given} for c in (cands if isinstance(cands, list) else [cands])]
        with np.errstate(all="ignore"):
            costs = [start_cost(c) for c in cands]
        p0 = (
            cands[int(np.nanargmin(np.where(np.isfinite(costs), costs, np.nan)))]
            if np.isfinite(costs).any()
            else cands[0]
        )
    free = tuple(f for f in st.parameters if f in free)
    scale = st.scale(p0, omega)

    def unpack(x):
        p = dict(p0)
        for f, v in zip(free, x, strict=True):
            p[f] = float(np.exp(v)) if f in st.log else v * scale[f]
        return p

    def resid(x):
        model = st.response(unpack(x), omega)
        out = []
        for k, g in chans.items():
            e = (model[k] - g) * w[k]
            out += [e.real, e.imag]
        return np.concatenate(out)

    x0 = np.array([np.log(p0[f]) if f in st.log else p0[f] / scale[f] for f in free])
    lo = np.array([-np.inf if f in st.log else 0.0 for f in free])
    best = None
    for tau0 in _DELAY_STARTS if "delay_s" in free else [None]:
        xs = x0.copy()
        if tau0 is not None:
            xs[free.index("delay_s")] = tau0
        sol = least_squares(
            resid,
            xs,
            bounds=(lo, np.inf),
            method="trf",
            x_scale="jac",
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=2000,
        )
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None  # one start at least
    # The bounded solver creeps towards an optimum that lies on a bound (a delay or a
    # viscous term that is truly 0: steps shrink with the distance to the bound). An
    # unbounded Levenberg–Marquardt polish from its solution is kept when it lowers the
    # cost and leaves every bounded parameter at or above 0 (to 1e-9 of its scale).
    if np.isfinite(lo).any():
        pol = least_squares(
            resid,
            best.x,
            method="lm",
            x_scale="jac",
            xtol=1e-15,
            ftol=1e-15,
            gtol=1e-15,
            max_nfev=200 * (len(x0) + 1),
        )
        fin = np.isfinite(lo)
        if pol.cost <= best.cost and np.all(pol.x[fin] >= -1e-9):
            pol.x = np.maximum(pol.x, lo)
            pol.fun = resid(pol.x)
            best = pol
    x = best.x
    cost = float(np.sum(best.fun**2))
    F = int(sum(g.size for g in chans.values()))
    n_par = len(free)
    Jac = best.jac
    cov_x = np.linalg.pinv(Jac.T @ Jac) * (0.5 if known else cost / max(2 * F - n_par, 1))
    p = unpack(x)

    def all_values(xx):
        q = unpack(xx)
        return np.array([q[k] for k in st.parameters] + list(st.derived(q).values()))

    names = list(st.parameters) + list(st.derived(p))
    h = 1e-6
    D = (
        np.column_stack(
            [(all_values(x + h * e) - all_values(x - h * e)) / (2 * h) for e in np.eye(len(x))]
        )
        if len(x)
        else np.zeros((len(names), 0))
    )
    cov_all = D @ cov_x @ D.T
    vals = all_values(x)
    params = {
        n: {"value": float(v), "std": float(np.sqrt(max(cov_all[i, i], 0)))}
        for i, (n, v) in enumerate(zip(names, vals, strict=False))
    }
    exp = F - n_par / 2 if known else None
    params = inflate_std(params, cost, F, n_par, exp)
    return StructuredFit(
        st.name,
        params,
        cost,
        exp,
        np.sqrt(exp) if exp is not None else None,
        F,
        n_par,
        cov_all,
        free,
        best.fun,
        given,
        tuple(chans),
    )


def fit_two_mass(
    omega,
    motor=None,
    load=None,
    *,
    motor_std=None,
    load_std=None,
    free=TWO_MASS,
    initial: dict | None = None,
) -> StructuredFit:
    """The two-mass drive fitted to the motor and/or load angle FRF (rad per input unit):
    :func:`fit_structure` with ``TWO_MASS_STRUCTURE``; ``response`` of the result gives
    ``motor_angle`` and ``load_angle``."""
    if motor is None and load is None:
        raise TFEstError("fit_two_mass needs the motor or the load angle FRF")
    std = None
    if motor_std is not None or load_std is not None:
        std = {"motor_angle": motor_std, "load_angle": load_std}
    return fit_structure(
        TWO_MASS_STRUCTURE,
        omega,
        {"motor_angle": motor, "load_angle": load},
        std,
        free=free,
        initial=initial,
    )
