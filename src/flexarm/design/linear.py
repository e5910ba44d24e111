r"""State feedback with an observer for any scenario arm: ``lqr`` and ``place``.

Design model (:func:`design_model`). The scenario's arm (single-link voltage servo, current
drive, multi-link) linearised about rest, friction left out
(:func:`flexarm.models.linearize.linearize`), ẋ = A x + B u; each measured channel i reads
y_i = g_i s_i(x) (g_i the sensor's gain), through its analog first-order low-pass where the
sensor has one, ẏ_f = ω_f (g_i s_i − y_f), ω_f = 2π·bandwidth; sampled with a zero-order hold
at the ``[sampling] period`` T; then augmented with the loop's pure delays as shift registers
(:func:`flexarm.control.lqg.augment_delays`): the computation delay d_c (``[sampling] delay``:
the plant gets u_{k−d_c}) and each sensor's delay d_i (``[sensors.X] delay``: the controller
reads y_i,k−d_i). Size n + m d_c + Σ d_i. A rigid rotation of the joints at rest is an
equilibrium of an arm without stiffness to ground (checked: the null space of A must hold
a state with each tracked channel at 1 and every other channel at 0), so the controller
acts on e = setpoint − measured alone (:mod:`flexarm.control.lqg`).

Regulator u = −K (x̂, q), q the integrators of the tracked channels' measured errors
(option ``integral``: LQI, q⁺ = q + T e_i, :func:`flexarm.control.lqg.integral_model`):

* ``lqr``: K = ``control.dlqr(A_r, B_r, Q, R)`` with Q = C_uᵀ diag(q_i) C_u + diag(q_I)
  on the channels' undelayed outputs C_u and the integrators, R = diag(r). Defaults by
  Bryson's rule, q_i = 1 / s_i², r = 1 / u_max²: s = the reference step amplitude |a| for a
  tracked channel (rad), 0.3 |a| L g_i for a tip deflection in m (0.3 |a| g_i for a
  deflection angle: 30 % of the tip's travel, :data:`DEFLECTION_FRACTION`), |a| × 0.2 s
  for an integrator (rad·s, :data:`INTEGRAL_TIME`),
  u_max the actuator limit (V or A); R then scaled up (ρ ≥ 1) until the linear loop's
  peak command for the step is within 90 % of the limit (``fit_limit``);
* ``place``: K by ``control.place`` on the states the feedback acts through (arm, input
  registers, registers of the integrated channels, integrators), the poles given for the arm
  (and integrator) states, as continuous-time s (z = e^{sT}, ``pole_domain="s"``) or discrete
  z, the delay registers at z = 0; the other registers get no gain (their poles stay at 0).

Integral action by default without integrators (``disturbance``): the observer also
estimates a constant disturbance d per input, entering the arm as the command does
(:func:`disturbance_model`: z⁺ = A z + B u + G d, d⁺ = d), and the command cancels it,
u = −K x̂ − d̂. A hub held by friction short of its setpoint does not move although the
model says it should: d̂ grows until it breaks free, so there is no rest short of the
setpoint; a reference step, in the two-degrees-of-freedom form below, is no disturbance
and winds nothing up (LQI's integrators do: its steps overshoot).

Reference (``two_dof``, default): the controller reads every channel against 0 and the
tracked channels also against their references (extra inputs e_r = r − y), so
u = −K (x̂ − Z r) − d̂, Z r the state at rest at the reference
(:func:`flexarm.control.lqg.observer_controller`): a step is an error of the regulator's
state, not a jump the observer must explain.

Observer (predictor) x̂⁺ = A x̂ + B u + L (y − C x̂) on the augmented model: a Kalman
predictor ``control.dlqe`` (default) with V = diag(σ_i² + q_i²/12) from the sensors' noise
σ_i and quantum q_i, and a process noise entering as the command does, W = B_d σ_d² B_dᵀ,
σ_d = max(Coulomb level, 2 % of the limit) in command units (the unmodelled friction torque),
and a random walk of the disturbance state of σ_d per 0.1 s (:data:`DISTURBANCE_TIME`),
or placed poles (``observer_poles``, count and domain as for ``poles``, registers at 0).

Result (:class:`~flexarm.design.result.Design`): the controller e → u as a discrete
python-control ``StateSpace`` (:func:`flexarm.control.lqg.observer_controller`, dt = T) and
the scenario with it as ``[controller] type = "lti"``, plus Feliu's Coulomb feedforward
``[controller.friction_compensation] level = C_f / k_u`` (k_u the drive's torque per unit
command, :mod:`flexarm.models.motor`; single-joint arms). ``info`` holds K, L, the
regulator, observer and closed-loop poles (checked: the loop of the augmented model and the
controller has exactly the regulator's and the observer's, separation principle), their
damping and natural frequency, the sizes and the weights, and the linear loop's response to
a reference step of the scenario's amplitude (peak command, settling): a warning when the
peak command plus the friction feedforward exceeds the actuator limit.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field

import control
import numpy as np
import scipy.linalg

from flexarm.control.lqg import (
    augment_delays,
    input_rows,
    integral_model,
    loop_poles,
    lti_controller_spec,
    observer_controller,
)
from flexarm.design.result import Design

__all__ = ["DesignModel", "design_model", "design_linear", "separation_check", "step_response"]

#: Bryson scale of a deflection channel as a fraction of the tip's travel. Unit 6 fit, 0.8 rad
#: step, default design: tip 2 % settling 1.01 s and 7 % overshoot at 0.3; 0.84 s and 19 %
#: at 1.0 (tighter values slow the rigid mode down under the command limit).
DEFLECTION_FRACTION = 0.3
#: Bryson scale of an integrator: amplitude × this time (s).
INTEGRAL_TIME = 0.2
#: Time (s) in which the estimated input disturbance may change by σ_d (``disturbance``).
DISTURBANCE_TIME = 0.1
#: Process noise σ_d: at least this fraction of the command limit.
DISTURBANCE_FRACTION = 0.02


@dataclass
class DesignModel:
    """The linear design model of a scenario's loop (module docstring)."""

    channels: list[str]  #: measured channels, the controller's inputs
    signals: list[str]  #: plant signal each channel reads
    setpoints: list[str | None]  #: reference channel of each channel (None: 0)
    tracked: list[int]  #: channels whose setpoint was asked for (integrators, step sizes)
    continuous: control.StateSpace  #: arm + analog sensor filters, outputs = the channels
    sampled: control.StateSpace  #: zero-order hold at T
    augmented: control.StateSpace  #: + computation and sensor delays
    dt: float
    computation_delay: int
    sensor_delays: list[int]
    quanta: list[float]
    noise: list[float]
    limit: np.ndarray  #: command limit per input
    k_u: np.ndarray  #: drive torque per unit command, per input (N·m/V or N·m/A)
    coulomb: np.ndarray  #: joint Coulomb level, per joint (N·m)
    amplitude: dict[str, float]  #: reference step amplitude per tracked channel
    scales: list[float]  #: Bryson scale of each channel
    #: (n_aug, n_tracked): the augmented state of a unit shift of each tracked channel at rest
    rigid: np.ndarray
    added_sensors: dict[str, dict] = field(default_factory=dict)

    @property
    def n_arm(self) -> int:
        return self.continuous.nstates


