"""Batched closed-loop (or open-loop replay) simulation of bench logs, for fitting.

The plant is the single-link arm of :mod:`flexarm.models.single_link` with one pinned tip
mass (the classic 2-DOF rotary flexible link), written out by hand for speed and batched
over a population of parameter vectors P and the logs L at once: every quantity is an
array of shape (L, P) and one :func:`jax.lax.scan` runs over the samples. In link
coordinates x = (θ, ω, w, ẇ), w the tip deflection (m) relative to the hub line,

    ẅ  = −ω_c² w − 2 ζ ω_c ẇ − L ω̇                      (link, hub-clamped frequency ω_c)
    J ω̇ = τ_a − F,   τ_a = k_u u − (k_ω + B) ω + (J_l / L)(ω_c² w + 2 ζ ω_c ẇ) + τ_bias

with k_u = η_g η_m K_g K_m / R, k_ω = k_u K_g K_m (voltage drive), J_l = m L² the link
inertia and C = J_l ω_c² its stiffness (N·m/rad). F is Karnopp friction exactly as in
:mod:`flexarm.models.friction` (stuck while |τ_a| <= F_s, F_c sign(ω) when moving) and
after every RK4 substep a hub that crossed zero velocity (or entered the band |ω| < Δv)
while |τ_a| <= F_s is stopped: ω = 0 (and ẇ += L ω_old, since the link's absolute
velocity is unchanged). This is the same sampled-data loop as
:func:`flexarm.sim.sampled.simulate_loop` (sensor gain, A/D quantisation, per-channel pure
delay, controller, computation delay, saturation, zero-order hold): RK4 is invariant
under the linear change of coordinates (θ, y) → (θ, w), so both agree to rounding.

Sensor low-pass filters (known cutoffs, not fitted; ``filters=(hub, tip)`` static flags,
ω_θ = ``const["omega_th"]``, ω_d = ``const["omega_d"]`` in rad/s) are analog first-order
filters in front of the A/D, as in :mod:`flexarm.sim.sampled`: their states join x and
RK4 integrates them with the arm between samples,

    y_θ' = ω_θ (θ − y_θ),   y_d' = ω_d (g w − y_d),   y_θ(0) = θ(0),  y_d(0) = g w(0),

and the channel reads y_θ (y_d) instead of θ (g w) before quantisation and delay.

The controller is the bench law of :mod:`flexarm.control.state_feedback`,
u = K1 (r − θ) − K2 d − K3 θ̇ − K4 ḋ with the filtered rate (τ = 0 gives the backward
difference), so a hub PD is K2 = K4 = 0; the gains are per sample (``data["K"]`` is
(L, N, 4)), so gains that change inside a log act as logged. In open-loop replay u is the
logged voltage.

Sensor delays of D samples (up to tens of milliseconds on real rigs) are a ring buffer of
``n_buf`` >= D + 1 samples per channel, read at (k − D) mod n_buf (one gather, whatever
the delay), filled at the start with the initial reading as in
:func:`flexarm.sim.sampled.simulate_loop`; the initial state is read from the log at
k = D (:class:`flexarm.identification.time_domain.objective.Objective`). (Feeding the controller the log's own
readings while a delay line fills was tried: it moved the synthetic acceptance fits into
other local minima, ζ −44 %, and changed the real units' held-out fit % by < 1 point.)

:func:`closed_loop_cost` accumulates, inside the scan, the squared output errors of the
measured hub angle and tip deflection against the log, weighted per sample (so the
trajectories are never stored); :func:`closed_loop_run` returns the trajectories.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

#: Names of the model numbers (each an array (L, P)) that :func:`closed_loop_cost` takes.
MODEL_KEYS = ("J", "B", "wc2", "c2z", "JlL", "Fc", "Fs", "bias", "gain", "dth", "dd",
              "th0", "om0", "w0", "wd0")
#: Names of the per-log data (arrays (L, ...)).
DATA_KEYS = ("ref", "y_th", "y_d", "w_th", "w_d", "volt", "K", "tau")


def _quantise(x: Array, q: Array) -> Array:
    return jnp.where(q > 0, jnp.round(x / jnp.where(q > 0, q, 1.0)) * q, x)


def _scan(m: dict, data: dict, const: dict, *, substeps: int, n_buf: int, comp_delay: int,
          open_loop: bool, record: bool, filters: tuple[bool, bool] = (False, False)):
    """The sampled-data loop over all samples; m: model numbers (L, P); data: per-log
    arrays (L, N) / (L, 4) / (L,); const: scalars (dt, L, k_u, k_om, q_th, q_d, limit, tol,
    and omega_th / omega_d for the filtered channels)."""
    dt, Lk = const["dt"], const["length"]
    ku, kom = const["k_u"], const["k_omega"]
    h = dt / substeps
    J, B, wc2, c2z, JlL = m["J"], m["B"], m["wc2"], m["c2z"], m["JlL"]
    Fc, Fs, bias, gain = m["Fc"], m["Fs"], m["bias"], m["gain"]
    tol = const["vel_tol"]
    damp = kom + B
    shape = J.shape
    tau = data["tau"][:, None]
    dth, ddl = m["dth"], m["dd"]

    def tau_applied(u, om, w, wd):
        return ku * u - damp * om + JlL * (wc2 * w + c2z * wd) + bias

    def rhs(u, th, om, w, wd):
        ta = tau_applied(u, om, w, wd)
        f = jnp.where(jnp.abs(om) < tol, jnp.clip(ta, -Fs, Fs), Fc * jnp.sign(om))
        omd = (ta - f) / J
        wdd = -wc2 * w - c2z * wd - Lk * omd
        return om, omd, wd, wdd

    filt_th, filt_d = filters

    def rhs_all(u, th, om, w, wd, *f):
        """The arm's derivatives, then the filters' (states f: y_θ if filtered, y_d if)."""
        out = rhs(u, th, om, w, wd)
        f = list(f)
        if filt_th:
            out += (const["omega_th"] * (th - f.pop(0)),)
        if filt_d:
            out += (const["omega_d"] * (gain * w - f.pop(0)),)
        return out

    def rk4(u, s):
        k1_ = rhs_all(u, *s)
        s2 = [a + 0.5 * h * b for a, b in zip(s, k1_)]
        k2_ = rhs_all(u, *s2)
        s3 = [a + 0.5 * h * b for a, b in zip(s, k2_)]
        k3_ = rhs_all(u, *s3)
        s4 = [a + h * b for a, b in zip(s, k3_)]
        k4_ = rhs_all(u, *s4)
        new = [a + h / 6.0 * (b + 2 * c + 2 * d + e)
               for a, b, c, d, e in zip(s, k1_, k2_, k3_, k4_)]
        th1, om1, w1, wd1 = new[:4]
        ta = tau_applied(u, om1, w1, wd1)
        stuck = ((s[1] * om1 <= 0.0) | (jnp.abs(om1) < tol)) & (jnp.abs(ta) <= Fs)
        wd1 = jnp.where(stuck, wd1 + Lk * om1, wd1)
        om1 = jnp.where(stuck, 0.0, om1)
        return (th1, om1, w1, wd1) + tuple(new[4:])

    def sense(x):
        """What the A/D converters read: the filters' outputs where there are filters."""
        f = list(x[4:])
        th = f.pop(0) if filt_th else x[0]
        d = f.pop(0) if filt_d else gain * x[2]
        return _quantise(th, const["q_th"]), _quantise(d, const["q_d"])

    x0 = (m["th0"], m["om0"], m["w0"], m["wd0"])
    x0 = x0 + ((x0[0],) if filt_th else ()) + ((gain * x0[2],) if filt_d else ())
    y0t, y0d = sense(x0)
    bt0 = jnp.broadcast_to(y0t, (n_buf,) + shape)
    bd0 = jnp.broadcast_to(y0d, (n_buf,) + shape)
    def delayed(buf, k, d):
        """Ring-buffer read of the sample written d samples ago, (L, P)."""
        idx = jnp.mod(k - d, n_buf)
        return jnp.take_along_axis(buf, idx[None], axis=0)[0]
    ctrl0 = (jnp.zeros(shape),) * 4
    # the command applied before the first computed one: the logged command where there is
    # one (a loop that was running before the log started), else 0
    ubuf0 = jnp.broadcast_to(data["volt"][:, :1], (comp_delay + 1,) + shape)
    acc0 = (jnp.zeros(shape), jnp.zeros(shape), jnp.zeros(shape, dtype=bool))

    def sample(carry, inp):
        x, bt, bd, ctrl, ubuf, started, acc, k = carry
        Kt = inp[-1][:, :, None]  # (L, 4, 1)
        k1, k2, k3, k4 = Kt[:, 0], Kt[:, 1], Kt[:, 2], Kt[:, 3]
        r, yt_log, yd_log, wt, wdw, v = (a[:, None] for a in inp[:-1])
        st, sd = sense(x)
        slot = jnp.mod(k, n_buf)
        bt = jax.lax.dynamic_update_index_in_dim(bt, st, slot, 0)
        bd = jax.lax.dynamic_update_index_in_dim(bd, sd, slot, 0)
        mt = delayed(bt, k, dth)
        md = delayed(bd, k, ddl)
        if open_loop:
            uc = jnp.broadcast_to(v, shape)
        else:
            tp = jnp.where(started, ctrl[0], mt)
            dp = jnp.where(started, ctrl[1], md)
            tdot = (tau * ctrl[2] + mt - tp) / (tau + dt)
            ddot = (tau * ctrl[3] + md - dp) / (tau + dt)
            ctrl = (mt, md, tdot, ddot)
            uc = k1 * (r - mt) - k2 * md - k3 * tdot - k4 * ddot
        ubuf = jnp.concatenate([uc[None], ubuf[:-1]], axis=0)
        u = jnp.clip(ubuf[-1], -const["limit"], const["limit"])
        xn = x
        for _ in range(substeps):
            xn = rk4(u, xn)
        et, ed = mt - yt_log, md - yd_log
        bad = acc[2] | ~(jnp.abs(xn[0]) < 1e3) | ~(jnp.abs(xn[2]) < 1e3)
        acc = (acc[0] + wt * et * et, acc[1] + wdw * ed * ed, bad)
        # keep a diverged rollout finite (its cost is replaced by the caller)
        xn = tuple(jnp.where(bad, 0.0, a) for a in xn)
        out = (mt, md, u, x[0], x[2]) if record else None
        return (xn, bt, bd, ctrl, ubuf, jnp.array(True), acc, k + 1), out

    carry0 = (x0, bt0, bd0, ctrl0, ubuf0, jnp.array(False), acc0, jnp.array(0))
    K = data["K"]  # (L, N, 4) per sample, or (L, 4) constant
    if K.ndim == 2:
        K = jnp.broadcast_to(K[:, None, :], data["ref"].shape + (4,))
    xs = tuple(data[k].T for k in ("ref", "y_th", "y_d", "w_th", "w_d", "volt")) + (
        jnp.swapaxes(K, 0, 1),)  # (N, L, 4)
    carry, out = jax.lax.scan(sample, carry0, xs)
    return carry[6], out  # the accumulators


