r"""Point-to-point tip references for the outer loop: parabolic and quasi-parabolic.

Feliu, Rattan & Brown (1993), Sec. V-B and Fig. 6. All angles in rad, times in s.

Parabolic (FRB Sec. VI-B.3, single-mass arm)
    bang-bang acceleration +A on [0, T/2], −A on [T/2, T], T = 2 √(D/A) for a distance
    D. Position, velocity and acceleration are bounded; the jerk is a train of Dirac
    impulses (A, −2A, A). With a minimum-phase G_b, N = 1/G_b has a polynomial part of
    degree 2 (eq. (13)) and the feedforward θ̂_mr = u + (0.06 u̇ + ü)/43.75 is bounded.

Quasi-parabolic (FRB Sec. VI-C.3, two-mass arm)
    the same acceleration profile with rounded corners: the *snap* (4th derivative of
    position, "second derivative of acceleration") is piecewise constant, ±S, so the
    derivatives up to the 4th are bounded. Each corner is the minimum-time transition
    with |snap| ≤ S: 0 → A in τ1 = 2 √(A/S) (snap +S then −S, jerk peak √(A S)),
    A → −A in 2 τm, τm = √(2A/S) (jerk peak √(2 A S)), −A → 0 in τ1; the constant-
    acceleration holds h are solved for the distance. The acceleration is antisymmetric
    about T/2, so the trajectory ends at rest at exactly D at T = 2 τ1 + 2 τm + 2 h.
    With G_b of eq. (14), the Wiener N(s) has numerator degree 6 and denominator degree
    2, i.e. a polynomial part of degree 4: the feedforward needs u … u⁗, which are
    bounded here, and it would need Dirac impulses and their derivatives for a parabolic
    reference ("the corresponding feedforward signal is unbounded", FRB Sec. V-B).

Laplace model for the Wiener design (``laplace_model``)
    u(s) = A/s³, the Laplace transform of the first segment (a step of acceleration A).
    Derivation: write G_b = −K (s − a)(s + a)/D(s) (eq. (14): K = 45.475, a² = 1273.3).
    With the factorisation rule of :mod:`flexarm.control.wiener`, eq. (11) gives, for
    u = 1/s^k, N(s) = D(s) Φ_k(s) / (K (s + a)²) with
    Φ_k(s) = [(s + a) − 2a (s/a)^k] / (a − s) = 1 + 2 Σ_{i=1}^{k−1} (s/a)^i.
    For k = 3, Φ_3 = 1 + (2/a) s + (2/a²) s² = 1 + 0.05605 s + 0.0015707 s², which is the
    second-order factor printed in FRB Sec. VI-C.3. So the paper designed N with the
    acceleration-step model 1/s³; the factor comes from the three poles of u at s = 0
    together with the reflected RHP zero, not from the rounding, and does not depend on
    A or S. The full trajectory, a sum of delayed steps of acceleration (with delays
    e^{−sT}), has no rational transform; the rounding only serves to make N·u bounded.

Sizing from deflection
    For the single-mass arm (eq. (13), G_b = ω²/(s² + 2ζω s + ω²)) with N = 1/G_b,
    θm − θt = (ü + 2ζω u̇)/ω² ≈ ü/ω², so A = deflection · ω²
    (:func:`acceleration_for_deflection`; FRB: 0.2 rad · 43.75 s⁻² = 8.75 rad/s²).
    General rule for any G_b (several modes, non-minimum phase): simulate the linear
    model, θm = N u, θt = G_b N u, and take the peak of |θm − θt|
    (:func:`peak_deflection`); :func:`check_deflection` raises when a trajectory
    exceeds a limit and says by how much. Deflection is roughly proportional to A for a
    given shape, so scaling A by limit/peak is a good next guess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control
import numpy as np

from flexarm.control.wiener import _siso_polys, cancel_common_roots, feedforward_signal

__all__ = [
    "PointToPointTrajectory",
    "parabolic",
    "quasi_parabolic",
    "acceleration_for_deflection",
    "peak_deflection",
    "check_deflection",
]


def _positive(value: float, name: str, unit: str) -> float:
    x = float(value)
    if not (math.isfinite(x) and x > 0):
        raise ValueError(f"{name} must be positive and finite (in {unit}); got {value!r}")
    return x


@dataclass(frozen=True, eq=False)
class PointToPointTrajectory:
    """A rest-to-rest move from 0 to ``distance`` rad, piecewise polynomial.

    The derivative of order ``smooth_order`` is piecewise constant (2: parabolic, 4:
    quasi-parabolic); lower derivatives are continuous, higher ones contain Dirac
    impulses and are refused by :meth:`derivative`. For t < 0 the arm is at 0 rad, for
    t ≥ ``duration`` at ``distance`` rad, at rest.
    """

    kind: str
    distance: float  # rad
    duration: float  # s
    max_acceleration: float  # rad/s²
    smooth_order: int
    breaks: np.ndarray = field(repr=False)  # segment start times (s), length n
    states: np.ndarray = field(repr=False)  # (n, smooth_order + 1): derivatives at breaks
    max_snap: float | None = None  # rad/s⁴, quasi-parabolic only

    # ------------------------------------------------------------------ evaluation
    def derivative(self, t: np.ndarray, order: int = 0) -> np.ndarray:
        """d^order u/dt^order at times t (s); rad/s^order. Vectorised."""
        if int(order) != order or order < 0:
            raise ValueError(f"order must be a non-negative integer; got {order!r}")
        order = int(order)
        if order > self.smooth_order:
            raise ValueError(
                f"a {self.kind} trajectory has no bounded derivative of order {order}: its "
                f"derivative of order {self.smooth_order} jumps, so order "
                f"{self.smooth_order + 1} and above contain Dirac impulses"
            )
        t = np.asarray(t, dtype=float)
        idx = np.clip(np.searchsorted(self.breaks, t, side="right") - 1, 0, self.breaks.size - 1)
        tau = t - self.breaks[idx]
        st = self.states[idx]  # (..., smooth_order + 1)
        val = np.zeros_like(t)
        for j in range(self.smooth_order, order - 1, -1):  # Horner on the Taylor series
            val = val * tau / (j - order + 1) + st[..., j]
        val = np.where(t < 0.0, 0.0, val)
        end = self.distance if order == 0 else 0.0
        return np.where(t >= self.duration, end, val)

    def position(self, t: np.ndarray) -> np.ndarray:
        """u(t), rad."""
        return self.derivative(t, 0)

    def velocity(self, t: np.ndarray) -> np.ndarray:
        """u̇(t), rad/s."""
        return self.derivative(t, 1)

    def acceleration(self, t: np.ndarray) -> np.ndarray:
        """ü(t), rad/s²."""
        return self.derivative(t, 2)

    def jerk(self, t: np.ndarray) -> np.ndarray:
        """d³u/dt³, rad/s³ (quasi-parabolic only)."""
        return self.derivative(t, 3)

    def snap(self, t: np.ndarray) -> np.ndarray:
        """d⁴u/dt⁴, rad/s⁴ (quasi-parabolic only)."""
        return self.derivative(t, 4)

    def __call__(self, t: np.ndarray, order: int = 0) -> np.ndarray:
        return self.derivative(t, order)

    def laplace_model(self) -> control.TransferFunction:
        """u(s) = A/s³ (rad·s), the reference model of the Wiener design (module doc)."""
        return control.tf([self.max_acceleration], [1.0, 0.0, 0.0, 0.0])

    def time_grid(self, dt: float, settle: float = 0.0) -> np.ndarray:
        """Uniform grid from 0 to ``duration + settle`` s with step ≈ ``dt`` s."""
        dt = _positive(dt, "dt", "s")
        n = int(math.ceil((self.duration + settle) / dt))
        return np.linspace(0.0, n * dt, n + 1)


def _integrate(
    durations: list[float], top: list[float], order: int
) -> tuple[np.ndarray, np.ndarray]:
    """Breaks and derivative states for a piecewise-constant derivative of ``order``."""
    breaks = np.concatenate([[0.0], np.cumsum(durations)[:-1]])
    states = np.zeros((len(durations), order + 1))
    x = np.zeros(order + 1)
    for i, (h, c) in enumerate(zip(durations, top, strict=True)):
        x[order] = c
        states[i] = x
        # exact Taylor step of length h
        nxt = np.zeros_like(x)
        for k in range(order + 1):
            nxt[k] = sum(x[k + j] * h**j / math.factorial(j) for j in range(order + 1 - k))
        x = nxt
    return breaks, states


def parabolic(distance: float, max_acceleration: float) -> PointToPointTrajectory:
    """Bang-bang acceleration move (FRB Sec. V-B): +A then −A, T = 2 √(D/A).

    Parameters: ``distance`` D (rad, > 0), ``max_acceleration`` A (rad/s², > 0).
    """
    d = _positive(distance, "distance", "rad")
    a = _positive(max_acceleration, "max_acceleration", "rad/s²")
    half = math.sqrt(d / a)
    breaks, states = _integrate([half, half], [a, -a], 2)
    return PointToPointTrajectory("parabolic", d, 2.0 * half, a, 2, breaks, states)


def quasi_parabolic(
    distance: float,
    max_acceleration: float,
    *,
    max_snap: float | None = None,
    rounding_time: float | None = None,
) -> PointToPointTrajectory:
    """Parabolic move with rounded acceleration corners, |d⁴u/dt⁴| ≤ S (module doc).

    Parameters
    ----------
    distance: D, rad (> 0).
    max_acceleration: A, rad/s² (> 0), reached and held.
    max_snap: S, rad/s⁴ — the paper's "second derivative of acceleration".
    rounding_time: alternatively τ1, s: duration of the 0 → A corner; S = 4 A / τ1².
        Give exactly one of ``max_snap`` and ``rounding_time``.

    Raises ValueError when the distance is too short to reach A with this snap (the
    message gives the minimum distance).
    """
    d = _positive(distance, "distance", "rad")
    a = _positive(max_acceleration, "max_acceleration", "rad/s²")
    if (max_snap is None) == (rounding_time is None):
        raise ValueError("give exactly one of max_snap (rad/s⁴) and rounding_time (s)")
    if max_snap is not None:
        s = _positive(max_snap, "max_snap", "rad/s⁴")
    else:
        assert rounding_time is not None  # one of the two (checked above)
        tr = _positive(rounding_time, "rounding_time", "s")
        s = 4.0 * a / tr**2
    tau1 = 2.0 * math.sqrt(a / s)
    taum = math.sqrt(2.0 * a / s)

    def build(h: float) -> tuple[np.ndarray, np.ndarray, list[float]]:
        durs = [tau1 / 2, tau1 / 2, h, taum, taum, h, tau1 / 2, tau1 / 2]
        snaps = [s, -s, 0.0, -s, s, 0.0, s, -s]
        keep = [i for i, du in enumerate(durs) if du > 0.0]
        durs = [durs[i] for i in keep]
        br, st = _integrate(durs, [snaps[i] for i in keep], 4)
        return br, st, durs

    # distance for h = 0, then D(h) = D0 + 2 (v1 + A τm) h + A h², v1 = A τ1 / 2
    br0, st0, durs0 = build(0.0)
    last = st0[-1]
    h_end = durs0[-1]
    d0 = sum(last[j] * h_end**j / math.factorial(j) for j in range(5))
    if d < d0 * (1.0 - 1e-12):
        raise ValueError(
            f"distance {d:.6g} rad is shorter than the {d0:.6g} rad a quasi-parabolic move "
            f"needs to reach max_acceleration {a:.6g} rad/s² with max_snap {s:.6g} rad/s⁴ "
            f"(short by {d0 - d:.3g} rad); lower max_acceleration or raise max_snap"
        )
    b = a * tau1 / 2 + a * taum
    h = max(0.0, (-b + math.sqrt(b * b + a * (d - d0))) / a)
    breaks, states, durs = build(h)
    duration = float(sum(durs))
    return PointToPointTrajectory("quasi-parabolic", d, duration, a, 4, breaks, states, max_snap=s)


# ------------------------------------------------------------------------ deflection
def acceleration_for_deflection(max_deflection_rad: float, omega2: float) -> float:
    """A = deflection · ω² (rad/s²) for the single-mass arm, ω² in s⁻² (FRB Sec. VI-B.3).

    Exact in steady acceleration for G_b = ω²/(s² + 2ζω s + ω²) with N = 1/G_b; for
    other plants use :func:`peak_deflection` / :func:`check_deflection`.
    """
    dfl = _positive(max_deflection_rad, "max_deflection_rad", "rad")
    w2 = _positive(omega2, "omega2", "s⁻²")
    return dfl * w2


def _deflection_signal(
    plant: control.TransferFunction,
    n: control.TransferFunction,
    trajectory: PointToPointTrajectory,
    dt: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(t, θm − θt) for θm = N u, θt = G_b N u (G_b N with cancelled common roots)."""
    gn = cancel_common_roots(plant * n, rtol=1e-6)
    _, nden = _siso_polys(n, "N(s)")
    _, gnden = _siso_polys(gn, "G_b(s) N(s)")
    poles = np.concatenate([np.roots(nden), np.roots(gnden)]).astype(complex)
    if np.any(np.real(poles) >= -1e-9 * np.maximum(1.0, np.abs(poles))):
        raise ValueError(
            "G_b(s) N(s) keeps poles on the imaginary axis or in the right half-plane "
            "(N does not cancel the plant's undamped modes): the deflection does not decay"
        )
    settle = 10.0 / np.min(-np.real(poles)) if poles.size else 0.0
    settle = min(settle, 10.0 * trajectory.duration)
    if dt is None:
        fast = np.max(np.abs(np.concatenate([poles, _zeros(plant), _zeros(n)])), initial=1.0)
        dt = min(trajectory.duration / 4000.0, 0.05 / fast)
    t = trajectory.time_grid(dt, settle)
    theta_m = feedforward_signal(n, trajectory, t)
    theta_t = feedforward_signal(gn, trajectory, t)
    return t, theta_m - theta_t