def _amplitude(scenario, ref: str | None) -> float:
    spec = scenario.reference if ref == "reference" else scenario.references.get(ref)
    a = abs(float(getattr(spec, "amplitude", 0.0) or 0.0)) if spec is not None else 0.0
    return a if a > 0 else 0.1


#: the largest command limit a design takes (V or A): its weights and noise scale with the
#: limit squared; an amplifier's limit is far below (issue #45: 1e300 V overflowed)
MAX_LIMIT = 1e6


def check_drive(name: str, limit, k_u, coulomb) -> None:
    """The drive's numbers a design can work with (issue #45), each refused as one
    ``ValueError`` line naming the field: a command limit above :data:`MAX_LIMIT`, and a
    joint whose Coulomb friction (N·m, or N for a linear axis) needs more command than
    the limit (C_f / k_u ≥ limit: the drive could never move it; 1e4 N·m was a unit
    slip)."""
    limit = np.asarray(limit, float).reshape(-1)
    for j, lim in enumerate(limit):
        if lim > MAX_LIMIT:
            raise ValueError(
                f"scenario {name!r}: the command limit {lim:g} (V or A) of joint {j + 1} is "
                f"beyond any amplifier (a design takes at most {MAX_LIMIT:g}); give the "
                "amplifier's limit ([arm.motor] voltage_limit / current_limit, or [actuator] "
                "limit)"
            )
    k_u = np.asarray(k_u, float).reshape(-1)
    coulomb = np.asarray(coulomb, float).reshape(-1)
    if coulomb.size != limit.size or k_u.size != limit.size:
        return
    for j, (c, k, lim) in enumerate(zip(coulomb, k_u, limit, strict=True)):
        if c > 0 and k > 0 and c / k >= lim:
            raise ValueError(
                f"scenario {name!r}: joint {j + 1}'s Coulomb friction {c:g} (N*m, or N for a "
                f"linear axis) needs {c / k:g} of command to overcome, at or beyond the "
                f"limit {lim:g} (V or A): the drive could never move the joint; check "
                "arm.friction.coulomb and its unit, or the limit"
            )


