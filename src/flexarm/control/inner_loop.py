r"""The motor (inner) loop of Feliu, Rattan & Brown (1993), Sec. IV and Fig. 4.

Control law (one sample k, all angles in rad, currents in A, torques in N·m):

    u_fb = G_cm1(z) [ θ_mr − G_cm2(z) θm ]                               (Fig. 4)
    i_c  = ( Ĉ_t + C_f · σ ) / K                                          (Sec. IV)
    u    = u_fb + i_c

* θ_mr: the commanded motor angle (a reference channel); θm, θt: measured motor and
  tip angles (after the A/D converters).
* Ĉ_t: coupling-torque estimate from the measured bending θm − θt, either a static gain
  (FRB eq. (16); C for the single-mass arm, whose C_t = C (θm − θt)) or a stable
  transfer function Ĉ_t = H(z) (θm − θt). An unstable or undamped H (eq. (15) combined
  with eq. (14) has poles on the imaginary axis, Sec. VI-C.2) is refused.
* C_f σ: the Coulomb friction compensation (Sec. III-B), σ the friction sign:

  - moving (|v̂| > ``velocity_deadband``): σ = sgn v̂, v̂ = (θm,k − θm,k−1)/T the
    backward difference of the measured angle;
  - at rest (|v̂| <= ``velocity_deadband``): σ = sgn u_fb when |u_fb| > ``rest_deadband``,
    else 0. A joint at rest feels static friction opposing the applied torque, which
    (coupling compensated) is K u_fb; compensating in that direction lets a small
    remaining error break the joint free, which is what makes the steady-state error
    vanish (FRB Fig. 11). The rest deadband (default: the feedback current of half an
    A/D count, G_cm1(1) q/2) stops the compensation from chattering when the error is
    below the converter resolution.

Why this structure (the lead in G_cm2, on the measurement)
    With the one-sample computation delay, θm has not moved at the sample where θ_mr
    steps, so the first current is u_0 = G_cm1(∞) Δθ_mr. Later |u_k| <= G_cm1(1) max|e|
    whenever the impulse response of G_cm1 is non-negative (a static gain or a lag:
    partial sums of g_j never exceed Σ g_j = G_cm1(1)), and |e| <= Δθ_mr while
    0 <= G_cm2 θm <= 2 Δθ_mr. So "G_cm1(1) = 15 A/rad limits the peak current, a
    400 mrad step gives 6 A" (FRB Sec. VI-B.2) holds exactly when G_cm1(∞) <= G_cm1(1):
    the phase lead the loop needs sits in G_cm2, in the feedback path, where it brakes
    the motor without kicking the current at the reference step. G_cm2(1) = 1 gives zero
    steady-state error: at rest u_fb = 0 (friction and coupling compensated, the motor
    model has an integrator) means θ_mr = G_cm2(1) θm. :func:`design_inner_loop` imposes
    the peak rule (peak ≤ G_cm1(1)·step) and finds G_cm1 static, G_cm2 a lead.

Design model (FRB eq. (9)): with the coupling and friction compensated,
Ĝ_m(s) = θm/(i − i_c) = K/(s (J s + V)), sampled with a zero-order hold, plus
``delay`` samples of computation delay.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import cast

import control
import equinox as eqx
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.optimize
from jax import Array
from threadpoolctl import threadpool_limits

from flexarm.control.discrete import Controller, Signals, from_transfer_function
from flexarm.control.friction_compensation import friction_sign

__all__ = [
    "InnerLoop",
    "InnerLoopDesign",
    "design_inner_loop",
    "inner_loop",
    "coupling_filter",
    "motor_design_model",
]


# ------------------------------------------------------------------------ realisations
def _realise(g: control.TransferFunction) -> tuple:
    """(A, B, C, D) of a discrete SISO G(z) with at least one state (a static gain gets a
    dummy one, as :func:`~flexarm.control.discrete.from_transfer_function` builds it), so
    every :class:`InnerLoop` has the same pytree structure and shares one compilation."""
    c = from_transfer_function(g)
    return c.A, c.B, c.C, c.D


def _as_discrete(g, dt: float, name: str) -> control.TransferFunction:
    if isinstance(g, (int, float, np.floating)):
        return control.tf([float(g)], [1.0], dt)
    if isinstance(g, control.StateSpace):
        g = control.ss2tf(g)
    if not isinstance(g, control.TransferFunction) or not g.issiso():
        raise TypeError(f"{name} must be a number or a SISO python-control transfer function")
    if g.isctime():
        raise ValueError(f"{name} is continuous-time; give G(z) with dt = {dt} s")
    return g


def coupling_filter(coupling, dt: float, *, margin: float = 1e-3) -> control.TransferFunction:
    r"""The coupling estimate Ĉ_t/(θm − θt) as a discrete transfer function (N·m/rad).

    ``coupling`` is a static gain (N·m/rad, FRB eq. (16)), a discrete H(z), or a
    continuous H(s) (FRB eq. (15) style), sampled with Tustin's map. Refused (ValueError)
    when H has a pole with |z| > 1 − ``margin``: a filter with undamped or unstable poles
    rings on every measurement error ("two imaginary poles that produce undesired
    oscillations and instability when implemented on a computer", FRB Sec. VI-C.2).
    """
    if isinstance(coupling, (int, float, np.floating)):
        return control.tf([float(coupling)], [1.0], dt)
    if isinstance(coupling, control.StateSpace):
        coupling = control.ss2tf(coupling)
    if not isinstance(coupling, control.TransferFunction) or not coupling.issiso():
        raise TypeError("coupling must be a gain (N·m/rad) or a SISO transfer function")
    h = coupling
    if h.isctime():
        sp = np.roots(np.asarray(h.den[0][0], float))
        h = control.sample_system(h, dt, method="tustin")
    else:
        sp = None
    zp = np.roots(np.asarray(h.den[0][0], float))
    bad = np.abs(zp) > 1.0 - margin
    if np.any(bad):
        where = ", ".join(
            f"{p:.4g}" for p in (sp[bad] if sp is not None and sp.size == zp.size else zp[bad])
        )
        raise ValueError(
            "the coupling transfer function cannot be implemented: poles at "
            f"{where} ({'s' if sp is not None else 'z'}-plane) give |z| = "
            f"{', '.join(f'{a:.6f}' for a in np.abs(zp[bad]))} >= 1 − {margin:g} (undamped or "
            "unstable: the estimate would ring on measurement errors, FRB Sec. VI-C.2); "
            "use its static gain (FRB eq. (16)), e.g. control.dcgain(H)"
        )
    return h


# ------------------------------------------------------------------------ the controller
class InnerLoop(Controller):
    """The motor loop of FRB Fig. 4 with friction and coupling feedforward (module doc).

    Fields (SI): realisations of G_cm1 (A/rad), G_cm2 (rad/rad) and the coupling filter
    H (N·m/rad); ``torque_constant`` K (N·m/A), ``coulomb`` C_f (N·m), the switches
    ``friction_on`` / ``coupling_on`` (1.0 or 0.0, traced: switching does not recompile),
    ``velocity_deadband`` (rad/s), ``rest_deadband`` (A), ``dt`` (s).
    Reads ``measured["motor_angle"]``, ``measured["tip_angle"]`` and
    ``reference[self.reference]`` (θ_mr).
    """

    g1: tuple
    g2: tuple
    coupling: tuple
    torque_constant: Array
    coulomb: Array
    friction_on: Array
    coupling_on: Array
    velocity_deadband: Array
    rest_deadband: Array
    dt: Array
    initial_motor_angle: Array
    reference: str = eqx.field(static=True, default="reference")

    measured_signals = ("motor_angle", "tip_angle")

    def init(self):
        def z(r):
            return jnp.zeros(r[1].shape)

        return z(self.g1), z(self.g2), z(self.coupling), self.initial_motor_angle

    @staticmethod
    def _lin(r, x, e):
        A, B, C, D = r
        return jnp.sum(A * x, axis=-1) + B * e, jnp.sum(C * x) + D * e

    def feedback(self, state, measured: Signals, reference: Signals):
        """New filter states and u_fb = G_cm1 [θ_mr − G_cm2 θm] (A)."""
        x1, x2, xc, _ = state
        th = measured["motor_angle"]
        x2n, y2 = self._lin(self.g2, x2, th)
        x1n, u_fb = self._lin(self.g1, x1, reference[self.reference] - y2)
        return x1n, x2n, u_fb

    def step(self, state, measured: Signals, reference: Signals):
        _, _, xc, th_prev = state
        th = measured["motor_angle"]
        x1n, x2n, u_fb = self.feedback(state, measured, reference)
        xcn, c_hat = self._lin(self.coupling, xc, th - measured["tip_angle"])
        v = (th - th_prev) / self.dt
        sigma = friction_sign(v, u_fb, self.velocity_deadband, self.rest_deadband)
        i_c = (
            self.coupling_on * c_hat + self.friction_on * self.coulomb * sigma
        ) / self.torque_constant
        return (x1n, x2n, xcn, th), jnp.reshape(u_fb + i_c, (1,))

    def with_switches(
        self, *, friction: bool | None = None, coupling: bool | None = None
    ) -> InnerLoop:
        """A copy with friction and/or coupling compensation turned on or off (FRB Figs.
        12, 13, 17). Same pytree structure: the compiled loop is reused."""
        out = self
        if friction is not None:
            out = eqx.tree_at(lambda c: c.friction_on, out, jnp.asarray(float(friction)))
        if coupling is not None:
            out = eqx.tree_at(lambda c: c.coupling_on, out, jnp.asarray(float(coupling)))
        return out


def inner_loop(
    gcm1,
    gcm2,
    *,
    dt: float,
    torque_constant: float,
    coulomb: float = 0.0,
    coupling=0.0,
    friction_compensation: bool = True,
    coupling_compensation: bool = True,
    angle_resolution: float = 0.0,
    velocity_deadband: float | None = None,
    rest_deadband: float | None = None,
    reference: str = "reference",
    initial_motor_angle: float = 0.0,
) -> InnerLoop:
    """Build an :class:`InnerLoop`.

    Parameters
    ----------
    gcm1, gcm2: G_cm1(z) (A/rad) and G_cm2(z) (rad/rad), discrete transfer functions
        with sampling period ``dt`` (s), or numbers (static gains).
    torque_constant: K, N·m/A. coulomb: C_f, N·m (the identified Coulomb level).
    coupling: Ĉ_t/(θm − θt): a gain (N·m/rad) or a transfer function, see
        :func:`coupling_filter`.
    friction_compensation, coupling_compensation: the switches of FRB Figs. 12, 13, 17.
    angle_resolution: the motor A/D count (rad), used for the default deadbands:
        ``velocity_deadband`` = q/(2T) (rad/s: below one count per sample the motor is
        taken to be at rest) and ``rest_deadband`` = G_cm1(1) q/2 (A).
    reference: the reference channel holding θ_mr.
    initial_motor_angle: θm at t = 0 (rad), the first velocity estimate's predecessor.
    """
    g1 = _as_discrete(gcm1, dt, "gcm1")
    g2 = _as_discrete(gcm2, dt, "gcm2")
    h = coupling_filter(coupling, dt)
    q = float(angle_resolution)
    if velocity_deadband is None:
        velocity_deadband = 0.5 * q / dt
    if rest_deadband is None:
        rest_deadband = 0.5 * q * abs(float(np.real(control.dcgain(g1))))

    def f(v):
        return jnp.asarray(v, dtype=float)

    return InnerLoop(
        _realise(g1),
        _realise(g2),
        _realise(h),
        f(torque_constant),
        f(coulomb),
        f(float(friction_compensation)),
        f(float(coupling_compensation)),
        f(velocity_deadband),
        f(rest_deadband),
        f(dt),
        f(initial_motor_angle),
        reference,
    )


# ------------------------------------------------------------------------ design
def motor_design_model(model) -> tuple[float, float, float]:
    """(J, V, K) of FRB eq. (9) from a :class:`~flexarm.models.single_link.SingleLinkModel`:
    J the hub inertia (kg·m²), V the viscous coefficient plus a voltage drive's
    back-EMF term (N·m·s/rad), K the drive gain (N·m per unit command)."""
    d = model.drive
    return float(model.J), float(model.V) + float(d.k_omega), float(d.k_u)


@dataclass
class InnerLoopDesign:
    """Result of :func:`design_inner_loop` (SI units)."""

    gcm1: control.TransferFunction  # A/rad
    gcm2: control.TransferFunction  # rad/rad
    dt: float  # s
    delay: int  # samples
    dc_gain: float  # G_cm1(1), A/rad
    settling_time: float  # s, linear design loop, intersample, band of the step
    band: float
    overshoot: float  # fraction of the step, linear design loop
    step: float  # rad, the design step
    peak_current: float  # A, linear loop, design step (feedback part only)
    available_current: float  # A, limit − coupling − friction compensation currents
    current_limit: float  # A
    coupling_current: float  # A, Ĉ · bending / K
    friction_current: float  # A, C_f / K
    params: np.ndarray = field(repr=False)  # (a1, b1, a2, b2): zeros and poles
    time: np.ndarray = field(repr=False)  # s, fine grid of the design response
    response: np.ndarray = field(repr=False)  # θm/step on ``time``
    current: np.ndarray = field(repr=False)  # A per rad of step, at the samples
    # How the search ended (differential evolution within its maxiter budget, then the
    # Nelder–Mead polish): the optimisers' status messages. The design is accepted on the
    # constraints checked after it, not on these.
    search_message: str = ""

    @property
    def peak_current_per_rad(self) -> float:
        """Peak feedback current of the linear loop per rad of step (A/rad)."""
        return self.peak_current / self.step

    @property
    def lag(self) -> float:
        """Equivalent delay of the design loop θm/θ_mr (s): ∫ (1 − y(t)) dt of its unit
        step response y (the first moment of its impulse response)."""
        h = self.time[1] - self.time[0]
        return float(np.sum(1.0 - self.response) * h)

    def closed_loop(self, model) -> control.TransferFunction:
        """θm/θ_mr of the linear design loop (discrete, delay included), its cancelling
        pole-zero pairs removed (``control.minreal``). With a long delay (60 samples and
        more) minreal's rebuild of the closed loop's polynomials from their roots puts
        poles outside the unit circle (the rotary rig's loop at 60 / 86 samples: |z| 1.03 /
        1.45, where the loop's own are within 0.987 / 0.994; issue #46): there the pairs
        are removed from G_cm1·plant before the loop is closed (the delay's poles at z = 0
        exact)."""
        plant = _plant_tf(model, self.dt, self.delay)
        full = control.feedback(self.gcm1 * plant, self.gcm2)
        reduced = control.minreal(full, tol=1e-9, verbose=False)
        if _radius(reduced) <= _radius(full) * (1 + 1e-6) + 1e-12:
            return reduced
        return control.feedback(
            control.minreal(self.gcm1 * plant, tol=1e-9, verbose=False), self.gcm2
        )

    def controller(self, model, **kw) -> InnerLoop:
        """An :class:`InnerLoop` for ``model`` (K, C_f from the model; coupling gain the
        static value of the model's C_t/(θm − θt) unless ``coupling=`` is given)."""
        _, _, k = motor_design_model(model)
        kw.setdefault("coupling", float(np.real(control.dcgain(model.coupling_tf()))))
        kw.setdefault("coulomb", float(model.friction.coulomb))
        return inner_loop(self.gcm1, self.gcm2, dt=self.dt, torque_constant=k, **kw)


def _radius(g: control.TransferFunction) -> float:
    """max |pole| of a SISO transfer function: the roots of its denominator's coefficients
    (``TransferFunction.poles`` goes through a common denominator rebuilt from roots, which
    at a long delay misplaces them as minreal does)."""
    den = np.trim_zeros(np.asarray(g.den[0][0], float), "f")
    return float(np.max(np.abs(np.roots(den)), initial=0.0))


def _plant_tf(model, dt: float, delay: int) -> control.TransferFunction:
    J, V, K = motor_design_model(model)
    g = control.tf([K], [J, V, 0.0])
    z = control.tf([1.0, 0.0], [1.0], dt)
    return control.sample_system(g, dt, method="zoh") * (1 / z) ** delay


def _comp(a: float, b: float, gain_at_1: float, dt: float) -> control.TransferFunction:
    k = gain_at_1 * (1.0 - b) / (1.0 - a)
    if abs(a - b) < 1e-12:
        return control.tf([gain_at_1], [1.0], dt)
    return control.tf([k, -k * a], [1.0, -b], dt)


#: from this many samples of delay on, :class:`_StepEvaluator` runs a block of ``delay``
#: samples at a time (below, sample by sample is quicker)
BLOCK_DELAY = 8


class _StepEvaluator:
    """Linear step response of Fig. 4 on eq. (9), sampled with ZOH, with ``delay``
    samples of delay; θm also between samples (``sub`` points per period)."""

    def __init__(self, J: float, V: float, K: float, dt: float, delay: int, n: int, sub: int = 10):
        A = np.array([[0.0, 1.0], [0.0, -V / J]])
        B = np.array([0.0, K / J])

        def zoh(h):
            m = np.zeros((3, 3))
            m[:2, :2], m[:2, 2] = A * h, B * h
            e = scipy.linalg.expm(m)
            return e[:2, :2], e[:2, 2]

        self.Ad, self.Bd = zoh(dt)
        fine = [zoh(dt * j / sub) for j in range(sub)]
        self.Phi = np.array([f[0][0] for f in fine])  # (sub, 2): θ row
        self.Gam = np.array([f[1][0] for f in fine])  # (sub,)
        self.delay, self.n, self.sub, self.dt = delay, n, sub, dt
        self.time = np.arange(n * sub) * dt / sub
        # a block of d samples (d the delay) has its motor inputs u_{k−d} from the block
        # before: the motor over the block is x_k = A_d^k x_0 + Σ_{j<k} A_d^{k−1−j} B_d u_a,j
        # (k = 0 ... d), these powers once for all candidates
        if delay >= BLOCK_DELAY:
            pw = [np.eye(2)]
            for _ in range(delay):
                pw.append(self.Ad @ pw[-1])
            Mu = np.zeros((delay + 1, 2, delay))
            for k in range(delay + 1):
                for j in range(k):
                    Mu[k, :, j] = pw[k - 1 - j] @ self.Bd
            # one matrix: rows (k, θ | ω), columns (θ0, ω0, u_a,0 ... u_a,d−1), so a block's
            # states are one BLAS product (an einsum here was most of a design's time)
            self._W = np.concatenate([np.array(pw), Mu], axis=2).reshape(2 * (delay + 1), -1)
        # θ at the fine points from (θ_k, ω_k, u_a,k): one (sub × 3) matrix
        self._C = np.concatenate([self.Phi, self.Gam[:, None]], axis=1)

    def _blocks(self, X: np.ndarray, U: np.ndarray, c: tuple) -> None:
        """The recursion of :meth:`run` a block of d samples at a time (d >= 1 the delay):
        within a block the motor's inputs u_{k−d} are known (the block before's commands,
        0 before the first sample), so the motor's states over the block follow at once,
        and so do the compensators' s2 (a first-order filter of θm) and s1 (of e) and the
        commands. n / d steps of O(P d²) work instead of n steps."""
        c_th, c_s1, c_s2, k1, k2, e_s2, b1, b2 = c
        d, n, P = self.delay, self.n, X.shape[-1]
        # per candidate, b^s for the scan's shifts s = 1, 2, 4, ... < d + 1
        shifts = [1 << i for i in range(d.bit_length()) if (1 << i) <= d]
        q1 = [b1**sh for sh in shifts]
        q2 = [b2**sh for sh in shifts]
        s1, s2 = np.zeros(P), np.zeros(P)
        z = np.zeros((2 + d, P))  # (θm, ω) at the block's start, then its inputs u_a
        sv1, sv2 = np.empty((d + 1, P)), np.empty((d + 1, P))
        for k0 in range(0, n, d):
            m = min(d, n - k0)
            if k0 >= d:
                z[2 : 2 + m] = U[k0 - d : k0 - d + m]
            # (θm, ω) at k0 + k, k = 0 ... m
            x = (self._W[: 2 * (m + 1), : 2 + m] @ z[: 2 + m]).reshape(m + 1, 2, P)
            th = x[:, 0]
            # s2 at k = 0 ... m: s2⁺ = b2 s2 + θm, a first-order scan over the block
            sv2[0], sv2[1 : m + 1] = s2, th[:m]
            _scan(sv2[: m + 1], shifts, q2)
            e = -k2 * th[:m] + e_s2 * sv2[:m] + 1.0
            sv1[0], sv1[1 : m + 1] = s1, e
            _scan(sv1[: m + 1], shifts, q1)
            X[k0 : k0 + m, 0:2] = x[:m]
            X[k0 : k0 + m, 2] = sv1[:m]
            X[k0 : k0 + m, 3] = sv2[:m]
            U[k0 : k0 + m] = c_th * th[:m] + c_s1 * sv1[:m] + c_s2 * sv2[:m] + k1
            z[:2], s1, s2 = x[m], sv1[m].copy(), sv2[m].copy()

    def run(self, p: np.ndarray, gain: float):
        """θm per unit step on the fine grid (n·sub, ...) and the feedback current per
        unit step at the samples (n, ...), for p = (a1, b1, a2, b2) of shape (4,) or
        (4, P) (:meth:`run_rows`, θm transposed)."""
        p = np.asarray(p, float)
        theta, cs = self.run_rows(p if p.ndim == 2 else p[:, None], gain)
        if p.ndim == 1:
            return theta[0], cs[:, 0]
        return theta.T, cs

    def run_rows(self, p: np.ndarray, gain: float):
        """θm per unit step on the fine grid, a row per candidate (P, n·sub), and the
        feedback current per unit step at the samples (n, P), for p = (a1, b1, a2, b2) of
        shape (4, P) (the candidate's fine points contiguous: what the objective reduces
        over). The loop, sample by sample: u_k = k1 (b1 − a1) s1 + k1 e_k with
        e_k = 1 − k2 (b2 − a2) s2 − k2 θm (the compensators' states s1, s2:
        s1⁺ = b1 s1 + e_k, s2⁺ = b2 s2 + θm), the motor (θm, ω)⁺ = A_d (θm, ω) + B_d u_{k−d}
        (ZOH of eq. (9); u = 0 before the first sample)."""
        a1, b1, a2, b2 = np.asarray(p, float)
        k1 = gain * (1 - b1) / (1 - a1)
        k2 = (1 - b2) / (1 - a2)
        d, n = self.delay, self.n
        # u = k1 (b1 − a1) s1 + k1 e,  e = r − k2 (b2 − a2) s2 − k2 θ  (r = 1):
        # u = c_th θ + c_s1 s1 + c_s2 s2 + k1 and e = −k2 θ − k2 (b2 − a2) s2 + 1
        c_th, c_s1, c_s2 = -k1 * k2, k1 * (b1 - a1), -k1 * k2 * (b2 - a2)
        e_s2 = -k2 * (b2 - a2)
        (a00, a01), (a10, a11) = self.Ad
        g0, g1 = self.Bd
        # the recursion in its own variables, the delay line as the command history: per
        # sample O(P) work whatever the delay (the companion form's x⁺ = A_cl x + b_cl in
        # x = (θm, ω, s1, s2, u_{k−d}, ..., u_{k−1}) costs O(P (4 + d)²) a sample, which on a
        # fitted rig with an 86-sample loop delay made one design minutes long)
        X = np.empty((n, 4, a1.size))  # θm, ω, s1, s2 at each sample, before its update
        U = np.empty((n, a1.size))  # the command computed at each sample
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            if d >= BLOCK_DELAY:
                self._blocks(X, U, (c_th, c_s1, c_s2, k1, k2, e_s2, b1, b2))
            else:  # sample by sample
                th, om, s1, s2 = (np.zeros(a1.size) for _ in range(4))
                for k in range(n):
                    X[k, 0], X[k, 1], X[k, 2], X[k, 3] = th, om, s1, s2
                    u = c_th * th + c_s1 * s1 + c_s2 * s2 + k1
                    U[k] = u
                    ua = (U[k - d] if k >= d else 0.0) if d else u
                    e = -k2 * th + e_s2 * s2 + 1.0
                    th, om = a00 * th + a01 * om + g0 * ua, a10 * th + a11 * om + g1 * ua
                    s1, s2 = b1 * s1 + e, X[k, 0] + b2 * s2
        X = np.nan_to_num(X, nan=1e6, posinf=1e6, neginf=-1e6)
        U = np.nan_to_num(U, nan=1e6, posinf=1e6, neginf=-1e6)
        cs = c_th * X[:, 0] + c_s1 * X[:, 2] + c_s2 * X[:, 3] + k1
        if d:  # the applied command: the one computed d samples before (0 before that)
            ua = np.concatenate([np.zeros((min(d, n), a1.size)), U[: max(n - d, 0)]])
        else:
            ua = cs
        # θ(t_k + j T/sub) = Φ_j[0] (θ_k, ω_k) + Γ_j[0] u_a,k, all fine points at once
        P = a1.size
        z = np.empty((P, n, 3))
        z[:, :, :2] = X[:, :2].transpose(2, 0, 1)
        z[:, :, 2] = ua.T
        theta = (z.reshape(P * n, 3) @ self._C.T).reshape(P, n * self.sub)
        return theta, cs


def _scan(y: np.ndarray, shifts: list[int], powers: list[np.ndarray]) -> None:
    """y[k] ← Σ_{j<=k} b^(k−j) y[j] in place (y of shape (L, P), b one per column): the
    first-order recursion y_k = b y_{k−1} + x_k with y_0 the start, by doubling (y[s:] +=
    b^s y[:−s] for s = 1, 2, 4, ... < L; ``powers`` the b^s): log2 L array operations
    instead of L, or a (P, L, L) matrix of powers per candidate."""
    n = y.shape[0]
    for sh, q in zip(shifts, powers, strict=True):
        if sh >= n:
            break
        y[sh:] = y[sh:] + q * y[:-sh]


def _settling(t: np.ndarray, y: np.ndarray, band: float) -> np.ndarray:
    """Last time |y − 1| leaves the band (y of shape (n,) or (n, P)), linearly
    interpolated between grid points; inf where it never settles."""
    y = np.asarray(y, float)
    if y.ndim == 1:
        return _settling_rows(t, y[None, :] - 1.0, band)[0]
    return _settling_rows(t, np.ascontiguousarray(y.T) - 1.0, band)


def _settling_rows(t: np.ndarray, dev: np.ndarray, band: float) -> np.ndarray:
    """:func:`_settling` of the deviations dev = y − 1, a row per candidate (P, n): the
    last time |dev| leaves the band, linearly interpolated; inf where it never settles,
    0 where it never leaves."""
    n = dev.shape[1]
    outside = (dev > band) | (dev < -band)  # |dev| > band, without |dev| in memory
    any_out = outside.any(axis=1)
    last = n - 1 - np.argmax(outside[:, ::-1], axis=1)
    nxt = np.minimum(last + 1, n - 1)
    rows = np.arange(dev.shape[0])
    e0, e1 = np.abs(dev[rows, last]), np.abs(dev[rows, nxt])
    frac = np.clip((e0 - band) / np.where(e0 > e1, e0 - e1, 1.0), 0.0, 1.0)
    ts = t[last] + frac * (t[nxt] - t[last])
    ts = np.where(last == n - 1, np.inf, ts)
    return np.where(any_out, ts, 0.0)


def _objective(
    ev: _StepEvaluator,
    p: np.ndarray,
    dc_gain: float,
    band: float,
    horizon: float,
    max_overshoot: float,
) -> np.ndarray:
    """The search's cost of candidates p = (a1, b1, a2, b2), shape (4, P): settling time
    (s) plus penalties for the peak-current excess and the overshoot (each weighted by
    10 × ``horizon`` s per unit), plus 1e-3 × the step's integral squared error (s,
    capped at 1), 100 × ``horizon`` where not finite (see :func:`design_inner_loop`)."""
    theta, cs = ev.run_rows(p, dc_gain)
    dev = theta - 1.0
    ts = _settling_rows(ev.time, dev, band)
    ts = np.where(np.isfinite(ts), ts, horizon * (1.0 + np.abs(dev[:, -1])))
    excess = np.maximum(0.0, np.max(np.abs(cs), axis=0) / dc_gain - 1.0)
    over = np.maximum(0.0, np.max(dev, axis=1) - max_overshoot)
    ise = np.einsum("pn,pn->p", dev, dev) / dev.shape[1] * horizon
    c = ts + horizon * 10.0 * (excess + over) + 1e-3 * np.minimum(ise, 1.0)
    return np.where(np.isfinite(c), c, 100.0 * horizon)


def _search(cost, bounds, lo: float, popsize: int, maxiter: int, seed: int):
    """Differential evolution over ``bounds`` (vectorised ``cost``), then the Nelder–Mead
    polish from its best (the roots clipped to [``lo``, 0.99]): both results."""
    best = scipy.optimize.differential_evolution(
        cost,
        bounds,
        popsize=popsize,
        maxiter=maxiter,
        tol=1e-8,
        seed=seed,  # pyright: ignore[reportCallIssue]  (scipy: seed, still accepted, is hidden by its rng decorator)
        vectorized=True,
        updating="deferred",
        polish=False,
    )
    polish = scipy.optimize.minimize(
        lambda p: float(cost(np.clip(p, lo, 0.99)[:, None])[0]),
        best.x,
        method="Nelder-Mead",
        options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 200},
    )
    return best, polish


def design_inner_loop(
    model,
    dt: float,
    delay: int = 1,
    *,
    dc_gain: float = 15.0,
    current_limit: float | None = None,
    step: float = 0.4,
    bending: float | None = None,
    coupling_gain: float | None = None,
    coulomb: float | None = None,
    band: float = 0.02,
    max_overshoot: float = 0.0,
    horizon: float = 0.3,
    popsize: int = 15,
    maxiter: int = 200,
    seed: int = 0,
    min_root: float = -0.99,
) -> InnerLoopDesign:
    r"""Minimum-settling-time G_cm1(z), G_cm2(z) for the motor loop (FRB Sec. VI-B.2).

    G_cm1(z) = k1 (z − a1)/(z − b1), G_cm2(z) = k2 (z − a2)/(z − b2), searched over the
    zeros and poles (a1, b1, a2, b2) ∈ [``min_root``, 0.99]⁴ by differential evolution
    (derivative-free, ``popsize``, ``maxiter``, ``seed``; the cost is piecewise smooth and
    multimodal) polished by Nelder–Mead (``min_root`` > −0.99 keeps the roots away from
    z = −1: a compensator pole there rings at the Nyquist frequency on every encoder count
    and sensor delay), with the gains fixed by the constraints

        G_cm2(1) = 1  (zero steady-state error),  G_cm1(1) = ``dc_gain`` (A/rad),

    minimising the settling time (``band`` of the step, θm evaluated between the
    samples too) of the linear loop of Fig. 4 on Ĝ_m(s) = K/(s (J s + V)) (eq. (9)),
    zero-order hold, ``delay`` samples of computation delay, subject to

        peak |u_fb| <= G_cm1(1) · step           (the paper's peak-current rule, module doc)
        G_cm1(1) · step <= I_avail = I_max − Ĉ·bending/K − C_f/K,
        overshoot of θm <= ``max_overshoot`` (fraction of the step; FRB Sec. IV: "a very
        fast response without an overshoot"),

    I_max = ``current_limit`` (A; default the model's amplifier limit), Ĉ the static
    coupling gain (N·m/rad; default from the model), ``bending`` the largest θm − θt
    while the loop works (rad; default ``step``: the tip held, FRB Fig. 11), C_f the
    Coulomb level (N·m; default from the model): the current the feedforward terms drain
    is not available to the feedback (FRB Sec. IV, last paragraph).

    Raises ValueError, naming the constraint and by how much, when
    G_cm1(1)·step exceeds I_avail, when the compensation alone exceeds I_max, or when
    no stable loop meeting the peak rule was found.
    """
    J, V, K = motor_design_model(model)
    for name, val in (
        ("dt", dt),
        ("dc_gain", dc_gain),
        ("step", step),
        ("band", band),
        ("horizon", horizon),
    ):
        if not (math.isfinite(val) and val > 0):
            raise ValueError(f"{name} must be positive and finite; got {val!r}")
    if int(delay) != delay or delay < 0:
        raise ValueError(f"delay must be a whole number of samples >= 0; got {delay!r}")
    i_max = float(model.drive.limit) if current_limit is None else float(current_limit)
    c_hat = (
        float(np.real(control.dcgain(model.coupling_tf())))
        if coupling_gain is None
        else float(coupling_gain)
    )
    c_f = float(model.friction.coulomb) if coulomb is None else float(coulomb)
    bend = step if bending is None else float(bending)
    i_coup = abs(c_hat * bend) / K
    i_fric = abs(c_f) / K
    avail = i_max - i_coup - i_fric
    if avail <= 0:
        raise ValueError(
            f"current limit violated by the compensation alone: coupling {i_coup:.4g} A "
            f"(Ĉ = {c_hat:.4g} N·m/rad × bending {bend:.4g} rad / K) + friction "
            f"{i_fric:.4g} A exceed current_limit {i_max:.4g} A by {-avail:.4g} A"
        )
    need = dc_gain * step
    if need > avail * (1 + 1e-12):
        raise ValueError(
            f"current limit violated: dc_gain G_cm1(1) = {dc_gain:.4g} A/rad × step "
            f"{step:.4g} rad = {need:.4g} A peak exceeds the available {avail:.4g} A "
            f"(current_limit {i_max:.4g} A − coupling compensation {i_coup:.4g} A − "
            f"friction compensation {i_fric:.4g} A) by {need - avail:.4g} A "
            f"({100 * (need / avail - 1):.3g} %); use dc_gain <= {avail / step:.4g} A/rad "
            f"or step <= {avail / dc_gain:.4g} rad"
        )
    n = int(math.ceil(horizon / dt))
    ev = _StepEvaluator(J, V, K, dt, int(delay), n)

    def cost(p):
        """Vectorised over candidates p (4, P): settling time plus penalties."""
        return _objective(ev, p, dc_gain, band, horizon, max_overshoot)

    lo = float(min_root)
    if not -0.99 <= lo < 0.99:
        raise ValueError(f"min_root must be in [-0.99, 0.99); got {min_root!r}")
    bounds = [(lo, 0.99)] * 4
    # the evaluator's products are small (a block's states, the fine grid): on OpenBLAS's
    # pool of a thread per core they cost more in hand-offs than they gain, several times
    # more on busy cores (as flexarm.sim.batch.one_blas_thread finds for the fit)
    with threadpool_limits(limits=1, user_api="blas"):
        best, polish = _search(cost, bounds, lo, popsize, maxiter, seed)
    search_message = (
        f"differential evolution: {best.message} "
        f"({'converged' if best.success else 'not converged'}); Nelder–Mead "
        f"polish: {polish.message}"
    )
    if polish.fun < best.fun:
        best = polish
    p = np.clip(best.x, lo, 0.99)
    theta, cs = ev.run(p, dc_gain)
    ts = _settling(ev.time, theta, band)
    peak = float(np.max(np.abs(cs)))
    over = float(np.max(theta) - 1.0)
    if not math.isfinite(ts) or peak > dc_gain * (1 + 1e-3) or over > max_overshoot + 1e-3:
        raise ValueError(
            "no inner-loop design met the constraints: best found settles in "
            f"{ts:.4g} s (horizon {horizon:g} s) with peak current {peak * step:.4g} A for "
            f"the {step:g} rad step, G_cm1(1)·step = {need:.4g} A (excess "
            f"{max(0.0, peak - dc_gain) * step:.3g} A), overshoot {100 * over:.3g} % "
            f"(allowed {100 * max_overshoot:.3g} %); raise horizon, dc_gain or max_overshoot"
        )
    g1 = _comp(p[0], p[1], dc_gain, dt)
    g2 = _comp(p[2], p[3], 1.0, dt)
    ts = cast(float, ts)  # a NumPy float: _settling of one response
    return InnerLoopDesign(
        g1,
        g2,
        dt,
        int(delay),
        float(dc_gain),
        ts,
        band,
        max(over, 0.0),
        float(step),
        peak * step,
        avail,
        i_max,
        i_coup,
        i_fric,
        p,
        ev.time,
        theta,
        cs,
        search_message,
    )