def _zeros(sys: control.TransferFunction) -> np.ndarray:
    num, _ = _siso_polys(sys, "transfer function")
    return np.roots(num).astype(complex) if num.size > 1 else np.zeros(0, complex)


def peak_deflection(
    plant: control.TransferFunction,
    n: control.TransferFunction,
    trajectory: PointToPointTrajectory,
    *,
    dt: float | None = None,
) -> float:
    """max_t |θm(t) − θt(t)| (rad) with θm = N u, θt = G_b θm, linear models.

    The grid runs from 0 to the end of the move plus ten time constants of the slowest
    pole of N and G_b N; ``dt`` (s) defaults to a fine step set by the duration and the
    fastest root. A parabolic trajectory with an N of polynomial degree > 2 raises
    ValueError (unbounded feedforward).
    """
    _, d = _deflection_signal(plant, n, trajectory, dt)
    return float(np.max(np.abs(d)))


def check_deflection(
    plant: control.TransferFunction,
    n: control.TransferFunction,
    trajectory: PointToPointTrajectory,
    max_deflection_rad: float,
    *,
    dt: float | None = None,
) -> float:
    """Return the peak deflection (rad); ValueError if it exceeds ``max_deflection_rad``.

    The message gives the excess in rad and % and the acceleration scale factor
    (limit/peak) that would approximately meet the limit.
    """
    limit = _positive(max_deflection_rad, "max_deflection_rad", "rad")
    peak = peak_deflection(plant, n, trajectory, dt=dt)
    if peak > limit:
        raise ValueError(
            f"deflection limit not met: peak |θm − θt| = {peak:.6g} rad exceeds "
            f"max_deflection_rad = {limit:.6g} rad by {peak - limit:.3g} rad "
            f"({100.0 * (peak / limit - 1.0):.3g} %); scale max_acceleration "
            f"({trajectory.max_acceleration:.6g} rad/s²) by about {limit / peak:.4g}"
        )
    return peak