def design_model(scenario, measured=None, setpoints: dict[str, str] | None = None) -> DesignModel:
    """The design model of ``scenario`` (module docstring).

    ``measured``: the channels the controller reads: a list of the scenario's
    ``[sensors]`` names, or a dict channel → plant signal (channels the scenario lacks are
    added as plain sensors); default: every sensor channel without a digital filter (the
    joint angles when there are none). ``setpoints``: channel → reference channel; default
    the scenario's ``lti`` controller's, else ``reference`` on the single link's hub angle,
    ``theta_ref_j`` on a multi-link arm's joint angle j."""
    from flexarm.models.linearize import linearize
    from flexarm.sim.build import sensor_quanta

    if scenario.sampling is None:
        raise ValueError(
            f"scenario {scenario.name!r}: no [sampling]; the design needs the "
            "controller's period (add [sampling] period = ...)"
        )
    dt = float(scenario.sampling.period)
    if scenario.arm.kind == "multi_link":
        from flexarm.models.assembly import multi_link_arm

        arm, _ = multi_link_arm(scenario.arm)
        limit = np.asarray(arm.limit, float).reshape(-1)
        length = None
    else:
        from flexarm.models.single_link import SingleLinkModel

        arm = SingleLinkModel.from_spec(scenario.arm).plant()
        limit = np.asarray(arm.limit, float).reshape(-1)
        length = float(getattr(scenario.arm.beam, "length", 0.0) or 0.0) or None
    if scenario.actuator.limit is not None:
        limit = np.minimum(limit, float(scenario.actuator.limit))
    if not np.all(np.isfinite(limit)):
        raise ValueError(
            f"scenario {scenario.name!r}: the command limit is not finite; give "
            "[actuator] limit (V or A): the design's R and its check need it"
        )
    sensors = {k: v.model_dump() for k, v in scenario.sensors.items()}
    added: dict[str, dict] = {}
    if measured is None:
        # every sensor of a plant signal (not a digitally filtered one, not the drive's
        # command recorded as a channel: a design reads the plant)
        chans = [
            k
            for k, s in sensors.items()
            if not s.get("filter") and (s.get("signal") or k) in arm.signal_names
        ]
        if not chans:
            chans = [n for n in arm.signal_names[: arm.n_joints]]
            added = {c: {} for c in chans}
    elif isinstance(measured, dict):
        chans = list(measured)
        for c, sig in measured.items():
            if c in sensors:
                if (sensors[c].get("signal") or c) != sig:
                    raise ValueError(
                        f"measured: channel {c!r} reads "
                        f"{sensors[c].get('signal') or c!r} in the scenario, not "
                        f"{sig!r}; give another channel name"
                    )
            else:
                added[c] = {"signal": sig}
    else:
        chans = list(measured)
        for c in chans:
            if c not in sensors:
                raise ValueError(
                    f"measured: {c!r} is not a sensor channel of scenario "
                    f"{scenario.name!r}; its channels: {', '.join(sensors) or 'none'} "
                    "(give a dict channel → signal to add one)"
                )
    if not chans:
        raise ValueError("measured: no channel to read; name at least the joint angle(s)")
    spec_of = {c: {**sensors.get(c, {}), **added.get(c, {})} for c in chans}
    for c in chans:
        if spec_of[c].get("filter"):
            raise ValueError(
                f"sensor {c!r} has a digital filter, which the design model does "
                "not include; leave it out of measured (e.g. --measured with the "
                "unfiltered channels)"
            )
    from flexarm.specs.experiment import Sensor

    quanta_all = sensor_quanta({c: Sensor.model_validate(spec_of[c]) for c in chans})
    signals = [spec_of[c].get("signal") or c for c in chans]
    for c, s in zip(chans, signals, strict=True):
        if s not in arm.signal_names:
            raise ValueError(
                f"sensor {c!r}: the arm has no signal {s!r}; its signals: "
                f"{', '.join(arm.signal_names)}"
            )
    uniq = list(dict.fromkeys(signals))
    lin = linearize(arm, outputs=uniq)
    A, B = np.asarray(lin.A), np.asarray(lin.B)
    Cs = np.asarray(lin.C)
    gains = [float(spec_of[c].get("gain", 1.0)) for c in chans]
    bw = [float(spec_of[c].get("bandwidth", 0.0) or 0.0) for c in chans]
    n, m, p = A.shape[0], B.shape[1], len(chans)
    filt = [i for i in range(p) if bw[i] > 0]
    N = n + len(filt)
    Ac, Bc, Cc = np.zeros((N, N)), np.zeros((N, m)), np.zeros((p, N))
    Ac[:n, :n], Bc[:n] = A, B
    names = list(lin.state_labels)
    for j, i in enumerate(filt):
        w = 2 * math.pi * bw[i]
        Ac[n + j, :n] = w * gains[i] * Cs[uniq.index(signals[i])]
        Ac[n + j, n + j] = -w
        Cc[i, n + j] = 1.0
        names.append(f"filter_{chans[i]}")
    for i in range(p):
        if i not in filt:
            Cc[i, :n] = gains[i] * Cs[uniq.index(signals[i])]
    cont = control.ss(
        Ac,
        Bc,
        Cc,
        np.zeros((p, m)),
        states=names,
        inputs=list(lin.input_labels),
        outputs=chans,
        name="design model",
    )
    sysd = control.c2d(cont, dt, "zoh")
    sysd = control.ss(
        sysd.A,
        sysd.B,
        sysd.C,
        sysd.D,
        dt,
        states=names,
        inputs=list(lin.input_labels),
        outputs=chans,
        name="design model, sampled",
    )
    delays = [int(spec_of[c].get("delay", 0) or 0) for c in chans]
    aug = augment_delays(sysd, int(scenario.sampling.delay), delays)

    # setpoints
    sp: dict[str, str] = {}
    ctrl = scenario.controller
    if setpoints is not None:
        sp = dict(setpoints)
    elif getattr(ctrl, "type", None) == "lti" and ctrl.setpoints is not None:
        sp = {i: s for i, s in zip(ctrl.inputs, ctrl.setpoints, strict=True) if isinstance(s, str)}
    elif scenario.arm.kind != "multi_link":
        hub = next((c for c, s in zip(chans, signals, strict=True) if s == "motor_angle"), None)
        sp = {hub: "reference"} if hub else {}
    else:
        for j in range(arm.n_joints):
            ref = f"theta_ref_{j + 1}"
            c = next(
                (c for c, s in zip(chans, signals, strict=True) if s == f"theta_{j + 1}"), None
            )
            if c is not None and ref in scenario.references:
                sp[c] = ref
    sp = {c: r for c, r in sp.items() if c is not None and c in chans}
    if not sp:
        raise ValueError(
            f"scenario {scenario.name!r}: no measured channel has a setpoint; give "
            "setpoints (channel = reference channel), e.g. motor_angle=reference"
        )
    refs = {"reference", *scenario.references}
    for c, r in sp.items():
        if r not in refs:
            raise ValueError(
                f"setpoints: {c} = {r!r} is not a reference channel of the "
                f"scenario; it has {', '.join(sorted(refs))}"
            )
    spl = [sp.get(c) for c in chans]
    tracked = [i for i, s in enumerate(spl) if s]
    amp = {chans[i]: _amplitude(scenario, spl[i]) for i in tracked}
    follow, v = _rigid_rotation(Ac, Cc, chans, tracked, scenario.name)
    # the same shift in the augmented state: input registers 0, output registers C_i v
    rigid = np.zeros((aug.nstates, v.shape[1]))
    rigid[:N] = v
    k = N + m * int(scenario.sampling.delay)
    for i, d in enumerate(delays):
        rigid[k : k + d] = Cc[i] @ v
        k += d
    for i, j in follow.items():
        spl[i] = spl[j]

    scales = []
    for i, _c in enumerate(chans):
        if i in tracked or i in follow:
            scales.append(amp[chans[follow.get(i, i)]] * abs(gains[i]))
        else:
            a = max(amp.values())
            travel = a * (length if signals[i] == "tip_deflection" and length else 1.0)
            scales.append(DEFLECTION_FRACTION * travel * abs(gains[i]))
    k_u = np.asarray(arm.k_u, float).reshape(-1)
    coulomb = np.asarray(
        [float(np.asarray(f.coulomb)) if f.model != "none" else 0.0 for f in arm.frictions]
    )
    check_drive(scenario.name, limit, k_u, coulomb)
    return DesignModel(
        chans,
        signals,
        spl,
        tracked,
        cont,
        sysd,
        aug,
        dt,
        int(scenario.sampling.delay),
        delays,
        [float(quanta_all[c]) for c in chans],
        [float(spec_of[c].get("noise", 0.0) or 0.0) for c in chans],
        limit,
        k_u,
        coulomb,
        amp,
        scales,
        rigid,
        added,
    )