_STATIC = ("substeps", "n_buf", "comp_delay", "open_loop", "filters")


@partial(jax.jit, static_argnames=_STATIC)
def closed_loop_cost(m: dict, data: dict, const: dict, *, substeps: int = 2, n_buf: int = 8,
                     comp_delay: int = 0, open_loop: bool = False,
                     filters: tuple[bool, bool] = (False, False)):
    """Weighted sums of squared errors (L, P) of the measured hub angle and tip deflection,
    and a flag (L, P) for rollouts that diverged (|θ| or |w| beyond 1e3). ``filters``:
    whether the hub / tip channel has a low-pass filter (cutoffs in ``const``)."""
    acc, _ = _scan(m, data, const, substeps=substeps, n_buf=n_buf, comp_delay=comp_delay,
                   open_loop=open_loop, record=False, filters=filters)
    return acc


@partial(jax.jit, static_argnames=_STATIC)
def closed_loop_run(m: dict, data: dict, const: dict, *, substeps: int = 2, n_buf: int = 8,
                    comp_delay: int = 0, open_loop: bool = False,
                    filters: tuple[bool, bool] = (False, False)):
    """Trajectories, each (N, L, P): measured θ, measured d, command u, true θ, true w;
    and the accumulators of :func:`closed_loop_cost`."""
    acc, out = _scan(m, data, const, substeps=substeps, n_buf=n_buf, comp_delay=comp_delay,
                     open_loop=open_loop, record=True, filters=filters)
    return out, acc


def as_jax(tree: dict) -> dict:
    """float64 (or int for the delays) JAX arrays of a dict of numbers/arrays."""
    out = {}
    for k, v in tree.items():
        a = np.asarray(v)
        out[k] = jnp.asarray(a, dtype=int if k in ("dth", "dd") else float)
    return out
