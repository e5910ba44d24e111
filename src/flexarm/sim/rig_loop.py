"""Batched closed-loop (or open-loop replay) simulation of bench logs, for fitting: the one
simulator's fast kernel for one plant kind, the rotary servo rig (issue #43: a faster kernel
lives inside the simulator and equals it; the servo preset's objective runs it).

The plant is the one plant of every arm, :class:`flexarm.models.assembly.Arm`, in its
one-link case: a hub of inertia J driving one pinned tip mode (the classic 2-DOF rotary
flexible link), built per parameter point by :func:`single_link_arm` and integrated by
:func:`flexarm.sim.integrate.integrate_hold` (RK4 with the stick projection after every
substep), exactly as :func:`flexarm.sim.sampled.simulate_loop` integrates it. In link
coordinates (θ, ω, w, ẇ), w the tip deflection (m) relative to the hub line,

    ẅ  = −ω_c² w − 2 ζ ω_c ẇ − L ω̇                      (link, hub-clamped frequency ω_c)
    J ω̇ = τ_a − F,   τ_a = k_u u − (k_ω + B) ω + (J_l / L)(ω_c² w + 2 ζ ω_c ẇ) + τ_bias

with k_u = η_g η_m K_g K_m / R, k_ω = k_u K_g K_m (voltage drive), J_l = m L² the link
inertia and C = J_l ω_c² its stiffness (N·m/rad). F is Karnopp friction
(:mod:`flexarm.models.friction`: stuck while |τ_a| <= F_s, F_c sign(ω) when moving; after
every substep a hub that crossed zero velocity, or entered the band |ω| < Δv, while
|τ_a| <= F_s is stopped with the link's absolute motion unchanged). What is special here is
the sample loop around it, for fitting: every log and parameter point at once (the batch
(L, P) carried last in every array), sensor delays that are traced parameters, the
logged per-sample gains, and the cost summed inside the scan; it equals
:func:`flexarm.sim.sampled.simulate_loop` on the same rig to 1e-9 (tests/test_time_domain_fit.py).

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
k = D (:class:`flexarm.identification.time_domain.objective.Objective`). (Feeding the controller the
log's own readings while a delay line fills was tried: it moved the synthetic acceptance fits into
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

from flexarm.models.assembly import Arm, SingleLinkBody
from flexarm.models.friction import Friction
from flexarm.models.single_link import SIGNALS
from flexarm.sim.integrate import integrate_hold, solver_for
from flexarm.sim.sampled import FilteredPlant

#: Names of the model numbers (each an array (L, P)) that :func:`closed_loop_cost` takes.
MODEL_KEYS = (
    "J",
    "B",
    "wc2",
    "c2z",
    "JlL",
    "Fc",
    "Fs",
    "bias",
    "gain",
    "dth",
    "dd",
    "th0",
    "om0",
    "w0",
    "wd0",
)
#: Names of the per-log data (arrays (L, ...)).
DATA_KEYS = ("ref", "y_th", "y_d", "w_th", "w_d", "volt", "K", "tau")


def _quantise(x: Array, q: Array) -> Array:
    return jnp.where(q > 0, jnp.round(x / jnp.where(q > 0, q, 1.0)) * q, x)


def single_link_arm(m: dict, const: dict, pushed: bool = False) -> Arm:
    """The rig as the one plant (:class:`flexarm.models.assembly.Arm`, one joint) for one
    parameter point: a hub of inertia J driving one pinned tip mode. In the beam block's
    absolute coordinates z_b = (y, ẏ), y = L θ + w the tip's position (m),

        ÿ = −ω_c² (y − L θ) − 2ζω_c (ẏ − L θ̇),
        (θ_t, C_t, w) = (y / L,  −(J_l / L)(ω_c² (y − L θ) + 2ζω_c (ẏ − L θ̇)),  y − L θ),

    which is the module docstring's ẅ = −ω_c² w − 2ζω_c ẇ − L ω̇ with J ω̇ = τ_a − F,
    τ_a = k_u u − (k_ω + B) ω − C_t + τ_bias (FRB eq. 1; the beam block of
    :mod:`flexarm.models.lumped_beam`); Karnopp friction (F_c, F_s) at the joint. ``pushed``:
    the stiffer clamp of a gear train pushed stuck (:class:`~flexarm.models.assembly.
    SingleLinkBody`; ``const["push_s"]``, ``const["push_T"]``, ``const["push_T1"]`` N·m)."""
    L = const["length"]
    wc2, c2z, JlL = m["wc2"], m["c2z"], m["JlL"]
    z, o = jnp.zeros_like(wc2), jnp.ones_like(wc2)
    Ab = jnp.stack([jnp.stack([z, o]), jnp.stack([-wc2, -c2z])])
    Bb = jnp.stack([jnp.stack([z, z]), jnp.stack([wc2 * L, c2z * L])])
    Cb = jnp.stack([jnp.stack([o / L, z]), jnp.stack([-JlL * wc2, -JlL * c2z]), jnp.stack([o, z])])
    Db = jnp.stack(
        [jnp.stack([z, z]), jnp.stack([JlL * wc2 * L, JlL * c2z * L]), jnp.stack([-L * o, z])]
    )
    body = SingleLinkBody(
        J=m["J"],
        Ab=Ab,
        Bb=Bb,
        Cb=Cb,
        Db=Db,
        state_names=("motor_angle", "motor_velocity", "beam_0", "beam_1"),
        push_stiffening=const["push_s"] if pushed else 0.0,
        push_threshold=const["push_T"] if pushed else float("inf"),
        push_full=const["push_T1"] if pushed else float("inf"),
        pushed=pushed,
    )
    fr = Friction(
        model="coulomb", coulomb=m["Fc"], static=m["Fs"], velocity_tolerance=const["vel_tol"]
    )

    def vec(v):  # one joint; the batch, if any, last
        return (v * o)[None]

    return Arm(
        state_names=body.state_names,
        signal_names=SIGNALS,
        input_names=("voltage",),
        body=body,
        k_u=vec(const["k_u"]),
        k_omega=vec(const["k_omega"]),
        viscous=vec(m["B"]),
        bias=vec(m["bias"]),
        limit=vec(const["limit"]),
        frictions=(fr,),
        kind="single",
    )


#: the plant signals the rig's sensors read: hub angle and tip deflection w (m)
_HUB, _TIP = SIGNALS.index("motor_angle"), SIGNALS.index("tip_deflection")


def _scan(
    m: dict,
    data: dict,
    const: dict,
    *,
    substeps: int,
    n_buf: int,
    comp_delay: int,
    open_loop: bool,
    record: bool,
    filters: tuple[bool, bool] = (False, False),
    pushed: bool = False,
):
    """The sampled-data loop over all samples; m: model numbers (L, P); data: per-log
    arrays (L, N) / (L, 4) / (L,); const: scalars (dt, L, k_u, k_om, q_th, q_d, limit, tol,
    and omega_th / omega_d for the filtered channels). Every quantity carries the batch
    (L, P) last: the plant's state is (n_x, L, P), integrated by
    :func:`flexarm.sim.integrate.integrate_hold` (an explicit batch axis is 1.2x quicker
    here than ``vmap`` of one rollout, whose per-rollout ring-buffer index becomes a
    scatter and a gather)."""
    dt, L = const["dt"], const["length"]
    h = dt / substeps
    gain = m["gain"]
    shape = gain.shape
    tau = data["tau"][:, None]
    dth, ddl = m["dth"], m["dd"]
    arm = single_link_arm(m, const, pushed)
    filt_th, filt_d = filters
    index = ((_HUB,) if filt_th else ()) + ((_TIP,) if filt_d else ())
    plant = arm
    if index:
        one = jnp.ones(shape)
        gains = jnp.stack(([one] if filt_th else []) + ([gain] if filt_d else []))
        omega = jnp.stack(
            ([const["omega_th"] * one] if filt_th else [])
            + ([const["omega_d"] * one] if filt_d else [])
        )
        plant = FilteredPlant.around(arm, index, gains, omega, [SIGNALS[i] for i in index])
    solver = solver_for("rk4")

    def deflection(x):
        """The tip deflection w = y − L θ (m) from the beam block's absolute coordinate."""
        return x[2] - L * x[0]

    def sense(x):
        """What the A/D converters read: the filters' outputs where there are filters."""
        f = list(x[4:])
        th = f.pop(0) if filt_th else x[0]
        d = f.pop(0) if filt_d else gain * deflection(x)
        return _quantise(th, const["q_th"]), _quantise(d, const["q_d"])

    th0, om0, w0 = m["th0"], m["om0"], m["w0"]
    x0 = [th0, om0, L * th0 + w0, L * om0 + m["wd0"]]
    x0 = jnp.stack(x0 + ([th0] if filt_th else []) + ([gain * w0] if filt_d else []))
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
        xn = integrate_hold(plant, x, u[None], h, substeps, solver)
        et, ed = mt - yt_log, md - yd_log
        bad = acc[2] | ~(jnp.abs(xn[0]) < 1e3) | ~(jnp.abs(deflection(xn)) < 1e3)
        acc = (acc[0] + wt * et * et, acc[1] + wdw * ed * ed, bad)
        # keep a diverged rollout finite (its cost is replaced by the caller)
        xn = jnp.where(bad, 0.0, xn)
        out = (mt, md, u, x[0], deflection(x)) if record else None
        return (xn, bt, bd, ctrl, ubuf, jnp.array(True), acc, k + 1), out

    carry0 = (x0, bt0, bd0, ctrl0, ubuf0, jnp.array(False), acc0, jnp.array(0))
    K = data["K"]  # (L, N, 4) per sample, or (L, 4) constant
    if K.ndim == 2:
        K = jnp.broadcast_to(K[:, None, :], data["ref"].shape + (4,))
    xs = tuple(data[k].T for k in ("ref", "y_th", "y_d", "w_th", "w_d", "volt")) + (
        jnp.swapaxes(K, 0, 1),
    )  # (N, L, 4)
    carry, out = jax.lax.scan(sample, carry0, xs)
    return carry[6], out  # the accumulators