def _rigid_rotation(A, C, chans, tracked, name) -> tuple[dict[int, int], np.ndarray]:
    """Each tracked channel j must be shiftable at rest: a state v with A v = 0, C_j v = 1,
    the other tracked channels at 0. An untracked channel i must read 0 there, or 1 (it
    reads the same angle, e.g. a tip angle: it then takes j's setpoint); returns
    {i: j} for those and the states v (columns, one per tracked channel)."""
    Nsp = scipy.linalg.null_space(A, rcond=1e-10)
    follow: dict[int, int] = {}
    vs = []
    for j in tracked:
        rows = list(tracked)
        target = np.zeros(len(rows))
        target[rows.index(j)] = 1.0
        v = None
        if Nsp.size:
            a, *_ = np.linalg.lstsq(C[rows] @ Nsp, target, rcond=None)
            if np.abs(C[rows] @ Nsp @ a - target).max() <= 1e-6:
                v = Nsp @ a
                vs.append(v)
        if v is None:
            raise ValueError(
                f"scenario {name!r}: channel {chans[j]!r} cannot rest at an arbitrary setpoint "
                "(the arm has a stiffness to ground, e.g. gravity, or the tracked channels read "
                "one angle); the error-form design needs a horizontal arm (gravity = 0)"
            )
        for i in range(len(chans)):
            if i in tracked:
                continue
            c = float(C[i] @ v)
            if abs(c) <= 1e-6:
                continue
            if abs(c - 1.0) <= 1e-6 and i not in follow:
                follow[i] = j
                continue
            raise ValueError(
                f"scenario {name!r}: channel {chans[i]!r} reads {c:.6g} per unit of "
                f"{chans[j]!r} at rest, so its setpoint is neither 0 nor {chans[j]!r}'s; leave "
                "it out of measured or give its gain"
            )
    return follow, np.stack(vs, axis=1)


# ----------------------------------------------------------------------------- gains
def _poles_z(poles, domain: str, dt: float, what: str) -> np.ndarray:
    if domain not in ("s", "z"):
        raise ValueError(
            f"pole_domain = {domain!r}; give 's' (continuous-time poles, rad/s, "
            "mapped by z = exp(s T)) or 'z' (discrete)"
        )
    p = np.asarray([complex(x) for x in poles])
    if p.size == 0:
        raise ValueError(f"{what}: no poles given")
    z = np.exp(p * dt) if domain == "s" else p
    if np.any(np.abs(z) >= 1.0):
        bad = p[np.abs(z) >= 1.0][0]
        raise ValueError(
            f"{what}: pole {bad:.6g} ({domain}) is not stable (|z| = "
            f"{abs(np.exp(bad * dt) if domain == 's' else bad):.6g} >= 1); give "
            + (
                "poles with a negative real part"
                if domain == "s"
                else "poles inside the unit circle"
            )
        )
    for x in z[np.abs(np.imag(z)) > 1e-12]:
        if not np.any(np.abs(z - np.conj(x)) < 1e-9 * max(1.0, abs(x))):
            raise ValueError(f"{what}: the complex pole {x:.6g} has no conjugate; give both")
    return z


def _place(A, B, poles, what: str) -> np.ndarray:
    try:
        return np.asarray(control.place(A, B, poles))
    except Exception as exc:  # repeated poles beyond rank(B): Ackermann for one input
        if B.shape[1] == 1:
            return np.asarray(control.acker(A, B, poles))
        raise ValueError(f"{what}: pole placement failed ({exc}); give distinct poles") from None


def _weights_matrix(w, n: int, what: str) -> np.ndarray:
    a = np.asarray(w, dtype=float)
    a = np.full(n, float(a)) if a.ndim == 0 else a
    a = np.diag(a) if a.ndim == 1 else a
    if (
        a.shape != (n, n)
        or not np.all(np.isfinite(a))
        or np.any(np.linalg.eigvalsh((a + a.T) / 2) < -1e-12)
    ):
        raise ValueError(f"{what}: give {n} non-negative numbers (or one); got {w!r}")
    return a


