"""Full-state feedback and hub-angle PD on measured signals, with a chosen rate scheme.

The law of most bench rigs (hub encoder θ, strain gauge d at the link root, SI units):

    u_k = K1 (r_k − θ_k) − K2 d_k − K3 θ̇_k − K4 ḋ_k

acting on the *measured* signals at the sample instants t_k = k T (the sensors' gains,
quantisation and pure delays are applied before the controller sees them), the command
held over [t_k, t_k + T] (zero-order hold). The rates come from the measured signals by

* ``rate="backward"``: backward difference, ẋ_k = (x_k − x_{k−1}) / T;
* ``rate="filtered"``: first-order filtered derivative s / (τ s + 1), discretised by
  backward Euler: ẋ_k = (τ ẋ_{k−1} + x_k − x_{k−1}) / (τ + T).

At the first sample x_{−1} = x_0 (no derivative kick from the initial state). A hub PD,
u = KP (r − θ) − KD θ̇ (derivative on the measured angle, not on the error), is the same
law with K2 = K4 = 0: :func:`hub_pd`.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import Array

from flexarm.control.discrete import Controller, Signals

RATE_SCHEMES = ("backward", "filtered")


class StateFeedback(Controller):
    """u = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ on measured θ (``angle``) and d (``deflection``).

    ``gains`` = (K1, K2, K3, K4) in V/rad, V/m, V·s/rad, V·s/m (or A/... for a current
    drive); ``dt`` the sampling period T (s); ``tau`` the filter time constant τ (s, used
    when ``rate == "filtered"``). State: (θ_{k−1}, d_{k−1}, θ̇_{k−1}, ḋ_{k−1}, started).
    """

    gains: Array
    dt: Array
    tau: Array
    rate: str = eqx.field(static=True, default="backward")
    angle: str = eqx.field(static=True, default="motor_angle")
    deflection: str | None = eqx.field(static=True, default="tip_deflection")
    reference: str = eqx.field(static=True, default="reference")
    #: reference-like input channels carrying K1..K4 at each sample (a logged gain
    #: schedule); None: ``gains`` throughout
    gain_signals: tuple[str, ...] | None = eqx.field(static=True, default=None)

    @property
    def measured_signals(self) -> tuple[str, ...]:
        """Sensor channels the law reads (``build.prepare`` adds them to the sensors)."""
        return (self.angle,) + ((self.deflection,) if self.deflection else ())

    def init(self) -> Array:
        return jnp.zeros(5)

    def step(self, state: Array, measured: Signals, reference: Signals) -> tuple[Array, Array]:
        th = measured[self.angle]
        d = measured[self.deflection] if self.deflection else jnp.zeros_like(th)
        started = state[4] > 0.5
        th_prev = jnp.where(started, state[0], th)
        d_prev = jnp.where(started, state[1], d)
        if self.rate == "backward":
            th_dot = (th - th_prev) / self.dt
            d_dot = (d - d_prev) / self.dt
        else:
            th_dot = (self.tau * state[2] + th - th_prev) / (self.tau + self.dt)
            d_dot = (self.tau * state[3] + d - d_prev) / (self.tau + self.dt)
        if self.gain_signals:  # the gains of this sample (a logged schedule)
            k = jnp.stack([jnp.asarray(reference[n], th.dtype) for n in self.gain_signals])
        else:
            k = self.gains
        u = k[0] * (reference[self.reference] - th) - k[1] * d - k[2] * th_dot - k[3] * d_dot
        new = jnp.stack([th, d, th_dot, d_dot, jnp.ones_like(th)])
        return new, jnp.reshape(u, (1,))


def state_feedback(
    k1: float,
    k2: float,
    k3: float,
    k4: float,
    dt: float,
    *,
    rate: str = "backward",
    rate_time_constant: float = 0.0,
    angle: str = "motor_angle",
    deflection: str = "tip_deflection",
    reference: str = "reference",
) -> StateFeedback:
    """u = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ (see module docstring). ``rate`` is
    ``"backward"`` or ``"filtered"`` (then ``rate_time_constant`` τ > 0 in s)."""
    if rate not in RATE_SCHEMES:
        raise ValueError(f"rate = {rate!r} is not known; choose one of {', '.join(RATE_SCHEMES)}")
    if rate == "filtered" and not rate_time_constant > 0:
        raise ValueError(
            "rate = 'filtered' needs rate_time_constant > 0 (s), e.g. 0.02 "
            "for a 50 rad/s derivative filter"
        )
    if not dt > 0:
        raise ValueError(f"sampling period dt = {dt!r} must be > 0 s")

    def f(v):
        return jnp.asarray(v, dtype=float)

    return StateFeedback(
        f([k1, k2, k3, k4]), f(dt), f(rate_time_constant), rate, angle, deflection, reference
    )


def hub_pd(
    kp: float,
    kd: float,
    dt: float,
    *,
    rate: str = "backward",
    rate_time_constant: float = 0.0,
    angle: str = "motor_angle",
    reference: str = "reference",
) -> StateFeedback:
    """u = KP (r − θ) − KD θ̇ on the measured hub angle, θ̇ by ``rate`` (no tip sensor)."""
    c = state_feedback(
        kp,
        0.0,
        kd,
        0.0,
        dt,
        rate=rate,
        rate_time_constant=rate_time_constant,
        angle=angle,
        reference=reference,
    )
    return StateFeedback(c.gains, c.dt, c.tau, c.rate, angle, None, reference)


def from_spec(spec, dt: float) -> StateFeedback:
    """The controller of a :class:`~flexarm.specs.controllers_bench.StateFeedbackController`
    (with ``gain_signals``: K1..K4 read per sample from those input channels)."""
    c = state_feedback(
        spec.k1,
        spec.k2,
        spec.k3,
        spec.k4,
        dt,
        rate=spec.rate,
        rate_time_constant=spec.rate_time_constant,
    )
    sig = getattr(spec, "gain_signals", None)
    if sig:
        c = StateFeedback(
            c.gains, c.dt, c.tau, c.rate, c.angle, c.deflection, c.reference, tuple(sig)
        )
    return c