_STATIC = ("substeps", "n_buf", "comp_delay", "open_loop", "filters", "pushed")


@partial(jax.jit, static_argnames=_STATIC)
def closed_loop_cost(
    m: dict,
    data: dict,
    const: dict,
    *,
    substeps: int = 2,
    n_buf: int = 8,
    comp_delay: int = 0,
    open_loop: bool = False,
    filters: tuple[bool, bool] = (False, False),
    pushed: bool = False,
):
    """Weighted sums of squared errors (L, P) of the measured hub angle and tip deflection,
    and a flag (L, P) for rollouts that diverged (|θ| or |w| beyond 1e3). ``filters``:
    whether the hub / tip channel has a low-pass filter (cutoffs in ``const``)."""
    acc, _ = _scan(
        m,
        data,
        const,
        substeps=substeps,
        n_buf=n_buf,
        comp_delay=comp_delay,
        open_loop=open_loop,
        record=False,
        filters=filters,
        pushed=pushed,
    )
    return acc


@partial(jax.jit, static_argnames=_STATIC)
def closed_loop_run(
    m: dict,
    data: dict,
    const: dict,
    *,
    substeps: int = 2,
    n_buf: int = 8,
    comp_delay: int = 0,
    open_loop: bool = False,
    filters: tuple[bool, bool] = (False, False),
    pushed: bool = False,
):
    """Trajectories, each (N, L, P): measured θ, measured d, command u, true θ, true w;
    and the accumulators of :func:`closed_loop_cost`."""
    acc, out = _scan(
        m,
        data,
        const,
        substeps=substeps,
        n_buf=n_buf,
        comp_delay=comp_delay,
        open_loop=open_loop,
        record=True,
        filters=filters,
        pushed=pushed,
    )
    return out, acc


def as_jax(tree: dict) -> dict:
    """float64 (or int for the delays) JAX arrays of a dict of numbers/arrays."""
    out = {}
    for k, v in tree.items():
        a = np.asarray(v)
        out[k] = jnp.asarray(a, dtype=int if k in ("dth", "dd") else float)
    return out
