"""``flexarm.identification.time_domain``: time-domain identification of a bench arm from
closed-loop logs.

Given what a data sheet gives (drive, gear ratio K_g, motor constant K_m, armature
resistance R, efficiencies, link length L), estimate the hub inertia, link stiffness,
inertia and damping, hub friction (Coulomb, breakaway, viscous, bias) per recording
session, the sensor delays and the tip sensor's calibration gain and sign, and each log's
initial link state, by minimising the closed-loop simulation output error
(:mod:`flexarm.identification.time_domain.objective`):

1. guesses and bounds from the data (:mod:`flexarm.identification.time_domain.guesses`);
2. global stage: differential evolution, whole generations in one batched simulation,
   on the first ``global_seconds`` of each log (None: whole logs; ``"auto"``: 5 s for
   a flexible link whose hub → tip estimate is trusted, else whole logs)
   (:mod:`flexarm.identification.time_domain.global_stage`);
3. local stage: ``scipy.optimize.least_squares`` (trust-region reflective) on the
   weighted residuals over the full logs, with a forward-difference Jacobian whose
   columns are simulated in one batch; it also refines each log's initial tip and hub
   state (a wrong initial hub rate alone costs more than all the noise). With quantised
   sensors it is a continuation: first on the loop without the converters' rounding,
   whose cost is smooth, then from there on the rounded loop (:func:`_local_continued`;
   on the rounded cost alone least squares stopped on its step tolerance in jags of
   1e-3 of a parameter's range, in a minimum that a 1e-15 change moved). When the tip
   delay is fitted, short refinements at the global stage's delay and its neighbours
   pick it first (``delay_search="both"``: a second start from a profile of short
   refinements at every delay; each start through the local stage and the polish, the
   lowest cost wins). The friction polish: a short batched differential evolution on the
   friction coordinates alone (stick-slip makes their finite differences unreliable),
   and least squares again;
4. uncertainty from the final Jacobian J and residuals r: the reported ``std`` is the
   Newey–West sandwich (JᵀJ)⁻¹ Ŝ (JᵀJ)⁻¹, Ŝ the Bartlett-weighted autocovariance of the
   scores Jᵀ_t r_t per log, its bandwidth 10 residual correlation times
   (:mod:`flexarm.identification.time_domain.uncertainty`): output-error residuals persist for many
   samples and the textbook s² (JᵀJ)⁻¹ (kept as ``std_iid``) is then 10-30× too small.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from flexarm.identification.time_domain import estimates as _est
from flexarm.identification.time_domain import guesses
from flexarm.identification.time_domain.global_stage import (
    GlobalResult,
    differential_evolution_stage,
    ordered_delays,
    overlapping_delays,
)
from flexarm.identification.time_domain.logs import (
    PERIOD_TOL,
    FitInputError,
    as_rig_log,
    check_closed_loop,
    pieces,
)
from flexarm.identification.time_domain.objective import Objective, Rig, check_filters
from flexarm.identification.time_domain.params import FRICTION, ParamDef, ParamSpace, derived
from flexarm.identification.time_domain.report import FitResult
from flexarm.identification.time_domain.solvers import evolve, trust_region
from flexarm.identification.time_domain.uncertainty import hac_covariance, iid_covariance
from flexarm.sim.batch import one_blas_thread


def detect_quantum(x: np.ndarray) -> float:
    """The A/D or encoder step of a signal (0 when it does not look quantised)."""
    d = np.abs(np.diff(x))
    d = d[d > 0]
    if d.size < 10:
        return 0.0
    q = float(np.min(d))
    k = x / q
    if (
        np.max(np.abs(k - np.round(k - 0.0))) < 1e-3
        or np.max(np.abs((x - x[0]) / q - np.round((x - x[0]) / q))) < 1e-3
    ):
        return q
    return 0.0


def _computation_delay(logs, notes: list[str]) -> int:
    """The samples between a sample and the command computed from it: the delay (0, 1, 2)
    at which the declared law best explains the logged command, the most common over the
    logs (:func:`~flexarm.identification.time_domain.controller_check.check_controller`);
    0 where no log declares a law or the check fails."""
    from flexarm.identification.time_domain.controller_check import check_controller

    found = []
    for g in logs:
        if getattr(g, "gains", None) is None or "voltage" not in g.columns:
            continue
        try:
            found.append(check_controller(g, use_regressed=True).delay)
        except Exception as exc:  # a log the check cannot read: no vote
            notes.append(f"{g.name}: controller check failed ({exc}); its delay not used")
    if not found:
        return 0
    d = max(set(found), key=found.count)
    notes.append(
        f"computation delay {d} sample(s): where the declared law best explains the "
        f"logged command ({found.count(d)} of {len(found)} logs)"
    )
    return int(d)


def _finer_than_logged(log, q: float) -> bool:
    """Whether a logged hub rate shows that the logger read the angle more finely than
    the step ``q`` of the logged angle (the rate is not a multiple of q / T)."""
    v = log.columns.get("motor_velocity")
    if v is None or np.ptp(v) == 0:
        return False
    k = v * log.dt / q
    return bool(np.median(np.abs(k - np.round(k))) > 0.05)


def make_rig(
    drive: str,
    gear_ratio: float,
    motor_constant: float | None,
    armature_resistance: float | None,
    link_length: float | None,
    gear_efficiency: float,
    motor_efficiency: float,
    limit: float,
    encoder_quantum: float,
    tip_quantum: float = 0.0,
) -> Rig:
    """Drive gains from the data sheet: voltage drive k_u = η_g η_m K_g K_m / R,
    k_ω = k_u K_g K_m; current drive k_u = η_g η_m K_g K_m, k_ω = 0."""
    for name, v in (
        ("gear_ratio", gear_ratio),
        ("motor_constant", motor_constant),
        ("link_length", link_length),
    ):
        if v is None or not v > 0:
            raise FitInputError(f"fit: field {name!r} = {v!r}: give the data-sheet value (> 0)")
    assert motor_constant is not None and link_length is not None  # checked just above
    eta = gear_efficiency * motor_efficiency
    if drive == "voltage":
        if armature_resistance is None or not armature_resistance > 0:
            raise FitInputError(
                "fit: field 'armature_resistance' is needed (> 0, ohm) for drive='voltage'"
            )
        ke = gear_ratio * motor_constant
        ku = eta * ke / armature_resistance
        motor = dict(
            drive="voltage",
            motor_constant=motor_constant,
            armature_resistance=armature_resistance,
            gear_ratio=gear_ratio,
            gear_efficiency=gear_efficiency,
            motor_efficiency=motor_efficiency,
            voltage_limit=limit,
        )
        return Rig("voltage", ku, ku * ke, limit, link_length, motor, encoder_quantum, tip_quantum)
    if drive == "current":
        ku = eta * gear_ratio * motor_constant
        motor = dict(drive="current", torque_constant=ku, current_limit=limit)
        return Rig("current", ku, 0.0, limit, link_length, motor, encoder_quantum, tip_quantum)
    raise FitInputError(f"fit: field 'drive' = {drive!r}: choose 'voltage' or 'current'")


def _priors(space: ParamSpace, priors) -> dict[int, tuple[float, float]]:
    """``fit(priors=...)`` checked and keyed by the parameter's index in ``space``."""
    out: dict[int, tuple[float, float]] = {}
    for name, spec in (priors or {}).items():
        hit = [
            i
            for i, (n, d) in enumerate(zip(space.names, space.defs, strict=True))
            if name in (n, d.name)
        ]
        ok = [n for n, d in zip(space.names, space.defs, strict=True) if d.lo >= 0]
        if not hit or any(space.defs[i].lo < 0 for i in hit):
            raise FitInputError(
                f"fit: field 'priors' names {name!r}: not a positive fitted parameter of "
                f"this rig; give one of {', '.join(ok)} (a session's as name[k])"
            )
        try:
            mean, rel = (float(x) for x in spec)
        except (TypeError, ValueError):
            mean = rel = float("nan")
        if not (math.isfinite(mean) and mean > 0 and math.isfinite(rel) and rel > 0):
            raise FitInputError(
                f"fit: field 'priors[{name!r}]' = {spec!r}: give (mean in SI > 0, relative "
                "std > 0), e.g. (2.1e-3, 0.1) for within ±10 %"
            )
        out.update({i: (mean, rel) for i in hit})
    return out