def _channel_weights(dm: DesignModel, q, integral: bool) -> tuple[dict, dict]:
    """Per channel (and per integrator ``int_<channel>``) the weight q_i = 1/s_i² (Bryson),
    overridden by ``q`` (dict name → weight, or one number per channel [+ integrators])."""
    w = {c: 1.0 / s**2 if s > 0 else 0.0 for c, s in zip(dm.channels, dm.scales, strict=True)}
    wi = (
        {f"int_{dm.channels[i]}": 1.0 / (INTEGRAL_TIME * dm.scales[i]) ** 2 for i in dm.tracked}
        if integral
        else {}
    )
    if q is None:
        return w, wi
    if isinstance(q, dict):
        for k, v in q.items():
            if k in w:
                w[k] = float(v)
            elif k in wi:
                wi[k] = float(v)
            else:
                raise ValueError(
                    f"q: {k!r} is not a measured channel"
                    + (" or integrator" if integral else "")
                    + "; give one of "
                    + ", ".join([*w, *wi])
                )
    else:
        vals = np.atleast_1d(np.asarray(q, float))
        keys = [*w, *wi]
        if vals.size != len(keys):
            raise ValueError(
                f"q: {vals.size} numbers; give {len(keys)} ({', '.join(keys)}) or "
                "name them, e.g. motor_angle=1e3"
            )
        for k, v in zip(keys, vals, strict=True):
            (w if k in w else wi)[k] = float(v)
    for k, v in {**w, **wi}.items():
        if not (v >= 0 and np.isfinite(v)):
            raise ValueError(f"q: {k} = {v!r}; give a finite weight >= 0")
    return w, wi


# ----------------------------------------------------------------------------- response
def _input_setpoints(dm: DesignModel, controller) -> list[str | None]:
    """The reference channel (or None: 0) of each controller input: the channels' setpoints
    in the one-input form; 0 on every channel and the reference on the ``_ref`` inputs in
    the two-degrees-of-freedom form (:func:`flexarm.control.lqg.observer_controller`)."""
    labels = list(controller.input_labels)
    if not any(lab.endswith("_ref") for lab in labels):
        return list(dm.setpoints)
    return [
        dm.setpoints[dm.channels.index(lab[2:-4])] if lab.endswith("_ref") else None
        for lab in labels
    ]


