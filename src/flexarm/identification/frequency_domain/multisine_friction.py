"""Coulomb friction from a periodic (multisine) record: the odd distortion matched by
flexarm's own simulator of the fitted two-mass model with Coulomb friction.

Beside the FRB ω0/3ω0 estimate (:mod:`flexarm.identification.frequency_domain.coulomb`).
Per unit of the input's torque constant (the input a current i in A, the outputs angles in
rad, as in :func:`flexarm.identification.frequency_domain.tfest.fit_two_mass`):

    J_m θ̈m = i − (c s + k)(θm − θl) − d_m' θ̇m − C_f sign(θ̇m),
    J_l θ̈l = (c s + k)(θm − θl) − d_l θ̇l,

C_f (A) at the motor (the single-link arm of :mod:`flexarm.models.assembly` with a
transfer-function beam is exactly this two-mass drive:
:func:`two_mass_scenario`), Karnopp stick with breakaway = C_f.

Method:

1. The BLA's viscous motor damping d_m already holds the friction's linear part: for a
   Gaussian-like velocity of rms σ_v, Bussgang's theorem gives the best linear gain of
   C_f sign(v) as C_f E|v|/E[v²] = C_f √(2/π)/σ_v =: d_eq. The simulator gets
   d_m' = d_m − d_eq (σ_v from the measured periodic motor angle,
   σ_v² = Σ_{k≥1} 2 |ω_k Θ_k|²).
2. One period of the measured input (its mean over the steady periods, DC removed: a
   constant torque would run the free rigid body away) is played for
   ``n_tr`` + 2 periods (n_tr ≥ 1 covers 10 time constants of the slowest mode: the
   rigid body's J/(d_m' + d_l) or the resonance's 1/(ζ ω_r); at most
   ``MAX_TRANSIENT_PERIODS``) in :class:`flexarm.sim.sampled.SampledLoop` through
   :func:`flexarm.sim.build.prepare`; :func:`~.periodic.periodic_frf` of the simulated
   output gives the output spectrum Ŷ_d(C_f) at the odd detection lines d.
3. Measured odd power per line P_d = |Ȳ_d|² − σ²_d/M (noise removed), in the octave bands
   where the odd level is ``DETECT_DB`` above the noise; C_f solves
   Σ_d |Ŷ_d(C_f)|² = Σ_d P_d (log-log interpolation on a grid of C_f, then secant steps).
   The measured input's own content at the odd lines (a current loop reacting to the
   friction puts some there) is played too, so its linear response is part of both sides
   (``linear_share_db``: the frictionless simulator's odd power re the measured).
4. Uncertainty: the line-by-line log ratio ρ_d = ln(P_d/|Ŷ_d|²) at the solution has a
   scatter s_ρ (noise and model error, lines taken as independent); the sum's relative
   std is ≈ s_ρ/√n_d and std(ln C_f) = s_ρ/(√n_d · ∂ln P/∂ln C_f). The C_f of each band
   alone is reported too (their spread shows model error across frequency).
5. Conditioning: at one amplitude the BLA cannot tell C_f from viscous damping (both are a
   damping d_eq); only the odd distortion can. Without odd distortion above the noise the
   result is the upper bound (the level whose distortion reaches the noise) and a warning
   says so; a d_eq above the BLA's d_m (the friction would need negative viscous damping)
   is warned too. Across amplitudes, :func:`coulomb_from_amplitudes`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flexarm.identification.frequency_domain.harmonics import (
    IdentificationError,
    IdentificationWarning,
)
from flexarm.identification.frequency_domain.periodic import DETECT_DB, PeriodicFRF, periodic_frf
from flexarm.identification.frequency_domain.structures import (
    frb_single_mass_derived,
    servo_gains,
    two_mass_derived,
    voltage_servo_derived,
)

#: Simulated friction levels (× the input rms) for the first search grid.
GRID = np.geomspace(1e-3, 0.5, 8)
#: Largest number of transient periods simulated before the two analysed ones.
MAX_TRANSIENT_PERIODS = 12


def two_mass_scenario(
    p: dict, coulomb: float, fs: float, n_samples: int, *, substeps: int = 4
) -> dict:
    """Scenario dict of the two-mass drive (per unit torque constant; ``p`` as
    :func:`~.tfest.two_mass_response`) as flexarm's single-link arm with a transfer-function
    beam: θl/θm = G_b = (c s + k)/(J_l s² + (c + d_l) s + k); the coupling torque
    (c s + k)(θm − θl) = c s θm + H(s)(1 − G_b)θm with H = ((k J_l − c²) s + (k d_l − c k))
    /(J_l s + d_l) (proper), so the motor's viscous term is d_m + c. ``coulomb`` in A
    (torque per unit of the torque constant); the delay is left out."""
    J, r = p["total_inertia"], p["inertia_ratio"]
    Jm, Jl = J / (1 + r), J * r / (1 + r)
    wr = 2 * np.pi * p["resonance_hz"]
    k = wr**2 * Jm * Jl / J
    c = 2 * p["shaft_damping"] * k / wr
    c = c if c * wr > 1e-12 * k else 0.0  # a shaft damping at round-off: none
    dm = max(float(p["motor_viscous"]), 0.0)
    dl = max(float(p["load_viscous"]), 1e-9 * k / wr)  # H's pole off the origin
    return {
        "name": "two-mass-from-frf",
        "arm": {
            "kind": "single_link",
            "motor": {
                "drive": "current",
                "inertia": Jm,
                "viscous": dm + c,
                "torque_constant": 1.0,
                "current_limit": 1e9,
            },
            "friction": (
                {"model": "coulomb", "coulomb": float(coulomb), "static": float(coulomb)}
                if coulomb > 0
                else {"model": "none"}
            ),
            "beam": {
                "model": "transfer_function",
                "tip_num": [c, k] if c else [k],
                "tip_den": [Jl, c + dl, k],
                "coupling_num": [k * Jl - c * c, k * dl - c * k],
                "coupling_den": [Jl, dl],
            },
        },
        "sampling": {"period": 1.0 / fs, "delay": 0},
        "simulation": {"duration": (n_samples - 1) / fs, "substeps": substeps},
        "sensors": {"motor_angle": {}, "tip_angle": {}},
    }


def voltage_servo_scenario(
    p: dict, coulomb: float, fs: float, n_samples: int, *, substeps: int = 4
) -> dict:
    """Scenario dict of the geared voltage-driven servo with a flexible link (``p`` as
    :func:`~.structures.voltage_servo_response`, with the given K_m, R_m, K_g, η) as
    flexarm's single-link arm: voltage drive (η as the gear efficiency, motor efficiency 1:
    the drive uses their product), hub J_eq, B_eq; a lumped beam of length L (``length``,
    or 1 m: the angles do not depend on it) with EI = C L/3, a pinned tip mass J_l/L² and
    modal damping ratio c/(2√(C J_l)) (hub-clamped mode: the damping c across the link,
    models/lumped_beam.py). ``coulomb``: Coulomb level at the output shaft in N·m (Karnopp,
    breakaway = Coulomb); the delay is left out."""
    L = float(p.get("length") or 1.0)
    C, Jl, c = p["link_stiffness"], p["link_inertia"], p["link_damping"]
    zeta = float(c / (2 * math.sqrt(C * Jl)))
    if zeta > 1:
        raise IdentificationError(
            f"voltage-servo: the fitted link damping ratio {zeta:.3g} "
            "exceeds 1; the lumped beam takes 0–1: refit the BLA"
        )
    return {
        "name": "voltage-servo-from-frf",
        "arm": {
            "kind": "single_link",
            "motor": {
                "drive": "voltage",
                "inertia": p["hub_inertia"],
                "viscous": max(float(p["hub_viscous"]), 0.0),
                "motor_constant": p["motor_constant"],
                "armature_resistance": p["armature_resistance"],
                "gear_ratio": p["gear_ratio"],
                "gear_efficiency": p["efficiency"],
                "motor_efficiency": 1.0,
                "voltage_limit": 1e9,
            },
            "friction": (
                {"model": "coulomb", "coulomb": float(coulomb), "static": float(coulomb)}
                if coulomb > 0
                else {"model": "none"}
            ),
            "beam": {
                "model": "lumped",
                "length": L,
                "flexural_rigidity": C * L / 3,
                "damping_ratio": zeta,
                "masses": [{"mass": Jl / L**2, "joint": "pinned"}],
            },
        },
        "sampling": {"period": 1.0 / fs, "delay": 0},
        "simulation": {"duration": (n_samples - 1) / fs, "substeps": substeps},
        "sensors": {"motor_angle": {}, "tip_angle": {}, "tip_deflection": {}},
    }


def frb_single_mass_scenario(
    p: dict, coulomb: float, fs: float, n_samples: int, *, substeps: int = 4
) -> dict:
    """Scenario dict of FRB's single-mass arm (``p`` as
    :func:`~.structures.frb_single_mass_response`, with the given K) as flexarm's
    single-link arm: current drive K, hub J, V, and the transfer-function beam of FRB eqs.
    (13), (16): G_b = (C/J_t)/(s² + (d_t/J_t) s + C/J_t), C_t = C (θm − θt). ``coulomb`` in A
    (the torque C_f = K·``coulomb``, as FRB reports it); the delay is left out."""
    K, C, Jt = p["motor_constant"], p["link_stiffness"], p["tip_inertia"]
    return {
        "name": "frb-single-mass-from-frf",
        "arm": {
            "kind": "single_link",
            "motor": {
                "drive": "current",
                "inertia": p["hub_inertia"],
                "viscous": max(float(p["hub_viscous"]), 0.0),
                "torque_constant": K,
                "current_limit": 1e9,
            },
            "friction": (
                {"model": "coulomb", "coulomb": float(coulomb) * K, "static": float(coulomb) * K}
                if coulomb > 0
                else {"model": "none"}
            ),
            "beam": {
                "model": "transfer_function",
                "stiffness": C,
                "tip_num": [C / Jt],
                "tip_den": [1.0, p["tip_damping"] / Jt, C / Jt],
            },
        },
        "sampling": {"period": 1.0 / fs, "delay": 0},
        "simulation": {"duration": (n_samples - 1) / fs, "substeps": substeps},
        "sensors": {"motor_angle": {}, "tip_angle": {}},
    }


@dataclass(frozen=True)
class _Simulator:
    """How a fitted structure is simulated with Coulomb friction at the (output) shaft."""

    scenario: Callable[..., dict]  # (params, C_f, fs, n) → scenario dict
    viscous: str  # the BLA's viscous parameter that holds the friction's Bussgang share
    rigid: Callable[
        ..., Any
    ]  # params → (total inertia, damping besides ``viscous``): slowest decay
    derived: Callable[..., dict]  # params → dict with resonance_hz, resonance_damping
    torque: Callable[..., Any]  # params → torque per unit of input (scales the C_f grid)
    input: str  # the reference channel the open-loop 'controller' plays
    unit: str  # of C_f
    damping_unit: str  # of ``viscous``
    where: str
    friction_torque: Callable[..., Any] = lambda p: (
        1.0
    )  # params → torque (damping units × rad/s) per unit C_f


def _two_mass_rigid(p):
    return p["total_inertia"], float(p["load_viscous"])


def _servo_rigid(p):
    return p["hub_inertia"] + p["link_inertia"], servo_gains(p)[1]


def _frb_rigid(p):
    return p["hub_inertia"] + p["tip_inertia"], float(p["tip_damping"])


SIMULATORS = {
    # the FRB arm's V in N·m·s/rad, C_f in A (as the paper): the friction torque is K C_f
    "frb-single-mass": _Simulator(
        frb_single_mass_scenario,
        "hub_viscous",
        _frb_rigid,
        frb_single_mass_derived,
        lambda p: 1.0,
        "current",
        "A",
        "N·m·s/rad",
        "at the motor",
        lambda p: p["motor_constant"],
    ),
    "two-mass": _Simulator(
        two_mass_scenario,
        "motor_viscous",
        _two_mass_rigid,
        two_mass_derived,
        lambda p: 1.0,
        "current",
        "A",
        "A·s/rad",
        "at the motor",
    ),
    "voltage-servo": _Simulator(
        voltage_servo_scenario,
        "hub_viscous",
        _servo_rigid,
        voltage_servo_derived,
        lambda p: servo_gains(p)[0],
        "voltage",
        "N·m",
        "N·m·s/rad",
        "at the output shaft",
    ),
}
#: The arm's signal that each structure output is read from.
_SIGNAL = {
    "motor_angle": "motor_angle",
    "load_angle": "tip_angle",
    "tip_angle": "tip_angle",
    "tip_deflection": "tip_deflection",
}


@dataclass
class MultisineCoulomb:
    """C_f from the odd distortion (in ``unit``: A per unit torque constant for the two-mass
    drive and FRB's arm (whose friction torque is K·C_f), N·m at the output shaft for the
    voltage servo); see the module docstring."""

    coulomb_current: float  # C_f in ``unit`` (the name kept from the current-driven case)
    std: float
    band_values: list[float | None]
    band_hz: list[tuple[float, float]]
    detected: bool
    equivalent_damping: float  # d_eq = C_f √(2/π)/σ_v (× K for FRB's arm), viscous units
    motor_viscous_bla: float  # d_m of the BLA fit
    velocity_rms: float
    linear_share_db: float  # odd power of the frictionless simulator re the measured
    simulations: int
    warnings: list[str] = field(default_factory=list)
    unit: str = "A"
    structure: str = "two-mass"

    def to_json(self) -> dict:
        where = SIMULATORS[self.structure].where
        return {
            "value": self.coulomb_current,
            "std": self.std,
            "unit": self.unit,
            "structure": self.structure,
            "band_hz": [list(b) for b in self.band_hz],
            "band_values": self.band_values,
            "detected": self.detected,
            "equivalent_damping": self.equivalent_damping,
            "motor_viscous_bla": self.motor_viscous_bla,
            "velocity_rms": self.velocity_rms,
            "linear_share_db": self.linear_share_db,
            "simulations": self.simulations,
            "method": "odd distortion matched by flexarm's simulator of the fitted "
            f"{self.structure} model with Coulomb friction {where}",
            "warnings": self.warnings,
        }


def _odd_lines(frf: PeriodicFRF) -> np.ndarray:
    exc = frf.lines
    det = np.setdiff1d(np.arange(exc.min(), exc.max() + 1), exc)
    if not np.all(exc % 2 == 1):
        raise IdentificationError(
            f"{frf.input}: the excited lines are not all odd; the odd distortion (the Coulomb "
            "friction's signature) needs an odd multisine (flexarm excite --kind random-odd)"
        )
    odd = det[det % 2 == 1]
    if odd.size == 0:
        raise IdentificationError(
            f"{frf.input}: no odd detection lines between the excited ones: the Coulomb level "
            "cannot be measured; use a random-odd multisine (flexarm excite --kind random-odd)"
        )
    return odd


def _bands(frf: PeriodicFRF, lines: np.ndarray) -> list[tuple[int, int, np.ndarray]]:
    kmin, kmax = int(frf.lines.min()), int(frf.lines.max())
    edges = [kmin]
    while edges[-1] * 2 < kmax:
        edges.append(edges[-1] * 2)
    edges.append(kmax + 1)
    return [
        (lo, hi, lines[(lines >= lo) & (lines < hi)])
        for lo, hi in zip(edges[:-1], edges[1:], strict=True)
    ]


def simulate_record(
    frf: PeriodicFRF,
    params: dict,
    coulomb: float,
    structure: str = "two-mass",
    outputs=("motor_angle",),
) -> PeriodicFRF:
    """The periodic FRF of ``structure`` at ``params`` with Coulomb level ``coulomb`` (in the
    structure's unit, :data:`SIMULATORS`) driven by the measured record's mean input period
    (DC removed: a constant torque would run the free rigid body away), played open loop
    for ``n_tr`` + 2 periods by flexarm's one sampled loop; ``n_tr`` ≥ 1 covers 10 time
    constants of the slowest mode (the rigid body's J/(d + d_rest) or the resonance's
    1/(ζ ω_r)), at most ``MAX_TRANSIENT_PERIODS``. Noise-free; the same lines as ``frf``."""
    import jax.numpy as jnp

    from flexarm.control.discrete import FunctionController
    from flexarm.sim.build import prepare
    from flexarm.sim.sampled import simulate_loop
    from flexarm.specs import scenario_from_dict

    sim = SIMULATORS[structure]
    sp = frf.spectra
    if not sp:
        raise IdentificationError(
            f"{frf.input}: the FRF carries no period spectra (LPM or "
            "several realisations): the record cannot be replayed"
        )
    P, fs = frf.period, frf.fs
    U = sp["mean"][0].copy()
    U[0] = 0.0
    u = np.fft.irfft(U * P, n=P)
    J, d_rest = sim.rigid(params)
    d = max(float(params[sim.viscous]), 0.0)
    der = {**params, **sim.derived(params)}  # resonance_hz: a parameter or derived
    tau = max(
        J / max(d + d_rest, 1e-300),
        1 / max(der["resonance_damping"] * 2 * math.pi * der["resonance_hz"], 1e-300),
    )
    ntr = int(min(MAX_TRANSIENT_PERIODS, max(1, math.ceil(10 * tau * fs / P))))
    n = (ntr + 2) * P
    sc = scenario_from_dict(sim.scenario(params, coulomb, fs, n))
    ctrl = FunctionController(fn=_play, params=None, state0=jnp.zeros(0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy's tf2ss on the beam block
        prep = prepare(sc, controller=ctrl, references={sim.input: np.tile(u, ntr + 2)})
    out = simulate_loop(prep.loop, prep.x0, prep.references, prep.n_samples)
    names = prep.loop.sensors.names
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return periodic_frf(
            out["command"][:, 0],
            {o: out["measured"][:, names.index(_SIGNAL[o])] for o in outputs},
            fs,
            period=P,
            lines=frf.lines,
            transient_periods=ntr,
        )


def coulomb_from_distortion(
    frf: PeriodicFRF,
    params: dict,
    *,
    output: str = "motor_angle",
    structure: str = "two-mass",
    progress=None,
) -> MultisineCoulomb:
    """C_f from the odd distortion of ``output`` in a periodic FRF (:func:`periodic_frf`
    of the measured record) and the parameters ``params`` of ``structure`` fitted to its BLA
    (``StructuredFit.values``; for ``voltage-servo`` with the given K_m, R_m, K_g, η merged
    in: ``{**fit.given, **fit.values}``); see the module docstring. C_f in A (per unit
    torque constant) for ``two-mass``, in A for ``frb-single-mass`` (torque K·C_f, its
    Bussgang share taken from V in N·m·s/rad), in N·m at the output shaft for ``voltage-servo``
    (its Bussgang share is taken from B_eq, the back-EMF damping being known).
    ``progress(i, n)`` after each simulation."""
    if structure not in SIMULATORS:
        raise IdentificationError(
            f"structure {structure!r}: the Coulomb level from the odd "
            f"distortion simulates {', '.join(SIMULATORS)}"
        )
    sim = SIMULATORS[structure]
    if output not in _SIGNAL:
        raise IdentificationError(
            f"output {output!r}: the odd distortion is matched on {', '.join(_SIGNAL)}"
        )
    if output not in frf.outputs:
        raise IdentificationError(
            f"output {output!r} is not in the FRF (outputs: {', '.join(frf.outputs)})"
        )
    sp = frf.spectra
    P, M, fs = frf.period, sp["M"], frf.fs
    j = 1 + frf.outputs.index(output)
    odd = _odd_lines(frf)
    mean, var = sp["mean"], sp["var"]
    y2 = np.abs(mean[j, odd]) ** 2
    noise = var[j, odd] / M
    Pd = y2 - noise
    notes: list[str] = []

    U = mean[0].copy()
    U[0] = 0.0
    u = np.fft.irfft(U * P, n=P)
    sv = velocity_rms(frf, "motor_angle" if "motor_angle" in frf.outputs else output)
    dm = float(params[sim.viscous])

    bands = _bands(frf, odd)
    pos = {int(k): i for i, k in enumerate(odd)}
    detected = []
    for _lo, _hi, ls in bands:
        if ls.size:
            idx = [pos[int(k)] for k in ls]
            if (
                10 * math.log10(max(y2[idx].mean(), 1e-300) / max(noise[idx].mean(), 1e-300))
                >= DETECT_DB
            ):
                detected.append(ls)
    use = np.concatenate(detected) if detected else odd
    sel = np.array([pos[int(k)] for k in use])
    target = float(np.sum(Pd[sel])) if detected else float(np.sum(noise[sel]))

    ft = float(sim.friction_torque(params))

    def d_eq(cf):
        return cf * ft * math.sqrt(2 / math.pi) / max(sv, 1e-300)

    count = [0]

    def simulate(cf) -> np.ndarray:
        p = dict(params, **{sim.viscous: max(dm - d_eq(cf), 0.0)})
        res = simulate_record(frf, p, cf, structure, outputs=(output,))
        count[0] += 1
        if progress is not None:
            progress(count[0], None)
        return np.abs(res.spectra["mean"][1, odd]) ** 2

    urms = float(np.sqrt(np.mean(u**2)))
    floor = simulate(0.0)
    grid = GRID * urms * sim.torque(params)
    sims = [simulate(cf) for cf in grid]
    tot = np.array([s[sel].sum() for s in sims])
    lg, lt = np.log(grid), np.log(np.maximum(tot, 1e-300))
    if target <= tot[0] or target >= tot[-1]:
        raise IdentificationError(
            f"{frf.input}: the measured odd distortion ({10 * math.log10(target):.1f} dB re 1 "
            f"rad²) is outside what the simulated {structure} model gives for C_f from "
            f"{grid[0]:.3g} to {grid[-1]:.3g} {sim.unit}; the fitted model or the friction "
            f"structure (Coulomb {sim.where}) does not describe this record"
        )
    # log-log interpolation on the monotone part, then secant steps with new simulations
    i = int(np.nonzero(tot >= target)[0][0])
    pts = [(lg[i - 1], lt[i - 1], sims[i - 1]), (lg[i], lt[i], sims[i])]
    lt_target = math.log(target)
    for _ in range(3):
        (a0, f0, _), (a1, f1, _) = pts[-2], pts[-1]
        x = a1 + (lt_target - f1) * (a1 - a0) / (f1 - f0) if f1 != f0 else a1
        x = float(np.clip(x, lg[0], lg[-1]))
        s = simulate(math.exp(x))
        pts.append((x, math.log(max(s[sel].sum(), 1e-300)), s))
        if abs(pts[-1][1] - lt_target) < 1e-3:
            break
    x, fx, s_best = min(pts, key=lambda q: abs(q[1] - lt_target))
    (a0, f0, _), (a1, f1, _) = sorted(pts[-2:], key=lambda q: q[0])
    slope = (f1 - f0) / (a1 - a0) if a1 != a0 else 2.0
    slope = slope if slope > 0.2 else 2.0
    cf = math.exp(x + (lt_target - fx) / slope)

    if detected:
        ratio = np.log(np.maximum(Pd[sel], noise[sel] * 0.1) / np.maximum(s_best[sel], 1e-300))
        s_rho = float(np.std(ratio, ddof=1)) if len(ratio) > 1 else 1.0
        std = cf * s_rho / (math.sqrt(len(sel)) * slope)
    else:
        std = cf  # an upper bound only
    band_vals: list[float | None] = []
    for _lo, _hi, ls in bands:
        if not any(ls is d for d in detected):
            band_vals.append(None)
            continue
        idx = np.array([pos[int(k)] for k in ls])
        tb = np.array([sm[idx].sum() for sm in sims])
        want = float(np.sum(Pd[idx]))
        ok = (tb[:-1] <= want) & (tb[1:] > want)
        if not ok.any():
            band_vals.append(None)
            continue
        q = int(np.nonzero(ok)[0][0])
        xb = lg[q] + (math.log(want) - math.log(tb[q])) * (lg[q + 1] - lg[q]) / (
            math.log(tb[q + 1]) - math.log(tb[q])
        )
        band_vals.append(float(math.exp(xb)))
    floor_db = 10 * math.log10(max(floor[sel].sum(), 1e-300) / target)
    if not detected:
        notes.append(
            f"{output}: no odd distortion {DETECT_DB:g} dB above the noise: at this amplitude "
            "Coulomb friction cannot be told from viscous damping (both only damp the BLA); "
            f"C_f = {cf:.3g} {sim.unit} is the upper bound whose distortion would reach the "
            "noise level"
        )
    deq = d_eq(cf)
    if deq > dm:
        notes.append(
            f"{output}: the friction's equivalent damping C_f·√(2/π)/σ_v = {deq:.3g} "
            f"{sim.damping_unit} exceeds the BLA's viscous damping {sim.viscous} = {dm:.3g}: "
            f"the model (Coulomb {sim.where} only) does not explain both the distortion and "
            "the damping; friction elsewhere or a different friction law is likely"
        )
    if detected and floor_db > -1.0:
        notes.append(
            f"{output}: the measured input's own odd-line content, through the linear "
            f"model, already gives {floor_db:+.1f} dB of the measured odd distortion: "
            "the friction's share cannot be separated from it"
        )
    for m in notes:
        warnings.warn(m, IdentificationWarning, stacklevel=2)
    return MultisineCoulomb(
        float(cf),
        float(std),
        band_vals,
        [(float(lo * fs / P), float((hi - 1) * fs / P)) for lo, hi, _ in bands],
        bool(detected),
        deq,
        dm,
        sv,
        floor_db,
        count[0],
        notes,
        sim.unit,
        structure,
    )


def velocity_rms(frf: PeriodicFRF, output: str = "motor_angle") -> float:
    """rms of the angle's derivative over the mean period (rad/s): σ_v² = Σ_{1≤k<P/2}
    2 |ω_k Θ_k|² (Θ_k the mean period's DFT with 1/P scaling)."""
    sp = frf.spectra
    if not sp:
        raise IdentificationError(
            f"{output}: the FRF carries no period spectra (LPM or "
            "several realisations): the velocity rms needs them"
        )
    P, fs = frf.period, frf.fs
    j = 1 + frf.outputs.index(output)
    wk = 2 * np.pi * np.arange(1, P // 2) * fs / P
    return float(np.sqrt(2 * np.sum(np.abs(wk * sp["mean"][j, 1 : P // 2]) ** 2)))


def _play(params, state, measured, reference):
    """The open-loop 'controller': the command is the reference channel ``current`` (a
    current drive) or ``voltage`` (a voltage drive)."""
    return state, reference["current"] if "current" in reference else reference["voltage"]


def coulomb_from_amplitudes(velocity_rms, damping, damping_std) -> dict:
    """C_f and the viscous damping from the BLA's damping at several amplitudes: the BLA's
    damping d(σ_v) = d_v + C_f √(2/π)/σ_v (Bussgang gain of C_f sign(v)), weighted linear
    least squares in 1/σ_v. Returns ``coulomb_current``, ``viscous`` (value, std) and the
    correlation of the two; a warning when C_f is within two standard deviations of zero
    (the amplitudes are too close to tell Coulomb from viscous damping)."""
    sv = np.asarray(velocity_rms, float)
    d = np.asarray(damping, float)
    sd = np.asarray(damping_std, float)
    if sv.size < 2 or np.ptp(1 / sv) <= 0:
        raise IdentificationError(
            "coulomb_from_amplitudes needs records at two or more "
            "different amplitudes (velocity rms)"
        )
    A = np.column_stack([np.ones_like(sv), math.sqrt(2 / math.pi) / sv]) / sd[:, None]
    x, *_ = np.linalg.lstsq(A, d / sd, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    s = np.sqrt(np.diag(cov))
    out = {
        "viscous": {"value": float(x[0]), "std": float(s[0])},
        "coulomb_current": {"value": float(x[1]), "std": float(s[1])},
        "correlation": float(cov[0, 1] / (s[0] * s[1])),
        "warnings": [],
    }
    if abs(x[1]) < 2 * s[1]:
        out["warnings"].append(
            f"C_f = {x[1]:.3g} ± {s[1]:.2g} A is within two standard deviations of zero: the "
            "amplitudes recorded cannot tell Coulomb friction from viscous damping"
        )
    return out


def coulomb_from_bla_amplitudes(
    frfs: list[PeriodicFRF],
    fits: list,
    structure: str = "two-mass",
    *,
    iterations: int = 3,
    progress=None,
) -> dict:
    """C_f and the viscous damping d_v from the BLA's viscous damping at several amplitudes,
    matched with flexarm's simulator of the fitted model with friction.

    ``frfs``: periodic FRFs of records at different amplitudes (with their period spectra);
    ``fits``: the ``structure`` fit (:func:`~.structures.fit_structure`) to each one's BLA.
    The BLA damping d_i (``motor_viscous`` or ``hub_viscous``) at velocity rms σ_i follows
    d_i ≈ d_v + C_f √(2/π)/σ_i (Bussgang, :func:`coulomb_from_amplitudes`: the start). The
    Gaussian-velocity assumption fails where the hub sticks, so the start is corrected by
    the simulator: each record's mean input period is played through the fitted model with
    (d_v, C_f) (:func:`simulate_record`), the same structure is fitted to the simulated BLA
    (same free parameters, same weights), and (d_v, C_f) move by the weighted least-squares
    step of the mismatch d_i − d_i^sim with the Bussgang Jacobian [1, √(2/π)/σ_i]
    (``iterations`` times; a fixed point where the simulated BLA damping equals the
    measured one at every amplitude). Covariance: (AᵀWA)⁻¹ with W = 1/std(d_i)²
    (``std_inflated`` where the χ² check rejected a fit). Returns a dict: ``coulomb``,
    ``viscous`` ({value, std}, in the structure's units), ``correlation``, ``bussgang``
    (the start), ``records`` (σ_v, d, d_sim per amplitude), ``mismatch`` (rms of
    (d − d_sim)/std at the end), ``warnings`` (C_f within two standard deviations of zero:
    the amplitudes cannot tell Coulomb friction from viscous damping; a negative d_v)."""
    if structure not in SIMULATORS:
        raise IdentificationError(
            f"structure {structure!r}: the amplitude match simulates {', '.join(SIMULATORS)}"
        )
    if len(frfs) != len(fits) or len(frfs) < 2:
        raise IdentificationError(
            "coulomb_from_bla_amplitudes needs two or more records "
            "(one FRF and one fit each) at different amplitudes"
        )
    from flexarm.identification.frequency_domain.structures import STRUCTURES, fit_structure

    sim = SIMULATORS[structure]
    names = STRUCTURES[structure].parameters
    sv = np.array([velocity_rms(f) for f in frfs])
    d = np.array([fit.parameters[sim.viscous]["value"] for fit in fits])
    sd = np.array(
        [
            fit.parameters[sim.viscous].get("std_inflated", fit.parameters[sim.viscous]["std"])
            for fit in fits
        ]
    )
    if np.any(~(sd > 0)):
        raise IdentificationError(
            f"the {sim.viscous} of a fit has no positive standard "
            f"deviation (held fixed?): it must be fitted in every record"
        )
    ft = float(sim.friction_torque({**fits[0].given, **fits[0].values}))  # torque per unit C_f
    start = coulomb_from_amplitudes(sv, d / ft, sd / ft)
    start["viscous"] = {k: v * ft for k, v in start["viscous"].items()}
    x = np.array([start["viscous"]["value"], start["coulomb_current"]["value"]])
    A = np.column_stack([np.ones_like(sv), ft * math.sqrt(2 / math.pi) / sv]) / sd[:, None]
    cov = np.linalg.inv(A.T @ A)
    count = 0
    d_sim = np.zeros_like(d)
    for _ in range(max(int(iterations), 0)):
        for i, (frf, fit) in enumerate(zip(frfs, fits, strict=True)):
            outs = tuple(o for o in fit.outputs if o in _SIGNAL)
            p = {**fit.given, **fit.values, sim.viscous: max(float(x[0]), 0.0)}
            rec = simulate_record(frf, p, max(float(x[1]), 0.0), structure, outputs=outs)
            count += 1
            if progress is not None:
                progress(count, None)
            k = [frf.outputs.index(o) for o in outs]
            w = 2 * np.pi * rec.frequency_hz
            # the simulator holds the played input over each sample: its FRF carries the
            # ZOH (1 − e^{−sT})/sT, divided out to compare with the fitted continuous model
            sT = 1j * w / frf.fs
            zoh = (1 - np.exp(-sT)) / sT
            f2 = fit_structure(
                structure,
                w,
                {o: rec.response[j] / zoh for j, o in enumerate(outs)},
                {
                    o: (frf.total_std if frf.total_std is not None else frf.noise_std)[kk]
                    for o, kk in zip(outs, k, strict=True)
                },
                free=fit.free,
                initial={n: fit.values[n] for n in names},
                given=fit.given,
            )
            d_sim[i] = f2.parameters[sim.viscous]["value"]
        x = x + cov @ A.T @ ((d - d_sim) / sd)
    s = np.sqrt(np.diag(cov))
    mismatch = float(np.sqrt(np.mean(((d - d_sim) / sd) ** 2))) if iterations else None
    notes = list(start["warnings"])
    if abs(x[1]) < 2 * s[1] and not notes:
        notes.append(
            f"C_f = {x[1]:.3g} ± {s[1]:.2g} {sim.unit} is within two standard deviations "
            "of zero: the amplitudes recorded cannot tell Coulomb friction from "
            "viscous damping"
        )
    if x[0] < 0:
        notes.append(
            f"the viscous damping {x[0]:.3g} {sim.damping_unit} is negative: the BLA's "
            "damping falls faster with amplitude than Coulomb friction explains"
        )
    for m in notes[len(start["warnings"]) :]:
        warnings.warn(m, IdentificationWarning, stacklevel=2)
    return {
        "structure": structure,
        "unit": sim.unit,
        "damping_unit": sim.damping_unit,
        "coulomb": {"value": float(x[1]), "std": float(s[1])},
        "viscous": {"value": float(x[0]), "std": float(s[0])},
        "correlation": float(cov[0, 1] / (s[0] * s[1])),
        "bussgang": {"coulomb": start["coulomb_current"], "viscous": start["viscous"]},
        "records": [
            {
                "velocity_rms": float(a),
                "damping": float(b),
                "damping_std": float(c),
                "damping_simulated": float(e),
            }
            for a, b, c, e in zip(sv, d, sd, d_sim, strict=True)
        ],
        "mismatch": mismatch,
        "iterations": int(iterations),
        "simulations": count,
        "method": "BLA viscous damping per amplitude; Bussgang start, then matched by "
        f"flexarm's simulator of the fitted {structure} model with Coulomb "
        f"friction {sim.where}",
        "warnings": notes,
    }
