r"""The tip (outer) loop of Feliu, Rattan & Brown (1993), Sec. V and Fig. 5.

Control law (one sample k; angles in rad):

    θ_mr = θ̂_mr + G_cb(z) (θ_tr − θt)                                     (Fig. 5)
    θ̂_mr = N(s) θ_tr      (the Wiener feedforward of eq. (11), precomputed)

and θ_mr is the commanded motor angle of the inner loop (:mod:`flexarm.control.inner_loop`,
Fig. 4), which in turn drives the current. θ_tr is the tip trajectory (the reference
channel ``"reference"``), θt the measured tip angle, θ̂_mr the feedforward channel
(``"feedforward"``), computed before the run by :func:`trajectory_references` with
:func:`flexarm.control.wiener.feedforward_signal` (analytic derivatives of the
trajectory for the polynomial part of N).

G_cb is a discrete PID (the single-mass arm, FRB Sec. VI-B.3, written as
k (1 − c1 z⁻¹)(1 − c2 z⁻¹)/((1 − z⁻¹)(1 − p z⁻¹)) by :func:`pid_zpk`) or a PD (the two-mass
arm, Sec. VI-C.3: the inner loop removes the friction errors, so no integrator is
needed; :func:`flexarm.control.discrete.pd`).

The loops nest with :class:`flexarm.control.discrete.Cascade`: the outer part is
``Sum(G_cb on the tip error, ReferenceChannel("feedforward"))``, its output the inner
loop's reference channel (``"motor_reference"``).

Trajectory sizing (Sec. VI-B.3, VI-C.3): :func:`size_parabolic` sets the acceleration of
a parabolic move from a design deflection, A = deflection · ω² for
G_b = ω²/(s² + 2ζω s + ω²); :func:`deflection_report` gives the peak |θm − θt| of any
trajectory through the linear model θm = N u, θt = G_b θm, and :func:`size_parabolic`
raises when the peak exceeds the limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from flexarm.control import discrete
from flexarm.control.discrete import Cascade, Controller, LinearController, Signals, Sum
from flexarm.control.inner_loop import InnerLoop
from flexarm.control.trajectories import (
    PointToPointTrajectory,
    acceleration_for_deflection,
    check_deflection,
    parabolic,
)
from flexarm.control.wiener import feedforward_signal, wiener_feedforward

__all__ = [
    "ReferenceChannel",
    "pid_zpk",
    "tip_feedback",
    "tip_loop",
    "trajectory_references",
    "size_parabolic",
    "deflection_report",
    "DeflectionReport",
]


class ReferenceChannel(Controller):
    """u = reference[channel]: a precomputed signal passed through (the feedforward
    θ̂_mr of FRB Fig. 5)."""

    channel: str = eqx.field(static=True, default="feedforward")

    def init(self):
        return jnp.zeros(())

    def step(self, state, measured: Signals, reference: Signals):
        return state, jnp.reshape(reference[self.channel], (1,))


def pid_zpk(
    gain: float, zeros: tuple[float, float], pole: float, dt: float
) -> control.TransferFunction:
    """G(z) = gain (1 − c1 z⁻¹)(1 − c2 z⁻¹) / ((1 − z⁻¹)(1 − p z⁻¹)), sampling period dt (s):
    a discrete PID with an integrator, two zeros c1, c2 and a filter pole p (rad/rad)."""
    c1, c2 = zeros
    num = gain * np.polymul([1.0, -c1], [1.0, -c2])
    den = np.polymul([1.0, -1.0], [1.0, -pole])
    return control.tf(num, den, dt)


def tip_feedback(gcb, dt: float) -> LinearController:
    """G_cb acting on θ_tr − θt (``reference`` − measured ``tip_angle``): a discrete
    transfer function, or ``(kp, kd)`` for the PD u = kp e + kd (e_k − e_{k−1})/T."""
    if isinstance(gcb, tuple):
        kp, kd = gcb
        return discrete.pd(kp, kd, dt, measured="tip_angle", reference="reference")
    return discrete.from_transfer_function(gcb, dt, measured="tip_angle", reference="reference")


def tip_loop(inner: InnerLoop, gcb, dt: float, *, feedforward: str = "feedforward") -> Cascade:
    """The two nested loops of FRB Fig. 3/5: θ_mr = θ̂_mr + G_cb(θ_tr − θt) fed to
    ``inner`` (whose reference channel names θ_mr; build it with
    ``reference="motor_reference"``)."""
    if inner.reference in ("reference", feedforward):
        raise ValueError(
            f"the inner loop reads its command from channel {inner.reference!r}, which the "
            "outer loop also uses; build it with reference='motor_reference'"
        )
    outer = Sum(tip_feedback(gcb, dt), ReferenceChannel(feedforward))
    return Cascade(outer, inner, via=inner.reference)


def trajectory_references(
    n: control.TransferFunction,
    trajectory: PointToPointTrajectory,
    t: np.ndarray,
    *,
    start: float = 0.0,
    advance: float = 0.0,
    oversample: int = 30,
) -> dict[str, np.ndarray]:
    """Reference channels for :func:`tip_loop` on the sample times ``t`` (s, uniform): the
    tip trajectory θ_tr(t) = u(t − start) (``"reference"``) and the feedforward
    θ̂_mr(t) = (N u)(t − start + advance) (``"feedforward"``), both rad.

    ``advance`` (s, >= 0) sends the feedforward early, e.g. by the inner loop's lag
    (:attr:`flexarm.control.inner_loop.InnerLoopDesign.lag`): the "correction terms that
    compensate for motor delays" of FRB Sec. V. 0 is the paper's unity-inner-loop
    assumption.

    N u is evaluated on a grid ``oversample`` times finer than ``t`` and then sampled:
    :func:`~flexarm.control.wiener.feedforward_signal` splits N into a polynomial and a
    proper part, and when N has a fast pole (the single-mass G_b's damping zero at
    s ≈ −729 rad/s puts one in N = 1/G_b) the two parts are large and cancel, so the
    linear interpolation of the proper part's input between grid points is amplified:
    on the 3 ms grid the error reaches ~0.1 rad, on a 0.1 ms grid it is below 1 mrad.
    """
    if advance < 0 or advance > start + 1e-12:
        raise ValueError(
            f"advance must be in [0, start] = [0, {start:g}] s (the feedforward cannot "
            f"begin before t = 0); got {advance:g} s"
        )
    t = np.asarray(t, float)
    k = max(1, int(oversample))
    fine = t[0] + np.arange((t.size - 1) * k + 1) * ((t[-1] - t[0]) / max(t.size - 1, 1) / k)

    def shifted(tt, o):
        return trajectory.derivative(np.asarray(tt) - start + advance, o)

    return {
        "reference": trajectory.position(t - start),
        "feedforward": feedforward_signal(n, shifted, fine)[::k],
    }


@dataclass(frozen=True)
class DeflectionReport:
    """Peak |θm − θt| (rad) of a trajectory through the linear model, and where."""

    peak: float  # rad
    time: float  # s after the start of the move
    duration: float  # s, the move
    steady_acceleration: float  # rad, (1 − G_b) θm at constant acceleration A


def deflection_report(
    gb: control.TransferFunction, n: control.TransferFunction, trajectory: PointToPointTrajectory
) -> DeflectionReport:
    """Peak of θm − θt with θm = N u, θt = G_b θm (linear models, inner loop = 1), when it
    occurs, and the deflection in steady acceleration: (1 − G_b(s))/s² at s → 0 times A,
    the part a parabolic move holds while accelerating (the rest comes from the corners)."""
    from flexarm.control.trajectories import _deflection_signal

    t, d = _deflection_signal(gb, n, trajectory, None)
    i = int(np.argmax(np.abs(d)))
    num, den = (np.asarray(a, float) for a in (gb.num[0][0], gb.den[0][0]))
    # 1 − G_b = (den − num)/den; its s² coefficient over den(0) (the s⁰, s¹ terms vanish
    # when G_b(0) = 1 and G_b'(0) = 0)
    diff = np.polysub(den, num)
    c2 = diff[-3] / den[-1] if diff.size >= 3 else 0.0
    return DeflectionReport(
        float(abs(d[i])),
        float(t[i]),
        trajectory.duration,
        float(abs(c2) * trajectory.max_acceleration),
    )


def size_parabolic(
    gb: control.TransferFunction, distance: float, design_deflection: float, max_deflection: float
) -> tuple[PointToPointTrajectory, control.TransferFunction, float]:
    """Parabolic move for a minimum-phase second-order G_b (FRB Sec. VI-B.3).

    A = ``design_deflection`` · ω² with ω² = G_b's denominator constant over its s²
    coefficient (the deflection θm − θt = ü/ω² in steady acceleration for N = 1/G_b);
    N = 1/G_b (eq. (11) for a minimum-phase G_b). Returns the trajectory, N and the peak
    deflection (rad) of the linear model; raises ValueError (naming the excess) when the
    peak exceeds ``max_deflection`` (rad).
    """
    den = np.trim_zeros(np.asarray(gb.den[0][0], float), "f")
    if den.size != 3:
        raise ValueError(
            "size_parabolic needs a second-order G_b = ω²/(s² + 2ζω s + ω²); for other "
            "beams size the move with flexarm.control.trajectories.check_deflection"
        )
    omega2 = den[2] / den[0]
    accel = acceleration_for_deflection(design_deflection, omega2)
    traj = parabolic(distance, accel)
    n = wiener_feedforward(gb, traj.laplace_model())
    peak = check_deflection(gb, n, traj, max_deflection)
    return traj, n, peak