def step_response(
    dm: DesignModel,
    controller: control.StateSpace,
    n: int,
    amplitude: dict[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """The linear loop (augmented model and ``controller`` on its inputs e = r − M y,
    :func:`flexarm.control.lqg.input_rows`) for a step of the tracked channels' references
    at k = 0 (``amplitude`` per channel; default the scenario's): t (s), the undelayed
    channel outputs ``y`` (n, p), the measured ones ``measured``, the command ``u`` (n, m)
    and the channels' references ``r``; no saturation and no friction."""
    P = dm.augmented
    A, B, C = (np.asarray(a) for a in (P.A, P.B, P.C))
    Ak, Bk, Ck, Dk = (
        np.asarray(a) for a in (controller.A, controller.B, controller.C, controller.D)
    )
    M = input_rows(P, controller)
    nx = dm.sampled.nstates
    Cu = np.asarray(dm.sampled.C)
    amp = dm.amplitude if amplitude is None else amplitude
    by_ref = {dm.setpoints[dm.channels.index(c)]: a for c, a in amp.items()}
    r = np.array([by_ref.get(s, 0.0) if s else 0.0 for s in dm.setpoints])
    w_ref = np.array([by_ref.get(s, 0.0) if s else 0.0 for s in _input_setpoints(dm, controller)])
    z, xi = np.zeros(A.shape[0]), np.zeros(Ak.shape[0])
    ys, ms, us = np.empty((n, C.shape[0])), np.empty((n, C.shape[0])), np.empty((n, B.shape[1]))
    for k in range(n):
        y = C @ z
        e = w_ref - M @ y
        u = Ck @ xi + Dk @ e
        ys[k], ms[k], us[k] = Cu @ z[:nx], y, u
        xi = Ak @ xi + Bk @ e
        z = A @ z + B @ u
    return {"t": np.arange(n) * dm.dt, "y": ys, "measured": ms, "u": us, "r": r}


def _pole_table(z: np.ndarray, dt: float) -> list[dict[str, float]]:
    out = []
    for p in sorted(z, key=lambda v: (-abs(v), v.imag)):
        s = cmath.log(p) / dt if abs(p) > 1e-300 else complex(-np.inf)
        wn = abs(s) if np.isfinite(s.real) else float("inf")
        zeta = -s.real / wn if wn and np.isfinite(wn) else 1.0
        out.append(
            {
                "re": float(p.real),
                "im": float(p.imag),
                "abs": float(abs(p)),
                "natural_frequency": float(wn),
                "damping": float(zeta),
            }
        )
    return out


def _settling(t, y, goal, band=0.02) -> float | None:
    out = np.nonzero(np.abs(y - goal) > band * abs(goal))[0]
    if out.size == 0:
        return 0.0
    return None if out[-1] == len(y) - 1 else float(t[out[-1] + 1])


# ----------------------------------------------------------------------------- design
def _regulator(dm: DesignModel, Ar, Br, idx, method, q, r, poles, pole_domain, rho=1.0):
    """K of the regulator model (A_r, B_r) (module docstring), the weights or poles used, and
    the poles asked for (place; None for lqr). ``rho`` multiplies R (lqr)."""
    P = dm.augmented
    na, m, p = P.nstates, P.ninputs, P.noutputs
    nx, ni = dm.sampled.nstates, len(idx)
    if method == "lqr":
        w, wi = _channel_weights(dm, q, bool(idx))
        Cu = np.zeros((p, na))
        Cu[:, :nx] = np.asarray(dm.sampled.C)
        Q = np.zeros((na + ni, na + ni))
        Q[:na, :na] = Cu.T @ np.diag([w[c] for c in dm.channels]) @ Cu
        for j, i in enumerate(idx):
            Q[na + j, na + j] = wi[f"int_{dm.channels[i]}"]
        R = rho * _weights_matrix(1.0 / dm.limit**2 if r is None else r, m, "r")
        # Cᵀ W C is symmetric; its rounding need not be (python-control checks it), so
        # take the symmetric part
        K, _, _ = control.dlqr(Ar, Br, 0.5 * (Q + Q.T), R)
        return (
            np.asarray(K),
            {
                "q": w,
                "q_integral": wi,
                "r": np.diag(R).tolist(),
                "rule": ("Bryson (1/scale²)" if q is None and r is None else "given"),
                "scales": dict(zip(dm.channels, dm.scales, strict=True)),
            },
            None,
        )
    zp = _poles_z(poles, pole_domain, dm.dt, "poles")
    if zp.size != nx + ni:
        raise ValueError(
            f"poles: {zp.size} given; give {nx + ni}: one per state of the "
            f"arm's model ({', '.join(dm.continuous.state_labels)})"
            + (f" and one per integrator ({ni})" if ni else "")
        )
    # states the feedback acts through: arm, input registers, the integrated channels'
    # registers, integrators; the other output registers get no gain (poles stay at 0)
    keep = list(range(nx + m * dm.computation_delay))
    start = nx + m * dm.computation_delay
    for i, d in enumerate(dm.sensor_delays):
        if i in idx:
            keep += list(range(start, start + d))
        start += d
    keep += list(range(na, na + ni))
    allp = np.concatenate([zp, np.zeros(len(keep) - zp.size)])
    Kred = _place(Ar[np.ix_(keep, keep)], Br[keep], allp, "poles")
    K = np.zeros((m, na + ni))
    K[:, keep] = Kred
    given = [complex(v) for v in poles]
    return (
        K,
        {"poles": [[v.real, v.imag] for v in given], "pole_domain": pole_domain},
        np.concatenate([allp, np.zeros(na + ni - len(keep))]),
    )


def disturbance_model(dm: DesignModel) -> control.StateSpace:
    """The augmented model with a constant disturbance d per input entering the arm as its
    command does (a torque offset in command units: friction bias, a stuck gear train):
    z⁺ = A z + B u + G d, d⁺ = d, y = C z (G: the arm's rows of B, not delayed)."""
    P = dm.augmented
    A, B, C = (np.asarray(a) for a in (P.A, P.B, P.C))
    na, m = B.shape
    p = C.shape[0]
    G = np.zeros((na, m))
    G[: dm.sampled.nstates] = np.asarray(dm.sampled.B)
    Ae = np.block([[A, G], [np.zeros((m, na)), np.eye(m)]])
    return control.ss(
        Ae,
        np.vstack([B, np.zeros((m, m))]),
        np.hstack([C, np.zeros((p, m))]),
        np.zeros((p, m)),
        P.dt,
        states=list(P.state_labels) + [f"disturbance_{k}" for k in P.input_labels],
        inputs=list(P.input_labels),
        outputs=list(P.output_labels),
        name="augmented model with input disturbance",
    )


def _observer(dm: DesignModel, plant, level, observer_poles, pole_domain, warnings):
    """L of the predictor on ``plant`` (the augmented model, or :func:`disturbance_model`)
    and what it was designed with."""
    A, C = np.asarray(plant.A), np.asarray(plant.C)
    ne, m = plant.nstates, plant.ninputs
    na = dm.augmented.nstates
    nd = ne - na  # disturbance states
    nx = dm.sampled.nstates
    if observer_poles is not None:
        zo = _poles_z(observer_poles, pole_domain, dm.dt, "observer_poles")
        if zo.size != nx + nd:
            raise ValueError(
                f"observer_poles: {zo.size} given; give {nx + nd}, one per state "
                f"of the arm's model ({', '.join(dm.continuous.state_labels)})"
                + (f" and one per disturbance ({nd})" if nd else "")
                + "; the delay registers get z = 0"
            )
        L = _place(A.T, C.T, np.concatenate([zo, np.zeros(ne - zo.size)]), "observer_poles").T
        return L, {"kind": "placed", "poles": [[float(x.real), float(x.imag)] for x in zo]}
    V = np.array([s**2 + qq**2 / 12 for s, qq in zip(dm.noise, dm.quanta, strict=True)])
    for i, v in enumerate(V):
        if v <= 0:
            V[i] = (1e-3 * dm.scales[i]) ** 2
            warnings.append(
                f"sensor {dm.channels[i]!r} has neither noise nor quantum: the "
                f"observer assumes σ = {math.sqrt(V[i]):.3g} (0.1 % of its scale); "
                "give [sensors] noise or quantum for a Kalman gain that fits the rig"
            )
    sd = np.maximum(level, DISTURBANCE_FRACTION * dm.limit)
    G = np.zeros((ne, m))
    G[:nx] = np.asarray(dm.sampled.B)
    W = G @ np.diag(sd**2) @ G.T
    for j in range(nd):  # a disturbance state walks by σ_d per DISTURBANCE_TIME
        W[na + j, na + j] = sd[j] ** 2 * dm.dt / DISTURBANCE_TIME
    W += 1e-9 * float(np.max(np.diag(W))) * np.eye(ne)
    L, _, _ = control.dlqe(A, np.eye(ne), C, W, np.diag(V))
    return np.asarray(L), {
        "kind": "Kalman predictor",
        "V": V.tolist(),
        "disturbance_sigma": sd.tolist(),
    }


def separation_check(dm: DesignModel, K, L, controller, integral, observer_plant=None) -> float:
    """The separation principle, checked on the matrices: the loop of the augmented model
    and ``controller`` (states ẑ of ``observer_plant``, default the augmented model, then
    the integrators q) in the coordinates (z, q, ε = E z − ẑ) (E: z into the observer's
    state, disturbances 0) must be block triangular, [[A_r − B_r K, ·], [0, A_o − L C_o]];
    the largest deviation of those blocks (relative to the loop matrix's norm). Its
    eigenvalues are then exactly the regulator's and the observer's."""
    P = dm.augmented
    Po = P if observer_plant is None else observer_plant
    A, B, C = (np.asarray(a) for a in (P.A, P.B, P.C))
    Ao, Co = np.asarray(Po.A), np.asarray(Po.C)
    Ak, Bk, Ck, Dk = (
        np.asarray(a) for a in (controller.A, controller.B, controller.C, controller.D)
    )
    MC = input_rows(P, controller) @ C
    na, ne, nk = A.shape[0], Ao.shape[0], Ak.shape[0]
    ni = nk - ne
    M = np.block([[A - B @ Dk @ MC, B @ Ck], [-Bk @ MC, Ak]])  # states (z, ẑ, q)
    # (z, q, ε) → (z, ẑ, q): ẑ = E z − ε
    T = np.zeros((na + nk, na + nk))
    T[:na, :na] = np.eye(na)
    T[na : na + ne, :na], T[na : na + ne, na + ni :] = np.eye(ne, na), -np.eye(ne)
    T[na + ne :, na : na + ni] = np.eye(ni)
    Mt = np.linalg.solve(T, M @ T)
    Ar, Br = integral_model(P, integral)
    dev = max(
        np.abs(Mt[na + ni :, : na + ni]).max(initial=0.0),
        np.abs(Mt[: na + ni, : na + ni] - (Ar - Br @ K)).max(),
        np.abs(Mt[na + ni :, na + ni :] - (Ao - L @ Co)).max(),
    )
    return float(dev / max(np.abs(M).max(), 1.0))


# ----------------------------------------------------------------------------- design
def design_linear(
    scenario,
    method: str = "lqr",
    *,
    q=None,
    r=None,
    poles=None,
    observer_poles=None,
    pole_domain: str = "s",
    integral: bool = False,
    friction_compensation: bool = True,
    measured=None,
    setpoints=None,
    disturbance: bool | None = None,
    fit_limit: bool = True,
    two_dof: bool = True,
    check_seconds: float = 3.0,
) -> Design:
    """``lqr`` or ``place`` state feedback with an observer for ``scenario``'s arm (module
    docstring); a :class:`~flexarm.design.result.Design`.

    ``q``: output weights (dict channel or ``int_<channel>`` → weight, or one number per
    channel then per integrator; default Bryson); ``r``: command weight (one number or one
    per input; default 1 / limit²); ``fit_limit`` (lqr): when the peak command of the linear
    loop's step (plus the friction feedforward) exceeds 90 % of the limit, R is scaled up by
    the smallest factor ρ ≥ 1 (bisection on log ρ, to 2 %) that brings it there;
    ``poles``: for ``place``, the closed-loop poles of the arm's states (and the
    integrators with ``integral``), in ``pole_domain`` ``"s"`` (rad/s) or ``"z"``;
    ``observer_poles``: the observer's poles for the arm's states (default a Kalman
    predictor); ``integral``: integrate the tracked channels' errors (LQI);
    ``disturbance`` (default: unless ``integral``): estimate a constant input disturbance
    and cancel it (integral action that a reference step does not wind up);
    ``friction_compensation``: add the Coulomb feedforward C_f / k_u; ``two_dof``: the
    reference enters as the state it asks for (extra inputs e_r = r − y of the tracked
    channels, :func:`flexarm.control.lqg.observer_controller`) instead of through the
    observer as an error (False: e → u alone, one degree of freedom); ``measured``,
    ``setpoints``: see :func:`design_model`; ``check_seconds``: length of the linear step
    response whose peak command is checked against the limit."""
    from flexarm.specs.scenario import scenario_from_dict

    if method not in ("lqr", "place"):
        raise ValueError(f"method = {method!r}; design_linear does lqr or place")
    if method == "lqr" and poles is not None:
        raise ValueError("poles: only for method = 'place'; lqr takes q and r")
    if method == "place" and (q is not None or r is not None):
        raise ValueError("q, r: only for method = 'lqr'; place takes poles")
    if method == "place" and poles is None:
        raise ValueError(
            "poles: method = 'place' needs the closed-loop poles of the arm's "
            "states (e.g. poles = [-20, -25, -8+15j, -8-15j]; see info)"
        )
    dm = design_model(scenario, measured, setpoints)
    P = dm.augmented
    m = P.ninputs
    idx = dm.tracked if integral else []
    Ar, Br = integral_model(P, idx)
    warnings: list[str] = []
    level = dm.coulomb / dm.k_u if dm.coulomb.size == m else np.zeros(m)

    # friction feedforward
    fc = None
    if friction_compensation:
        if m != 1 or len(dm.coulomb) != 1:
            warnings.append(
                "friction compensation: one joint only ([controller."
                "friction_compensation]); left out for this multi-joint arm"
            )
        elif dm.coulomb[0] <= 0:
            warnings.append("friction compensation: the arm has no Coulomb friction; none added")
        else:
            hub = next(
                (dm.channels[i] for i in dm.tracked if dm.signals[i] in ("motor_angle", "theta_1")),
                None,
            )
            if hub is None:
                warnings.append("friction compensation: no measured hub angle channel; none added")
            else:
                fc = {"level": float(level[0]), "measured": hub}
    ff = level if fc else np.zeros(m)
    if disturbance is None:
        disturbance = not integral
    if disturbance and integral:
        raise ValueError(
            "integral and disturbance: both give integral action; choose one "
            "(integral: integrators of the errors, LQI; disturbance: an estimated "
            "constant input disturbance, cancelled)"
        )
    Po = disturbance_model(dm) if disturbance else P
    nd = Po.nstates - P.nstates
    L, obs = _observer(dm, Po, level, observer_poles, pole_domain, warnings)
    Zo = np.vstack([dm.rigid, np.zeros((nd, dm.rigid.shape[1]))])
    n = int(round(check_seconds / dm.dt)) + 1

    def attempt(rho):
        K, weights, wanted = _regulator(dm, Ar, Br, idx, method, q, r, poles, pole_domain, rho)
        # with a disturbance estimate d̂: u = −K x̂ − d̂ (cancelled where it enters)
        Ko = np.hstack([K[:, : P.nstates], np.eye(m)[:, :nd], K[:, P.nstates :]])
        ctrl = observer_controller(
            Po, Ko, L, integral=idx, name=method, reference=((dm.tracked, Zo) if two_dof else None)
        )
        sr = step_response(dm, ctrl, n)
        return K, weights, wanted, ctrl, sr, np.abs(sr["u"]).max(axis=0) + ff

    K, weights, wanted, ctrl, sr, peak = attempt(1.0)
    rho = 1.0
    target = 0.9 * dm.limit
    if method == "lqr" and fit_limit and np.any(peak > target):
        lo, hi = 0.0, 1.0  # log10 ρ: lo too aggressive, hi within the limit
        while True:
            K, weights, wanted, ctrl, sr, peak = attempt(10.0**hi)
            if np.all(peak <= target) or hi > 12:
                break
            lo, hi = hi, hi + 1.0
        while hi - lo > math.log10(1.02):
            mid = 0.5 * (lo + hi)
            if np.all(attempt(10.0**mid)[5] <= target):
                hi = mid
            else:
                lo = mid
        rho = 10.0**hi
        K, weights, wanted, ctrl, sr, peak = attempt(rho)
    weights["rho"] = rho
    weights["observer"] = obs
    if fc:
        # no compensation at rest while the feedback is below what half an encoder count
        # of hub error gives: no chatter on the last count (control/friction_compensation.py)
        # (the regulator's command for a rigid shift of half a count: |K_x Z| q / 2)
        h = dm.channels.index(fc["measured"])
        kp = float(np.abs(K[:, : P.nstates] @ dm.rigid[:, dm.tracked.index(h)])[0])
        fc["rest_deadband"] = 0.5 * dm.quanta[h] * kp
    reg = np.linalg.eigvals(Ar - Br @ K)
    est = np.linalg.eigvals(np.asarray(Po.A) - L @ np.asarray(Po.C))
    cl = loop_poles(P, ctrl)
    sep = separation_check(dm, K, L, ctrl, idx, Po)
    if sep > 1e-9:
        warnings.append(
            f"separation check: the loop deviates from the block-triangular form "
            f"by {sep:.3g} (relative); the closed-loop poles may differ from the "
            "regulator's and observer's"
        )
    if np.abs(reg).max() >= 1 or np.abs(est).max() >= 1:
        warnings.append(
            f"the design is not stable: largest |z| regulator "
            f"{np.abs(reg).max():.6g}, observer {np.abs(est).max():.6g}"
        )
    if np.any(peak > dm.limit * (1 + 1e-9)):
        warnings.append(
            "peak command of the linear loop for a reference step of "
            + ", ".join(f"{a:g}" for a in dm.amplitude.values())
            + f" (+ the friction feedforward): {', '.join(f'{v:.3g}' for v in peak)} exceeds the "
            f"limit {', '.join(f'{v:g}' for v in dm.limit)}; the command saturates"
            + (
                " (lower the tracked channel's weight q or raise r)"
                if method == "lqr"
                else " (give slower poles)"
            )
        )
    settle = {dm.channels[i]: _settling(sr["t"], sr["y"][:, i], sr["r"][i]) for i in dm.tracked}

    data = scenario.model_dump(mode="json", exclude_none=True)
    sens = data.setdefault("sensors", {})
    for c, s in dm.added_sensors.items():
        sens.setdefault(c, s)
    chans = [lab[2:-4] if lab.endswith("_ref") else lab[2:] for lab in ctrl.input_labels]
    spec = lti_controller_spec(ctrl, chans, [s or 0 for s in _input_setpoints(dm, ctrl)])
    if fc:
        spec["friction_compensation"] = fc
    data["controller"] = spec
    data["description"] = (
        f"{scenario.name} with a {method} state feedback and "
        f"{obs['kind'].lower()} observer designed by flexarm"
    )
    sc = scenario_from_dict(data, f"{scenario.name}: the {method} design")

    def cpx(a):
        return [[float(v.real), float(v.imag)] for v in a]

    info = {
        "model": {
            "arm_states": list(dm.continuous.state_labels),
            "n_arm": dm.n_arm,
            "n_augmented": P.nstates,
            "n_integrators": len(idx),
            "n_disturbances": nd,
            "two_dof": two_dof,
            "n_controller": ctrl.nstates,
            "period": dm.dt,
            "computation_delay": dm.computation_delay,
            "sensor_delays": dict(zip(dm.channels, dm.sensor_delays, strict=True)),
            "measured": dm.channels,
            "setpoints": dict(zip(dm.channels, dm.setpoints, strict=True)),
        },
        "weights": weights,
        "K": K.tolist(),
        "L": L.tolist(),
        "regulator_poles": _pole_table(reg, dm.dt),
        "observer_poles": _pole_table(est, dm.dt),
        "closed_loop_poles": cpx(cl),
        "separation_error": sep,
        "placement_error": None if wanted is None else _match(reg, wanted),
        "friction_compensation": fc,
        "step": {
            "amplitude": dm.amplitude,
            "peak_command": peak.tolist(),
            "limit": dm.limit.tolist(),
            "settling_time_2pc": settle,
            "model": "linear loop, no friction or saturation",
        },
    }
    return Design(method, sc, ctrl, info, warnings)


def _match(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance between the eigenvalue sets ``a`` and ``b`` paired one to one
    (optimal assignment); inf when the sizes differ."""
    from scipy.optimize import linear_sum_assignment

    a, b = np.asarray(a), np.asarray(b)
    if a.size != b.size:
        return float("inf")
    d = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(d)
    return float(d[i, j].max())