def _space(
    logs,
    rig: Rig,
    n_sessions: int,
    friction: bool,
    max_delay: int,
    tip_sign,
    delays,
    bounds: dict | None,
    info: dict,
    est: dict | None = None,
) -> tuple[ParamSpace, np.ndarray, np.ndarray]:
    """Bounds from the data (see :mod:`flexarm.identification.time_domain.guesses` and
    :mod:`flexarm.identification.time_domain.estimates`) and the seed point. ``est``: the cheap
    estimates (``tip``: the hub → tip model, ``hub``: the hub delay, ``frequency``: the link
    frequency estimates), which narrow the search where they are trusted."""
    est = est or {}
    tip, hub = est.get("tip"), est.get("hub")
    fb = (est.get("frequency") or {}).get("bounds")
    if fb:
        wc_b = (fb[0], fb[1])  # (lo, hi)
        wc = tip.omega_c if tip is not None and tip.trusted else math.sqrt(fb[0] * fb[1])
        info["link_frequency_guess"] = {"value": wc, "from": "estimates"}
    else:
        wc, how = guesses.link_frequency(logs)
        info["link_frequency_guess"] = {"value": wc, "from": how}
        wc_b = (wc / 1.35, wc * 1.35) if wc else (2 * np.pi * 0.3, 2 * np.pi * 40)
        wc = wc or math.sqrt(wc_b[0] * wc_b[1])
    J_est = guesses.hub_inertia(logs, rig.k_u)
    info["hub_inertia_guess"] = J_est
    J_b = (J_est / 8, J_est * 2) if J_est else (1e-7, 10.0)
    if hub is not None and hub.trusted and hub.inertia:
        # the regression's J (delay-aware) and the step-start J (an upper-biased estimate)
        lo_j = min(hub.inertia / 3, J_b[0]) if J_est else hub.inertia / 3
        J_b = (lo_j, max(hub.inertia * 3, J_b[1] if J_est else 0))
        J_est = hub.inertia
    J_ref = J_est or 1e-3
    if tip is not None and tip.trusted:
        g, r2 = tip.gain, 1.0
        info["tip_gain_guess"] = {"value": g, "from": "hub-to-tip model"}
    else:
        g, r2 = guesses.tip_gain(logs, wc, rig.length)
        info["tip_gain_guess"] = {"value": g, "r2": r2}
    if g is not None and r2 > 0.3:
        g_b, sign = (abs(g) / 2.5, abs(g) * 2.5), int(np.sign(g))
    else:
        g_b, sign = (0.1, 10.0), None
    if tip_sign is not None:
        sign = int(tip_sign)
    tau_f = guesses.stick_torque(logs, rig.k_u)
    info["stick_torque_guess"] = tau_f
    tau_f = max(tau_f or 0.0, 0.01 * rig.k_u * rig.limit)
    speed = max(
        np.percentile(np.abs(np.gradient(g_.columns["motor_angle"], g_.dt)), 99)
        for g_ in logs
        if "motor_angle" in g_.columns
    )
    B_hi = max(0.5 * rig.k_u * rig.limit / max(speed, 1e-3), 2 * rig.k_omega, 1e-6)
    defs = [ParamDef("hub_inertia", "kg*m**2", *J_b, "log")]
    if any("tip_deflection" in g.outputs for g in logs):
        defs += [
            ParamDef("link_frequency", "rad/s", *wc_b, "log"),
            ParamDef("link_inertia", "kg*m**2", J_ref / 20, J_ref * 20, "log"),
            ParamDef("link_damping", "", 0.002, 0.3, "log"),
            ParamDef("tip_gain", "m/m", *g_b, "log"),
        ]
    else:  # a rigid arm: no link to fit, its tip delay and sign are not searched
        sign = 1
        delays = (delays[0], 0)
    for s in range(n_sessions):
        defs.append(ParamDef("viscous", "N*m*s/rad", 0.0, B_hi, "loglin", s))
        if friction:
            defs += [
                ParamDef("coulomb", "N*m", 0.0, 2 * tau_f, "loglin", s),
                ParamDef("static_excess", "N*m", 0.0, 2 * tau_f, "loglin", s),
                ParamDef("bias", "N*m", -tau_f, tau_f, "lin", s),
            ]
    for name, (lo, hi) in (bounds or {}).items():
        hits = [i for i, d in enumerate(defs) if d.name == name]
        if not hits:
            raise FitInputError(
                f"fit: bounds: {name!r} is not a fitted parameter; fitted: "
                f"{sorted({d.name for d in defs})}"
            )
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise FitInputError(f"fit: bounds[{name!r}] = ({lo}, {hi}): need finite lo < hi")
        for i in hits:
            d = defs[i]
            if d.scale == "log" and lo <= 0:
                raise FitInputError(f"fit: bounds[{name!r}]: {name} must be > 0 (got lo = {lo})")
            defs[i] = ParamDef(d.name, d.unit, float(lo), float(hi), d.scale, d.session)
    ranges = _delay_ranges(hub, tip, max_delay, delays)
    info["delay_ranges"] = {"motor_angle": ranges[0], "tip_deflection": ranges[1]}
    space = ParamSpace(
        defs,
        n_sessions,
        max(r[1] for r in ranges),
        sign,
        friction,
        (delays[0], delays[1]),
        delay_ranges=ranges,
    )
    zeta0 = float(np.clip(tip.zeta, 0.003, 0.25)) if tip is not None and tip.trusted else 0.03
    B0 = (
        float(np.clip(hub.viscous, 0.0, B_hi))
        if hub is not None and hub.trusted and hub.viscous is not None
        else 0.05 * B_hi
    )
    seed = {
        "hub_inertia": J_est or J_ref,
        "link_frequency": wc,
        "link_inertia": J_ref,
        "link_damping": zeta0,
        "tip_gain": abs(g) if g else 1.0,
        "viscous": B0,
        "coulomb": 0.6 * tau_f,
        "static_excess": 0.2 * tau_f,
        "bias": 0.0,
    }
    u0 = np.array(
        [float(np.clip(d.to_unit(np.clip(seed[d.name], d.lo, d.hi)), 0, 1)) for d in defs]
    )
    # the seed's delays: the middle of a range set by a trusted estimate, else the
    # smallest delay searched
    from_est = (hub is not None and hub.trusted, tip is not None and tip.trusted)
    mid = [sum(r) // 2 if e else r[0] for r, e in zip(ranges, from_est, strict=True)]
    d0 = np.array(
        [
            delays[0] if delays[0] is not None else mid[0],
            delays[1] if delays[1] is not None else mid[1],
            ((sign or 1) + 1) // 2,
        ]
    )
    return space, u0, d0


#: half-width (samples) of the delay search around a trusted estimate
DELAY_HALF_WIDTH = 6


def _delay_ranges(hub, tip, max_delay: int, fixed) -> tuple[tuple[int, int], tuple[int, int]]:
    """Search ranges of the hub and tip delays (samples): ± ``DELAY_HALF_WIDTH`` around a
    trusted estimate (the hub regression; the hub range plus the hub → tip lag), else
    0 ... ``max_delay``; a fixed delay is its own range."""
    w = DELAY_HALF_WIDTH
    if fixed[0] is not None:
        h = (int(fixed[0]), int(fixed[0]))
    elif hub is not None and hub.trusted and hub.delay is not None:
        h = (max(hub.delay - w, 0), min(hub.delay + w, max_delay))
    else:
        h = (0, max_delay)
    if fixed[1] is not None:
        t = (int(fixed[1]), int(fixed[1]))
    elif tip is not None and tip.trusted:
        t = (max(min(h[0] + tip.lag - w, max_delay), 0), min(h[1] + tip.lag + w, max_delay))
    else:
        t = (0, max_delay)
    return h, t


#: the global stage's window on a flexible link's logs (s), ``global_seconds="auto"``
GLOBAL_SECONDS = 5.0


def _global_window(global_seconds: float | None | str, whole: bool) -> float | None:
    """The global stage's window (s; None: whole logs) for ``fit(global_seconds=...)``;
    ``whole``: what ``"auto"`` means here (a rigid arm, or a flexible link that the hub →
    tip estimate does not tie down)."""
    if global_seconds is None:
        return None
    if global_seconds == "auto":
        return None if whole else GLOBAL_SECONDS
    if isinstance(global_seconds, int | float) and global_seconds > 0:
        return float(global_seconds)
    raise FitInputError(
        f"fit: field 'global_seconds' = {global_seconds!r}: give seconds > 0, None "
        '(whole logs) or "auto" (5 s for a flexible link, whole logs for a rigid arm or '
        "a link the hub -> tip estimate does not tie down)"
    )


def fit(
    logs: Sequence[Any],
    *,
    drive: str = "voltage",
    gear_ratio: float = 1.0,
    motor_constant: float | None = None,
    armature_resistance: float | None = None,
    link_length: float | None = None,
    gear_efficiency: float = 1.0,
    motor_efficiency: float = 1.0,
    voltage_limit: float | None = None,
    current_limit: float | None = None,
    mode: str = "closed_loop",
    controller: Any = None,
    sessions: Sequence[int] | None = None,
    friction: bool = True,
    encoder_counts: int | None = None,
    tip_sign: int | None = None,
    angle_delay: int | None = None,
    tip_delay: int | None = None,
    max_delay: int | None = None,
    computation_delay: int | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    substeps: int = 2,
    popsize: int = 8,
    maxiter: int = 40,
    global_seconds: float | None | str = "auto",
    local_nfev: int = 30,
    delay_nfev: int = 6,
    polish_iter: int = 8,
    seed: int = 0,
    global_starts: int | str = "auto",
    tip_after_hub: bool = True,
    chunk: int = 64,
    progress: Callable[[str], None] | None = None,
    filters: dict[str, float] | None = None,
    delay_search: str = "neighbours",
    estimates: bool = True,
    priors: Mapping[str, tuple[float, float]] | None = None,
    segment: float | None = None,
) -> FitResult:
    """Fit the arm's physical parameters to closed-loop (or open-loop) logs.

    ``voltage_limit`` (V; A for a current drive without ``current_limit``): None takes the
    amplifier limit the logs' format declares (``[controller] limit``), else 10 V with a
    warning. ``computation_delay`` (samples between a sample and its command): None takes
    the delay at which the declared law best explains the logged command
    (:func:`~flexarm.identification.time_domain.controller_check.check_controller`, R² per
    delay 0, 1, 2; 0 where the logs declare no law). Both, and the resolution of the logged
    hub angle, go into the fitted scenario (:meth:`FitResult.write_scenario`), so a design
    on it needs no further flag.

    ``logs``: paths or :class:`~flexarm.io.logs.Log` s; logs given together are one
    recording session (shared friction) unless ``sessions`` gives a session index per log
    (mechanics shared, friction per session). ``mode``: ``"closed_loop"`` (each log's
    controller closed in simulation; ``controller`` overrides every log's declaration)
    or ``"open_loop"`` (replay of the logged ``voltage`` / command column).
    ``friction=False`` fits a model without dry friction (viscous only), for comparison.
    ``encoder_counts`` per revolution (default: detected from the hub-angle steps);
    ``tip_sign``, ``angle_delay``, ``tip_delay`` fix what is known; None (the default)
    fits them (the logger's hub channel can lag the motion by tens of ms; with sensor noise
    feeding the loop a hub delay trades off against the hub inertia, so give
    ``angle_delay=0`` where the encoder is known to be latched at the sample instant).
    The global stage uses the first ``global_seconds`` of each log (None: all; ``"auto"``,
    the default: :data:`GLOBAL_SECONDS` = 5 s for a flexible link, whole logs for a rigid
    arm), ``popsize`` × dimension members for at most ``maxiter`` generations. With few
    moves in that window a stick-slip run cannot tell inertia, delay and friction apart: on
    the rigid session of 4/25 (four 10 s runs, a step every 2.5 s) the first 5 s led to a
    basin at 2.5 × the data sheet's inertia, whose held-out fit was 61-75 %; whole logs,
    81.5-87 % on every one of four seeds (``tests/test_time_domain_fit__rotary_rig.py``),
    at 1.5 × the global stage's time. A flexible link keeps 5 s where its ringing and the
    hub → tip estimate (trusted) that start the search tie the inertia down within a move:
    on whole logs the units' 10 s fits move (unit 6's hub delay 24 → 16 samples) and
    designs tuned on them miss targets met before (``tests/test_design_tune.py``). Where
    that estimate is not trusted (4/27: heavy gear friction, the hub → tip model 29 %) the
    global stage takes whole logs too: on the first 5 s it chose a hub delay of 109
    samples, whose fit cost 0.398 on the full logs against 0.360 from whole logs (72
    samples), at the same fit time.
    The local stage runs at most ``local_nfev`` evaluations
    from each of the starts that ``delay_search`` gives when the tip delay is fitted (on
    the global window): ``"neighbours"``: ``delay_nfev`` evaluations at the global stage's
    tip delay and its two neighbours, the best one; ``"profile"``: ``2 PROFILE_NFEV``
    evaluations at the global stage's delay, then ``PROFILE_NFEV`` at every delay
    0 ... ``max_delay`` from there, the two best; ``"both"``: the neighbours' best and the
    profile's best other delay. Each start gets the local stage and the friction polish;
    the lowest cost wins, with a warning when another delay is within ``DELAY_FLAT``.
    ``"neighbours"`` is the default (one start: the acceptance protocol's figures); use
    ``"both"`` with ``polish_iter=20`` when the global stage may miss the tip delay by
    2 samples (one open-loop log, several sessions, a slow sensor filter: tested), at
    about twice the time.
    ``global_starts`` (default ``"auto"``: 3 where the fit spans several sessions and no
    estimate ties the sensor delays down, else 1; on the 4/27 + 5/2 training runs the
    mean training tip rose from 61.8 to 63.3 % with three starts): the global stage, the
    delay starts, the local stage and
    the polish run from this many seeds (``seed``, ``seed + 1``, ...), the lowest full-log
    cost wins, ``info["global_starts"]`` lists every start, and a warning says when a
    start with other delays costs within :data:`DELAY_FLAT` of the winner; at that many
    times the time. Where no estimate ties the delays down (a flexible link whose hub →
    tip model is not trusted, as on 4/27) one start's outcome depends on its seed, and the
    result says so (on 4/27 the hub / tip delays of seeds 0, 1, 2 at 5 V: 36 / 47, 35 / 66,
    16 / 43 samples, at costs 0.347, 0.344, 0.366).
    ``tip_after_hub`` (default True): where both delays are free and their search ranges
    leave the order open (the tip's starting before the hub's ends: no trusted hub → tip
    estimate, ``estimates=False``, or a trusted lag over an untrusted hub's wide range,
    :func:`~.global_stage.ordered_delays`), the tip delay is searched as the hub delay plus a
    lag ≥ 0 (global stage, neighbours, profile): an
    encoder reads the hub at once and a strain gauge's conditioning only adds lag. Without
    it the 4/27 session's delays came out in either order (three seeds at two amplifier
    limits: the tip before the hub in three of six, e.g. 89 / 65 samples), each fit cheaper
    by trading a late hub (a stuck gear train starting late) against the tip, and the
    default seed missed #23's floors at either limit (K1 tip 54.6 % at 5 V, K1K2 hub
    78.8 % at 10 V); with it, hub 83.0-89.7 % and tip 56.1-67.2 % in five of the six, the
    sixth tip 54.2 % (``docs/tasks/fit-rotary-rig.md``). False searches the two independently.
    Least squares runs as a continuation (:func:`_local_continued`):
    on the rounded loop's cost alone it stopped in local minima that the last bits moved
    (on the acceptance logs a 1e-15 change of the sampling period moved the viscous B from
    −2 % to −10 % at 4× the cost); continued, sampling periods changed by ±1e-12 and
    1e-10 give the same delays and every parameter within 1.4 %.
    ``estimates`` (default True): first the cheap estimates of
    :mod:`flexarm.identification.time_domain.estimates` (hub → tip model, hub delay, link
    frequency), which set
    the delay search ranges (± 6 samples around them, up to ``max_delay``, default
    150 ms), the bounds of ω_c, J and the tip gain, the gauge's sign and, unless
    ``filters`` names the tip channel, its low-pass, and the stiffer clamp of a gear train
    pushed stuck where the stuck phases ring faster under a push
    (:func:`~flexarm.identification.time_domain.guesses.pushed_ringing`: a rig constant,
    not fitted; ``info["estimates"]["pushed_ringing"]``); False: the guesses of
    :mod:`flexarm.identification.time_domain.guesses` alone, every delay 0 ... ``max_delay``
    searched.
    ``filters``: known low-pass cutoffs (Hz, not fitted) of the sensors' analog first-order
    filters, e.g. ``{"tip_deflection": 50.0}``
    (:mod:`flexarm.sim.rig_loop`).
    ``priors``: parameter name (:data:`~.params.MECHANICS`, :data:`FRICTION` but ``bias``;
    ``coulomb`` for every session, ``coulomb[1]`` for one) → (mean in SI, relative std):
    r_p = (ln p − ln p̄) / σ_p, eq. (2) of the general engine, weighed against V as there
    (:meth:`~.objective.Objective.prior_rows`), in every stage; their information joins
    the HAC std. E.g. ``{"hub_inertia": (2.1e-3, 0.1)}``: the data sheet's hub inertia
    within ±10 %.
    ``segment`` (s): multiple shooting: after the estimates (on the whole logs), each log
    is cut into pieces of ``segment`` s (:func:`~.logs.pieces`), and the stages fit the
    pieces as logs of their own (each its own start state, the session of its log); the
    result's logs and fit % are the pieces' (``flexarm.fit`` adds the whole logs'
    prediction). None: whole logs.
    """
    say = progress or (lambda msg: None)
    t_start = time.perf_counter()
    _global_window(global_seconds, False)  # bad input: one line before any work
    if delay_search not in ("neighbours", "profile", "both"):
        raise FitInputError(
            f"fit: field 'delay_search' = {delay_search!r}: choose "
            "'neighbours', 'profile' or 'both'"
        )
    if mode not in ("closed_loop", "open_loop"):
        raise FitInputError(f"fit: field 'mode' = {mode!r}: choose 'closed_loop' or 'open_loop'")
    if global_starts != "auto" and (
        isinstance(global_starts, bool) or not isinstance(global_starts, int) or global_starts < 1
    ):
        raise FitInputError(
            f"fit: field 'global_starts' = {global_starts!r}: give a whole number >= 1 "
            "(1: one global stage; 3: three seeds, the lowest cost wins) or 'auto'"
        )
    if not isinstance(tip_after_hub, bool):
        raise FitInputError(
            f"fit: field 'tip_after_hub' = {tip_after_hub!r}: give True (the tip sensor's "
            "delay at least the hub's) or False (any order)"
        )
    if not logs:
        raise FitInputError("fit: no logs given")
    blogs = [as_rig_log(x, controller) for x in logs]
    dts = [g.dt for g in blogs]
    for g in blogs:
        if abs(g.dt - dts[0]) > PERIOD_TOL * dts[0]:
            raise FitInputError(
                f"{g.path}: field 'time': sampling period {g.dt:g} s differs "
                f"from {blogs[0].path}'s {dts[0]:g} s; resample to one period"
            )
        if mode == "closed_loop":
            check_closed_loop(g)
        elif "voltage" not in g.columns:
            raise FitInputError(
                f"{g.path}: field 'voltage': open-loop replay needs the logged "
                "command column 'voltage' (V, or A for a current drive)"
            )
    if max_delay is None:
        max_delay = int(round(_est.MAX_DELAY_S / dts[0]))
    filt = check_filters(filters, dts[0], substeps)
    sess = list(sessions) if sessions is not None else [0] * len(blogs)
    if len(sess) != len(blogs) or sorted(set(sess)) != list(range(max(sess) + 1)):
        raise FitInputError(
            f"fit: field 'sessions' = {sess}: give one index per log, "
            "numbered 0, 1, ... without gaps"
        )
    if encoder_counts:
        q = 2 * np.pi / encoder_counts
    else:
        q = max(
            (detect_quantum(g.columns["motor_angle"]) for g in blogs if "motor_angle" in g.columns),
            default=0.0,
        )
        if q > 0 and any(_finer_than_logged(g, q) for g in blogs):
            # the logger rounds the angle it writes, but its own rate (from the angle it
            # read) is not a multiple of q / T: the controller read a finer angle
            q = 0.0
    notes: list[str] = []
    if voltage_limit is None:
        declared = {float(v) for v in (getattr(g, "voltage_limit", None) for g in blogs) if v}
        if len(declared) == 1:
            voltage_limit = declared.pop()
        else:
            voltage_limit = 10.0
            notes.append(
                "no amplifier limit given and the logs' format declares "
                + ("several" if declared else "none")
                + ": 10 V assumed "
                "(give voltage_limit, --voltage-limit, or [controller] limit in the "
                "log format)"
            )
    if computation_delay is None:
        computation_delay = _computation_delay(blogs, notes) if mode == "closed_loop" else 0
    q_logged = max(
        (detect_quantum(g.columns["motor_angle"]) for g in blogs if "motor_angle" in g.columns),
        default=0.0,
    )
    limit = voltage_limit if drive == "voltage" else (current_limit or voltage_limit)
    rig = make_rig(
        drive,
        gear_ratio,
        motor_constant,
        armature_resistance,
        link_length,
        gear_efficiency,
        motor_efficiency,
        limit,
        q,
    )
    info: dict[str, Any] = {
        "encoder_quantum": q,
        "logged_resolution": q_logged,
        "voltage_limit": voltage_limit,
        "computation_delay": computation_delay,
        "notes": notes,
    }
    # a gauge whose sign changed between sessions: the estimates read every session's tip
    # with session 0's sign (the fit applies each session's sign, ParamSpace.session_signs)
    signs, elogs = [1] * (max(sess) + 1), blogs
    if max(sess) > 0 and link_length is not None:
        signs, sign_est = guesses.session_signs(blogs, sess, None, float(link_length))
        info["session_signs"] = {"signs": signs, "estimates": sign_est}
        if any(x < 0 for x in signs):
            flipped = [s_ for s_, x in enumerate(signs) if x < 0]
            notes.append(
                f"the tip gauge's sign differs between sessions: session(s) {flipped} read "
                "with the sign opposite to session 0's (gauge estimates "
                + ", ".join(
                    f"{e['gain']:.3g} m/m (R² {e['r2']:.2f})"
                    for e in sign_est
                    if e["gain"] is not None
                )
                + "); the gauge's size is shared, its sign is per session"
            )
            say(notes[-1])
            elogs = [_with_tip_sign(g, signs[k]) for g, k in zip(blogs, sess, strict=True)]
    if estimates:
        say("estimates: hub-to-tip model, hub delay, link frequency")
        est = _estimates(elogs, rig, max_delay, filters)
        info["estimates"] = {
            "tip_model": est["tip"].to_dict() if est["tip"] else None,
            "hub_delay": est["hub"].to_dict(),
            "link_frequency": est["frequency"],
        }
        # a gear train that clamps the link more stiffly while the motor pushes it stuck
        # (4/27: light stuck phases ring at 1.79 Hz, pushed ones at 1.91 Hz)
        push = guesses.pushed_ringing(elogs, rig.k_u)
        info["estimates"]["pushed_ringing"] = push
        if push is not None:
            rig = replace(
                rig,
                push_stiffening=push["stiffening"],
                push_threshold=push["threshold"],
                push_full=push["full"],
            )
            say(
                f"stuck phases ring {push['pushed_hz']:.3f} Hz where the motor pushes with "
                f">= {push['full_command']:.3g} ({push['full']:.3g} N*m), "
                f"{push['light_hz']:.3f} Hz with <= {push['threshold_command']:.3g}: the "
                f"clamp stiffens up to x{1 + push['stiffening']:.3f} while pushed"
            )
    else:  # bounds from the guesses alone, every delay 0 ... max_delay searched
        est = {}
        info["estimates"] = None
    if est.get("tip_cutoff"):
        # the hub → tip model's low-pass, as a known sensor filter (lag and cutoff are
        # estimated together; the closed-loop stages then search the delay around it)
        filt = check_filters(
            {**{k: v for k, v in filt.items() if v}, "tip_deflection": est["tip_cutoff"]},
            dts[0],
            substeps,
        )
    space, u0, d0 = _space(
        elogs,
        rig,
        max(sess) + 1,
        friction,
        max_delay,
        tip_sign,
        (angle_delay, tip_delay),
        bounds,
        info,
        est,
    )
    space.priors = _priors(space, priors)
    space.session_signs = tuple(signs) if any(x < 0 for x in signs) else ()
    # the start point (SI, the gauge gain with the start's sign): the result's template
    info["start"] = {
        nm: float(d.to_phys(u0[i])) * (2 * int(d0[2]) - 1 if d.name == "tip_gain" else 1)
        for i, (nm, d) in enumerate(zip(space.names, space.defs, strict=True))
    }
    wc_guess = float(np.sqrt(space.defs[1].lo * space.defs[1].hi))
    if segment is not None:
        # multiple shooting: the estimates and bounds above come from the whole logs; the
        # stages fit the pieces, each from its own estimated start state
        blogs, owner = pieces(blogs, segment)
        sess = [sess[i] for i in owner]
        say(f"multiple shooting: {len(blogs)} pieces of {segment:g} s")
    n_full = max(len(g) for g in blogs)
    # "auto": a flexible link's window is short only where the hub -> tip estimate ties it
    # down (with estimates off, as before: 5 s)
    untied = bool(est) and not (est.get("tip") is not None and est["tip"].trusted)
    g_s = _global_window(global_seconds, space.rigid or untied)
    if global_starts == "auto":
        # several sessions with the delays untied: one seed's outcome varies most there
        # (4/27 + 5/2: delays 39 / 51 from seed 0, 53 / 67 from the best of three)
        global_starts = AUTO_STARTS if untied and max(sess) > 0 and not space.rigid else 1
        if global_starts > 1:
            say(f"{global_starts} global starts (several sessions, delays untied)")
    info["global_starts_used"] = global_starts
    info["global_window"] = g_s
    n_glob = n_full if g_s is None else min(n_full, int(round(g_s / dts[0])))
    common: dict[str, Any] = dict(
        mode=mode,
        substeps=substeps,
        comp_delay=computation_delay,
        chunk=chunk,
        wc_guess=wc_guess,
        filters=filt,
    )
    obj_g = Objective(blogs, rig, space, sess, n_samples=n_glob, **common)
    say(
        f"global stage: {space.n_cont} continuous + discrete parameters, "
        f"{len(blogs)} logs x {n_glob} samples"
    )
    best = {"U": u0, "D": d0, "off": None, "cost": float("inf")}
    try:
        dbounds = space.discrete_bounds()

        def run_stages(ordered: bool):
            return _stages(
                obj_g,
                blogs,
                rig,
                space,
                sess,
                common,
                u0,
                d0,
                n_glob,
                n_full,
                best,
                say,
                popsize=popsize,
                maxiter=maxiter,
                seed=seed,
                global_starts=global_starts,
                ordered=ordered,
                local_nfev=local_nfev,
                delay_nfev=delay_nfev,
                polish_iter=polish_iter,
                friction=friction,
                delay_search=delay_search,
                info=info,
            )

        glob, loc, D, warnings, obj = run_stages(tip_after_hub and ordered_delays(dbounds))
        if tip_after_hub and overlapping_delays(dbounds) and int(D[1]) < int(D[0]):
            # a tip range that a trusted lag started later than an untrusted hub's wide one
            # (unit 7): searched freely, and the tip came out before the hub (85 / 64 samples,
            # an encoder read 85 ms late): searched again with the tip at or after the hub
            say(
                f"tip delay {int(D[1])} < hub delay {int(D[0])} samples: searched again "
                "with the tip at or after the hub (tip_after_hub)"
            )
            info["reordered"] = {"hub": int(D[0]), "tip": int(D[1])}
            glob, loc, D, warnings, obj = run_stages(True)
        interrupted = False
    except KeyboardInterrupt:
        # Ctrl-C: the best point so far, marked interrupted (flexarm.errors.FitInterrupted)
        interrupted = True
        D, warnings = np.asarray(best["D"]), []
        off = best["off"] if best["off"] is not None else np.zeros((len(blogs), 4))
        loc = {
            "U": np.asarray(best["U"]),
            "off": off,
            "std_u": np.full(space.n_cont, np.nan),
            "std_iid_u": np.full(space.n_cont, np.nan),
            "success": False,
            "message": "interrupted",
            "nfev": 0,
            "cost": best["cost"],
            "seconds": 0.0,
            "rho": float("nan"),
            "at_bounds": [],
            "bandwidth": [],
        }
        glob = best.get("glob") or GlobalResult(
            loc["U"], D, best["cost"], 0, 0, False, "interrupted", 0.0, np.zeros(0)
        )
        obj = Objective(blogs, rig, space, sess, **common) if n_glob != n_full else obj_g
    if not interrupted:
        loc, space = _widen_and_retry(obj, loc, D, space, local_nfev, info, warnings, say)
    tr, e, bad = obj.run(loc["U"][None], D[None], loc["off"][None])
    fitp = obj.fit_percent(e[0])
    res = FitResult.build(
        logs=blogs,
        rig=rig,
        space=space,
        U=loc["U"],
        D=D,
        offsets=loc["off"],
        std_u=loc["std_u"],
        std_iid_u=loc["std_iid_u"],
        fit_percent=fitp,
        diverged=bad[0],
        traj=[a[0] for a in tr],
        glob=glob,
        local=loc,
        info=info,
        settings=dict(
            mode=mode,
            friction=friction,
            substeps=substeps,
            computation_delay=computation_delay,
            sessions=sess,
            popsize=popsize,
            maxiter=maxiter,
            global_samples=n_glob,
            seed=seed,
            global_starts=global_starts,
            tip_after_hub=tip_after_hub,
            filters=filt,
            priors={space.names[i]: list(v) for i, v in sorted(space.priors.items())},
            segment=segment,
            # multiple shooting: the index of the log each piece was cut from
            piece_owner=None if segment is None else [int(i) for i in owner],
        ),
        seconds=time.perf_counter() - t_start,
        objective=obj,
    )
    res.warnings.extend(
        warnings
        + _poorly_determined(res, rig, space)
        + _tip_offsets(blogs)
        + _delay_order(res, space)
        + [n for n in notes if n.startswith(("no amplifier limit", "the tip gauge's sign"))]
        + _pushed_note(rig)
        + (_seed_note(est.get("tip"), space) if untied and global_starts == 1 else [])
    )
    if interrupted:
        from flexarm.errors import FitInterrupted

        res.message = (
            "INTERRUPTED (Ctrl-C): the best parameters found so far, cost "
            f"{best['cost']:.4g}; not converged. " + res.message
        )
        raise FitInterrupted(res)
    return res


#: how often bounds that a parameter ends at are widened before the fit gives up on it
WIDEN_RETRIES = 2
#: factor (log-scaled parameters) or widths (linear ones) a bound moves out by
WIDEN_FACTOR = 3.0


def _widen_and_retry(
    obj: Objective,
    loc: dict,
    D: np.ndarray,
    space: ParamSpace,
    local_nfev: int,
    info: dict,
    warnings: list,
    say,
) -> tuple:
    """A parameter that ends at a bound of its data-derived range: move that bound out
    (×``WIDEN_FACTOR`` for log-scaled, one range width for linear ones), refit from the
    same physical point by least squares, keep the refit when it costs less; at most
    ``WIDEN_RETRIES`` times. Every widening is reported (``info["widened"]`` and a
    warning); a parameter still at a bound is warned about by the result."""
    for _ in range(WIDEN_RETRIES):
        hits = [i for i in loc["at_bounds"] if space.defs[i].scale in ("log", "lin")]
        if not hits:
            break
        defs = list(space.defs)
        moved = {}
        for i in hits:
            d, u = defs[i], loc["U"][i]
            low = u < 0.5
            if d.scale == "log":
                lo, hi = (d.lo / WIDEN_FACTOR, d.hi) if low else (d.lo, d.hi * WIDEN_FACTOR)
            else:
                w = d.hi - d.lo
                lo, hi = (d.lo - w, d.hi) if low else (d.lo, d.hi + w)
            defs[i] = ParamDef(d.name, d.unit, lo, hi, d.scale, d.session, d.doc)
            moved[space.names[i]] = [[d.lo, d.hi], [lo, hi]]
        new = replace(space, defs=defs)
        U1 = np.array(
            [
                nd.to_unit(od.to_phys(u))
                for od, nd, u in zip(space.defs, defs, loc["U"], strict=False)
            ]
        )
        say(f"widening the bounds of {', '.join(moved)} and refitting")
        obj.space = new
        loc2 = _local_continued(obj, np.clip(U1, 0.0, 1.0), D, local_nfev, off0=loc["off"])
        info.setdefault("widened", []).append(
            {"bounds": moved, "cost_before": loc["cost"], "cost_after": loc2["cost"]}
        )
        if loc2["cost"] < loc["cost"]:
            warnings.append(
                f"{', '.join(moved)} ended at a bound of the data-derived range; "
                "the range was widened and the fit redone (cost "
                f"{loc['cost']:.4g} -> {loc2['cost']:.4g})"
            )
            loc, space = loc2, new
        else:
            obj.space = space
            break
    return loc, space


def _stages(
    obj_g,
    blogs,
    rig,
    space,
    sess,
    common,
    u0,
    d0,
    n_glob,
    n_full,
    best,
    say,
    *,
    seed,
    global_starts,
    info,
    **search: Any,
):
    """``global_starts`` runs of :func:`_one_start` (the global stage from seeds ``seed``,
    ``seed + 1``, ...; each with its tip-delay starts, local stage and friction polish;
    ``search``: :func:`_one_start`'s other settings, passed on as they are); the lowest
    full-log cost wins. ``best`` is kept current with the best point so far. More
    than one start: ``info["global_starts"]`` lists each start's seed, global cost, delays
    and final cost, and a warning says when another start's delays differ by more than
    :data:`DELAY_HALF_WIDTH` samples at a cost within :data:`DELAY_FLAT` of the winner's."""
    obj = Objective(blogs, rig, space, sess, **common) if n_glob != n_full else obj_g
    runs = []
    for k in range(global_starts):
        if global_starts > 1:
            say(f"global start {k + 1} of {global_starts} (seed {seed + k})")
        inf: dict[str, Any] = {}
        glob, loc, D, warnings = _one_start(
            obj_g, obj, blogs, space, u0, d0, n_full, best, say, seed=seed + k, info=inf, **search
        )
        runs.append(dict(k=k, glob=glob, loc=loc, D=D, warnings=warnings, info=inf))
    order = sorted(runs, key=lambda r: (r["loc"]["cost"], r["k"]))
    win = order[0]
    glob, loc, D, warnings = win["glob"], win["loc"], win["D"], win["warnings"]
    info.update(win["info"])
    if global_starts > 1:
        info["global_starts"] = [
            {
                "seed": seed + r["k"],
                "global_cost": float(r["glob"].cost),
                "delays": [int(d) for d in r["D"][:2]],
                "cost": float(r["loc"]["cost"]),
            }
            for r in runs
        ]
        say(f"global start {win['k'] + 1} (seed {seed + win['k']}) wins: {info['global_starts']}")
        far = [
            r
            for r in order[1:]
            if np.max(np.abs(np.asarray(r["D"][:2]) - D[:2])) > DELAY_HALF_WIDTH
            and r["loc"]["cost"] < (1 + DELAY_FLAT) * loc["cost"]
        ]
        if far:
            r = far[0]
            warnings = warnings + [
                f"the sensor delays are poorly determined: global start {r['k'] + 1} (seed "
                f"{seed + r['k']}) ended at delays {int(r['D'][0])} / {int(r['D'][1])} "
                f"samples (hub / tip) against {int(D[0])} / {int(D[1])}, costing only "
                f"{100 * (r['loc']['cost'] / loc['cost'] - 1):.1f} % more; give "
                "angle_delay= / tip_delay= if they are known, or record longer logs"
            ]
    return glob, loc, D, warnings, obj


def _one_start(
    obj_g,
    obj,
    blogs,
    space,
    u0,
    d0,
    n_full,
    best,
    say,
    *,
    popsize,
    maxiter,
    seed,
    local_nfev,
    delay_nfev,
    polish_iter,
    friction,
    delay_search,
    ordered,
    info,
):
    """The global stage, the tip-delay starts, the local stage and the friction polish
    (see :func:`fit`); ``best`` is kept current with the best point so far."""
    glob = differential_evolution_stage(
        obj_g,
        u0,
        d0,
        popsize=popsize,
        maxiter=maxiter,
        seed=seed,
        progress=lambda k, c: say(f"  generation {k}: best cost {c:.4g}"),
        best=best,
        tip_after_hub=ordered,
    )
    best["glob"] = glob
    if not np.isfinite(glob.cost) or glob.cost >= 1e3:
        bad = [g.name for i, g in enumerate(blogs)]
        raise FitInputError(
            f"fit: every simulated loop diverged ({', '.join(bad)}): the logs' controller "
            "gains make the simulated loop unstable for all parameters tried; check the "
            "'# controller:' lines (gains, signs, units: V/rad, V/m, V*s/rad, V*s/m), the "
            "tip sensor's sign (tip_sign=) and the data-sheet values"
        )
    D, U0, off0 = glob.D, glob.U, None
    warnings: list[str] = []
    # starting points of the local stage (D, U, per-log initial-state offsets)
    starts = [{"D": D, "U": U0, "off": off0}]
    if space.fixed_delays[1] is None and local_nfev > 1:
        starts = []
        lowest = int(D[0]) if ordered else 0  # the smallest tip delay tried
        # the delays are compared by short refinements of the smooth (unrounded) cost:
        # on the rounded one, which jag each short refinement stops in decides the delay
        obj_r = obj_g.unquantised() if obj_g.quantised else obj_g
        if delay_search in ("neighbours", "both"):
            # the tip delay is an integer the local stage cannot move, and the global
            # stage's choice trades off against ζ and the initial tip rate: refine
            # briefly at the neighbouring delays too (on the global window), keep the best
            near = _neighbour_refinement(obj_r, glob.U, D, min(delay_nfev, local_nfev), lowest)
            info["tip_delay_trials"] = near.pop("trials")
            say(
                f"tip delay {int(near['D'][1])} samples (short refinements: "
                f"{info['tip_delay_trials']})"
            )
            starts.append(near)
        if delay_search in ("profile", "both"):
            prof = _tip_delay_profile(
                obj_r,
                glob.U,
                D,
                min(2 * PROFILE_NFEV, local_nfev),
                min(PROFILE_NFEV, local_nfev),
                lowest,
            )
            info["tip_delay_profile"] = prof["profile"]
            say(
                f"tip delay profile (short refinements): "
                f"{ {k: round(v, 6) for k, v in prof['profile'].items()} }"
            )
            # "profile": its two best delays; "both": its best delay other than the
            # neighbours' choice (two starts that test two delays on the full logs)
            taken = {int(c["D"][1]) for c in starts}
            new = [c for c in prof["candidates"] if int(c["D"][1]) not in taken]
            starts.extend(new[: 2 if delay_search == "profile" else 1])
    # every start gets the local stage and the friction polish on the full logs; the
    # lowest cost wins (on one open-loop log, two sessions or behind a slow sensor filter
    # the global stage's tip delay was 2 samples off, which the profile over every delay
    # finds)
    finals = []
    for k, c in enumerate(starts):
        say(
            f"local stage{f' (start {k + 1} of {len(starts)})' if len(starts) > 1 else ''}: "
            f"least squares on {len(blogs)} logs x {n_full} samples"
        )
        loc_k = _local_continued(obj, c["U"], c["D"], local_nfev, off0=c["off"])
        if friction and polish_iter > 0:
            say("friction polish: batched differential evolution on the friction parameters")
            loc_k = _friction_polish(obj, loc_k, c["D"], polish_iter, seed, local_nfev)
        finals.append((loc_k, c["D"]))
        if loc_k["cost"] < best["cost"]:
            best.update(U=loc_k["U"], D=c["D"], off=loc_k["off"], cost=loc_k["cost"])
    finals.sort(key=lambda t: t[0]["cost"])
    loc, D = finals[0]
    if len(finals) > 1:
        info["local_starts"] = [{"tip_delay": int(d[1]), "cost": r["cost"]} for r, d in finals]
        say(f"tip delay {int(D[1])} samples (costs of the starts: {info['local_starts']})")
        other = [t for t in finals[1:] if int(t[1][1]) != int(D[1])]
        if other and other[0][0]["cost"] < (1 + DELAY_FLAT) * loc["cost"]:
            warnings.append(
                f"tip_deflection delay = {int(D[1])} samples is poorly determined: delay "
                f"{int(other[0][1][1])} costs only "
                f"{100 * (other[0][0]['cost'] / loc['cost'] - 1):.1f} % more on the full "
                "logs; give tip_delay= if it is known, or record longer logs"
            )
    return glob, loc, D, warnings


#: a tip low-pass estimate is used as the channel's filter when its group delay is at
#: least this many samples
TIP_FILTER_MIN_SAMPLES = 3


#: global starts of ``global_starts="auto"`` where several sessions leave the delays untied
AUTO_STARTS = 3


def _seed_note(tip, space: ParamSpace) -> list[str]:
    """A warning for a one-start fit whose estimates left the sensor delays untied (a
    flexible link whose hub → tip model ``tip`` is not trusted, or none; the caller's
    ``untied``): with a delay free, the global stage's seed chose it."""
    if space.rigid or all(d is not None for d in space.fixed_delays):
        return []
    why = (
        f"the hub -> tip model explains {tip.fit_percent:.0f} % of the tip"
        if tip is not None
        else "no hub -> tip model was found"
    )
    return [
        f"{why} (not trusted), so nothing ties the sensor delays down but the global "
        "stage, whose outcome here depends on its seed: give global_starts=3 "
        "(--global-starts 3) to search from three seeds and keep the lowest cost, or "
        "angle_delay= / tip_delay= if the delays are known"
    ]


def _pushed_note(rig: Rig) -> list[str]:
    """What the stiffer clamp of a gear train pushed stuck means for the result (a rig
    constant estimated from the stuck phases, not a fitted parameter)."""
    if not rig.push_stiffening > 0:
        return []
    return [
        f"the stuck phases ring faster where the motor pushes the stuck gear train: the "
        f"link's clamp is taken up to {1 + rig.push_stiffening:.3f} times stiffer while the "
        f"hub is stuck, rising from a drive torque of {rig.push_threshold:.3g} N*m to "
        f"{rig.push_full:.3g} N*m (estimated from the logs, not fitted; the fitted scenario "
        "carries it as arm.friction.pushed_stiffening, push_threshold and push_full)"
    ]


def _with_tip_sign(log, sign: int):
    """``log`` with its tip channels (deflection and rate) read with ``sign``: the cheap
    estimates' view of a session whose gauge sign differs from session 0's."""
    if sign > 0:
        return log
    sig = {
        k: (-v if k in ("tip_deflection", "tip_velocity") else v) for k, v in log.signals.items()
    }
    return replace(log, signals=sig)


@one_blas_thread
def _estimates(blogs, rig: Rig, max_delay: int, filters) -> dict:
    """The cheap estimates of :mod:`flexarm.identification.time_domain.estimates` (hub → tip model
    with the tip channel's lag relative to the hub, the hub delay, the link frequency), and the
    tip low-pass cutoff to use when the user gave none and the model is trusted."""
    known = "tip_deflection" in (filters or {})  # given, 0 (no filter) included
    tip = _est.tip_model(blogs, rig.length, max_lag=max_delay)
    hub = _est.hub_delay(blogs, rig.k_u, rig.k_omega, max_delay=max_delay, tip=tip)
    freq = _est.link_frequency_estimates(blogs, tip)
    out = {"tip": tip, "hub": hub, "frequency": freq, "tip_cutoff": None}
    if tip is not None and tip.trusted and not known:
        # at most what two RK4 substeps integrate accurately, and only a real low-pass:
        # one whose group delay 1/(2π f_c) is at least TIP_FILTER_MIN_SAMPLES samples
        # (a faster one is, at the link's frequency, the same as a delay of a sample or
        # two, which the delay search finds; as a known filter it biased ζ by 6 % on a
        # synthetic rig without any filter, the hub -> tip model reading 97 Hz)
        fc = tip.cutoff_hz
        dt = blogs[0].dt
        if fc < min(0.1 / dt, 1.0 / (2 * math.pi * TIP_FILTER_MIN_SAMPLES * dt)):
            out["tip_cutoff"] = float(fc)
    return out


#: the tip delay is called poorly determined when the second candidate's full-log cost is
#: within this fraction of the winner's (on two 6 s synthetic logs the true delay won by
#: 11 %, and the local stage's unconverged last iterations still move costs by a few %)
DELAY_FLAT = 0.10
#: evaluations of each short refinement of the delay profile
PROFILE_NFEV = 10


def _tip_delay_profile(
    obj: Objective, U: np.ndarray, D: np.ndarray, start_nfev: int, nfev: int, lowest: int = 0
) -> dict:
    """Profile the cost over every tip delay ``lowest`` ... max_delay on ``obj``'s window: first a
    refinement (``start_nfev`` evaluations) at the global stage's delay ``D[1]`` (the
    global stage runs without the per-log initial-state offsets and stops far from the
    optimum: short refinements from there land in different local minima at each delay,
    and their costs do not rank the delays); then from that point a short refinement
    (``nfev``) at each delay, all parameters and initial states free. The delay is an
    integer the local stage cannot move, and it trades off against J (about ±5 % per
    sample on the synthetic rig), ζ and the initial tip rate, so each delay needs its own
    adjusted parameters. Returns the profile {delay: cost} and every delay's refinement as
    candidates (D, U, offsets), lowest cost first."""
    r0 = _local(obj, U, D, start_nfev)
    trials = []
    for dd in range(lowest, obj.space.max_delay + 1):
        Dk = D.copy()
        Dk[1] = dd
        r = _local(obj, r0["U"], Dk, nfev, off0=r0["off"])
        trials.append((r["cost"], dd, Dk, r))
    profile = {int(t[1]): float(t[0]) for t in trials}
    trials.sort(key=lambda t: t[0])
    return {
        "profile": profile,
        "candidates": [{"D": Dk, "U": r["U"], "off": r["off"]} for _, _, Dk, r in trials],
    }


def _neighbour_refinement(
    obj: Objective, U: np.ndarray, D: np.ndarray, nfev: int, lowest: int = 0
) -> dict:
    """Short refinements (``nfev``) from the global point ``U`` at the global stage's tip
    delay D[1] and its two neighbours (those ≥ ``lowest``, the hub delay where the tip
    must not lead it); the lowest cost as a start (D, U, offsets), with the costs by delay
    (``trials``)."""
    best, trials = None, {}
    for dd in (D[1] - 1, D[1], D[1] + 1):
        if max(lowest, 0) <= dd <= obj.space.max_delay or dd == D[1]:
            Dk = D.copy()
            Dk[1] = dd
            r = _local(obj, U, Dk, nfev)
            trials[int(dd)] = r["cost"]
            if best is None or r["cost"] < best[0]["cost"]:
                best = (r, Dk)
    assert best is not None  # D[1] itself is always tried
    r, Dk = best
    return {"D": Dk, "U": r["U"], "off": r["off"], "trials": trials}


def _delay_order(res: FitResult, space: ParamSpace) -> list[str]:
    """A warning when both delays were fitted and the tip channel reads the motion before
    the hub channel: on real rigs of this kind the tip lags the hub by tens of ms, so the
    fitted hub delay then stands for something the model lacks (on the 4/27 session, with
    heavy gear friction, the stuck gear train starting later than the model's breakaway)."""
    dh, dt = res.delays.get("motor_angle"), res.delays.get("tip_deflection")
    if space.rigid or any(f is not None for f in space.fixed_delays):
        return []
    if dh is None or dt is None or dt >= dh:
        return []
    return [
        f"tip_deflection delay = {dt} samples is below the motor_angle delay = {dh}: "
        "the tip channel reading the motion before the hub channel is not what a strain "
        "gauge and an encoder do; the hub delay likely stands for a lag of the hub's "
        "start that the friction model lacks (a stuck gear train); treat both delays as "
        "apparent, or give angle_delay= if it is known"
    ]


#: a tip reading at rest beyond this fraction of the signal's range is called an offset
TIP_OFFSET_WARN = 0.02


def _tip_offsets(blogs) -> list[str]:
    """Warnings for logs whose tip sensor reads away from zero at rest (see
    :func:`flexarm.identification.time_domain.guesses.tip_rest_reading`): the model has no sensor
    offset."""
    out = []
    for g in blogs:
        r = guesses.tip_rest_reading(g)
        if r is not None and r[1] > 0 and abs(r[0]) > TIP_OFFSET_WARN * r[1]:
            out.append(
                f"{g.name}: tip_deflection reads {r[0]:.3g} m at rest "
                f"({100 * abs(r[0]) / r[1]:.0f} % of its range), where a free link "
                "rests at 0: a sensor offset, which the model does not have; zero "
                "the gauge (subtract its rest reading) before fitting"
            )
    return out


def _poorly_determined(res: FitResult, rig: Rig, space: ParamSpace) -> list[str]:
    """What such logs hardly determine, whatever the standard errors say (they come from a
    local linearisation of a cost that stick-slip makes jumpy, and are optimistic)."""
    out = []
    for s in range(space.n_sessions):
        sfx = "" if space.n_sessions == 1 else f"[{s}]"
        B = res.params.get("viscous" + sfx, 0.0)
        if rig.k_omega > 0 and B < 0.2 * rig.k_omega:
            out.append(
                f"viscous{sfx} = {B:.3g} N*m*s/rad is poorly determined: it is "
                f"{100 * B / rig.k_omega:.0f} % of the drive's back-EMF damping "
                f"k_omega = {rig.k_omega:.3g}, which acts in parallel"
            )
        if space.friction:
            out.append(
                f"static_excess{sfx} (breakaway) and bias{sfx} rest on the restarts "
                "of a stuck hub and the up/down asymmetry of its stops: with few "
                "restarts (short logs, one move size) expect 10-20 % errors in the "
                "breakaway and a bias known to a few % of it only"
            )
    return out


def _friction_polish(
    obj: Objective,
    loc: dict,
    D: np.ndarray,
    maxiter: int,
    seed: int,
    local_nfev: int,
    width: float = 0.12,
) -> dict:
    """Stick-slip makes the cost jump where a stop lands on another encoder count, so the
    finite-difference Jacobian of the friction parameters is unreliable and least squares
    stalls there. Re-search the friction coordinates (unit box ± ``width`` around the
    local optimum) by a short batched differential evolution on the full logs, the
    mechanics and initial states held, then refine everything by least squares again."""
    sp = obj.space
    idx = [i for i, d in enumerate(sp.defs) if d.name in FRICTION]
    U, off = loc["U"], loc["off"]
    bounds = [(max(U[i] - width, 0.0), min(U[i] + width, 1.0)) for i in idx]

    def f(x):
        X = np.atleast_2d(x.T)
        Us = np.tile(U, (X.shape[0], 1))
        Us[:, idx] = X
        return obj.cost(Us, np.tile(D, (X.shape[0], 1)), np.tile(off, (X.shape[0], 1, 1)))

    c0 = float(f(U[idx][:, None])[0])
    res = evolve(f, bounds, x0=U[idx], popsize=8, maxiter=maxiter, seed=seed, tol=0.0)
    if res.fun >= c0:
        return loc
    U1 = U.copy()
    U1[idx] = res.x
    out = _local(obj, U1, D, max(local_nfev // 2, 2), off0=off)
    out["nfev"] += loc["nfev"] + int(res.nfev)
    out["seconds"] += loc["seconds"]
    if "smooth_stage" in loc:
        out["smooth_stage"] = loc["smooth_stage"]
    return out if out["cost"] <= float(res.fun) + 1e-15 else loc


def _local_continued(
    obj: Objective, U0: np.ndarray, D: np.ndarray, max_nfev: int, off0: np.ndarray | None = None
) -> dict:
    """:func:`_local` first on the loop without the converters' rounding
    (:meth:`Objective.unquantised`: a smooth cost), then from its optimum on the rounded
    loop, each with up to ``max_nfev`` evaluations; one stage when nothing is quantised.

    The rounded cost is jagged along every parameter (a count flips in the simulated loop's
    controller; on the acceptance logs jumps of 10-50 % of the cost within 1e-3 of the
    viscous B's and ζ's unit range) and least squares stops on its step tolerance in the
    first jag: on those logs at 17× the cost of the continued fit, B −21 %, ζ −26 %, and
    which jag depended on the last bits of the simulation. The unrounded cost's minimum
    lies within the jags of the rounded one's, so the second stage only polishes."""
    if not obj.quantised:
        return _local(obj, U0, D, max_nfev, off0=off0)
    pre = _local(obj.unquantised(), U0, D, max_nfev, off0=off0)
    out = _local(obj, pre["U"], D, max_nfev, off0=pre["off"])
    out["nfev"] += pre["nfev"]
    out["seconds"] += pre["seconds"]
    out["smooth_stage"] = {"cost": pre["cost"], "nfev": pre["nfev"], "message": pre["message"]}
    return out


def _local(
    obj: Objective,
    U0: np.ndarray,
    D: np.ndarray,
    max_nfev: int,
    step: float = 1e-3,
    off0: np.ndarray | None = None,
    free_params: bool = True,
) -> dict:
    """least_squares over the unit coordinates and each log's initial-state offsets (tip
    deflection and rate, hub angle and rate); ``free_params=False`` holds the parameters
    at ``U0`` and estimates the initial states only (a held-out log's, from its own data)."""
    n, L = obj.space.n_cont, obj.L
    nz = n + 4 * L
    W = np.sqrt(obj.weights())  # (2, L, N)
    mask = W > 0
    y = np.stack([np.asarray(obj.data["y_th"]), np.asarray(obj.data["y_d"])])
    z0 = np.concatenate([U0, np.zeros(4 * L) if off0 is None else np.ravel(off0)])
    lo = np.concatenate([np.zeros(n), np.full(4 * L, -5.0)])
    hi = np.concatenate([np.ones(n), np.full(4 * L, 5.0)])
    free = np.arange(nz) if free_params else np.arange(n, nz)
    nf = free.size
    Db = np.tile(D, (nf + 1, 1))
    cache: dict = {}

    def split(Z):
        return Z[:, :n], Z[:, n:].reshape(-1, L, 4)

    def full(zf):
        z = z0.copy()
        z[free] = zf
        return z

    def batch(zf):
        key = zf.tobytes()
        if key in cache:
            return cache[key]
        z = full(zf)
        h = np.where(zf + step > hi[free], -step, step)
        Z = np.tile(z, (nf + 1, 1))
        Z[1 + np.arange(nf), free] += h
        U, off = split(Z)
        tr, e, bad = obj.run(U, Db, off)
        sim = np.stack([tr[0], tr[1]])  # (2, P, L, N)
        R = (W[:, None] * (sim - y[:, None])).transpose(1, 0, 2, 3).reshape(nf + 1, -1)
        R = np.where(np.isfinite(R), R, 1e3)
        R[bad.any(-1)] = 1e3 * W.max()
        if free_params:  # the priors' rows (eq. (2)) after the data's
            R = np.concatenate([R, obj.prior_rows(U)], axis=1)
        cache.clear()
        cache[key] = (R[0], ((R[1:] - R[0]) / h[:, None]).T)
        return cache[key]

    t0 = time.perf_counter()
    res = trust_region(
        lambda z: batch(z)[0],
        lambda z: batch(z)[1],
        z0[free],
        lo[free],
        hi[free],
        max_nfev=max_nfev,
        ftol=1e-6,
        xtol=1e-6,
        gtol=1e-8,
    )
    r, Jac = batch(res.x)
    x = full(res.x)
    m_data = mask.size
    Jp = Jac[m_data:]  # the priors' rows: their information joins the covariance
    r, Jac = r[:m_data], Jac[:m_data]
    keep = mask.ravel()
    r = np.where(keep, r, 0.0)
    Jac = np.where(keep[:, None], Jac, 0.0)
    rr = r[keep]
    rho = float(np.clip(np.sum(rr[1:] * rr[:-1]) / max(rr @ rr, 1e-300), 0.0, 0.999))
    std_u = std_iid_u = np.full(n, np.nan)
    cov_u = np.full((n, n), np.nan)
    bw: list = []
    if free_params:
        try:
            cov_iid = iid_covariance(rr, Jac[keep])
            # in eq. (1)'s units (V's residuals / s) where priors weigh in: the data's own
            # sandwich does not depend on the units, the prior's information does
            s = obj.prior_scale() if Jp.size else 1.0
            cov, bw = hac_covariance(
                r.reshape(2, L, -1) / s,
                Jac.reshape(2, L, -1, nz) / s,
                prior_jac=Jp / s if Jp.size else None,
            )
            std_u = np.sqrt(np.maximum(np.diag(cov)[:n], 0.0))
            cov_u = cov[:n, :n]
            std_iid_u = np.sqrt(np.maximum(np.diag(cov_iid)[:n], 0.0))
        except np.linalg.LinAlgError:
            bw = []
    U, off = split(x[None])
    return {
        "U": U[0],
        "off": off[0],
        "std_u": std_u,
        "std_iid_u": std_iid_u,
        "cov_u": cov_u,
        "bandwidth": [int(m) for m in bw],
        "status": int(res.status),
        "success": bool(res.status > 0),
        "message": str(res.message),
        "nfev": int(res.nfev),
        "cost": float(2 * res.cost),
        "rho": rho,
        "seconds": time.perf_counter() - t0,
        "at_bounds": [
            i
            for i in range(n)
            if free_params
            and (x[i] < 1e-3 or x[i] > 1 - 1e-3)
            and obj.space.defs[i].scale != "loglin"
        ],
    }


__all__ = ["fit", "FitResult", "FRICTION", "derived"]
