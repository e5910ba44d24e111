"""The nominal check of a controller before it leaves flexarm as C (issue #45): is the
sampled closed loop of the scenario, with its delays, stable on the nominal plant?

The loop is the one the simulator runs (:mod:`flexarm.sim.sampled`), linearised at rest:

* the plant (:func:`flexarm.sim.build.prepare`'s loop plant, joint friction left out as
  :func:`flexarm.models.linearize.frictionless` does: Coulomb friction and stiction have no
  linearisation at rest) and the analog sensor low-passes, ẋ = A x + B u, held over the
  sample period T (exact zero-order hold, ``expm``);
* the sensors' gains, digital filters and delays (samples), the controller's own step
  (any exportable controller; its Jacobian by ``jax.jacfwd`` at rest, reference 0), the
  computation delay (samples), the command held from the previous sample for signals that
  read it;
* left out: saturation, D/A and encoder quantisation, sensor noise, the logger's zeroing
  (a constant offset), a friction compensation's sign term (zero slope at rest).

Blocks at several rates (``[[controllers]]``, ``every``) make the loop periodic: the map
over one hyper-period (the least common multiple of the blocks' ``every``) is the product
of the per-sample Jacobians. The loop is stable when every eigenvalue z of that map lies
inside the unit circle; :func:`nominal_check` calls it unstable when max |z| exceeds
1 + ``tolerance`` (default 1e-6: eigenvalues on the circle within round-off, e.g. a
controller state no signal drives, are not failures).

This is the gate's nominal check (:mod:`flexarm.design.gate`) as a linear test: the gate
simulates the design's step with friction and saturation; the export checks the loop
itself, for every scenario and design, in well under a second.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["NominalCheck", "nominal_check", "loop_matrix"]

#: the longest hyper-period (samples) of blocks at several rates the check multiplies out
MAX_HYPERPERIOD = 10_000


@dataclass(frozen=True)
class NominalCheck:
    """The nominal check's result: ``stable`` (bool), ``radius`` (max |z| of the
    closed loop's eigenvalues over one hyper-period), ``poles`` (those eigenvalues),
    ``period_samples`` (the hyper-period), ``verdict`` (``"stable"`` or
    ``"unstable on the nominal plant (...)"``, the gate's wording) and ``notes`` (what the
    linear check left out)."""

    stable: bool
    radius: float
    poles: np.ndarray
    period_samples: int
    verdict: str
    notes: list[str] = field(default_factory=list)


def _everies(ctrl) -> list[int]:
    """The ``every`` of each block in a controller tree."""
    out = []
    ev = getattr(ctrl, "every", None)
    if isinstance(ev, int) and ev > 1:
        out.append(ev)
    for p in getattr(ctrl, "parts", ()) or ():
        out += _everies(p)
    for attr in ("inner", "outer", "controller", "feedback"):
        sub = getattr(ctrl, attr, None)
        if sub is not None and hasattr(sub, "step") and sub is not ctrl:
            out += _everies(sub)
    return out


def loop_matrix(scenario, controller=None) -> tuple[np.ndarray, int]:
    """The closed loop's linear map over one hyper-period at rest (module doc) and the
    hyper-period in samples. ``controller``: a controller object instead of the
    scenario's (as :func:`flexarm.sim.build.prepare` takes it)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    from jax.flatten_util import ravel_pytree
    from scipy.linalg import expm

    from flexarm.models.assembly import Arm
    from flexarm.models.linearize import frictionless
    from flexarm.sim.build import prepare

    prep = prepare(scenario, controller)
    loop = prep.loop
    plant = loop.plant
    if isinstance(plant, Arm):
        plant = frictionless(plant)
    ctrl = loop.controller
    if not hasattr(ctrl, "init") or type(ctrl).__name__ == "ContinuousLaw":
        raise ValueError("a continuous-time law has no sampled loop to check")
    sens = loop.sensors
    dt = float(loop.dt)
    n, m = int(plant.n_states), int(plant.n_inputs)
    x0, u0 = jnp.zeros(n), jnp.zeros(m)
    A, B = (np.asarray(a, float) for a in jax.jacfwd(plant.rhs, argnums=(0, 1))(x0, u0))
    Sx, Su = (np.asarray(a, float) for a in jax.jacfwd(plant.signals, argnums=(0, 1))(x0, u0))
    gain = np.asarray(sens.gain, float).reshape(-1) * np.ones(len(sens.names))
    idx = list(sens.index)
    # analog low-passes: yf' = ω (g s_i − yf), integrated with the plant
    filt = list(sens.filtered)
    nf = len(filt)
    omega = np.asarray(sens.omega, float).reshape(-1) if nf else np.zeros(0)
    N = n + nf
    Ac, Bc = np.zeros((N, N)), np.zeros((N, m))
    Ac[:n, :n], Bc[:n] = A, B
    for j, c in enumerate(filt):
        w = omega[j] if omega.size > 1 else omega[0]
        Ac[n + j, :n] = w * gain[c] * Sx[idx[c]]
        Bc[n + j] = w * gain[c] * Su[idx[c]]
        Ac[n + j, n + j] = -w
    big = np.zeros((N + m, N + m))
    big[:N, :N], big[:N, N:] = Ac * dt, Bc * dt
    E = expm(big)
    Ad, Bd = jnp.asarray(E[:N, :N]), jnp.asarray(E[:N, N:])
    Sx, Su, gainj = jnp.asarray(Sx), jnp.asarray(Su), jnp.asarray(gain)
    digital = list(sens.digital)
    delays = [int(d) for d in np.asarray(sens.delays)]
    dmax = sens.depth
    n_ch = len(sens.names)
    refs0 = {k: jnp.asarray(0.0) for k in prep.references}
    refs0.setdefault("reference", jnp.asarray(0.0))

    cstate0 = ctrl.init()
    cfloat0, cstatic0 = eqx.partition(cstate0, eqx.is_inexact_array)
    nd = len(digital)
    xd0 = jnp.zeros(tuple(sens.fA.shape[:2])) if nd and sens.fA is not None else jnp.zeros((0,))
    z0 = (
        jnp.zeros(N),
        cfloat0,
        jnp.zeros((dmax + 1, n_ch)),
        jnp.zeros((loop.delay + 1, m)),
        jnp.zeros(m),
        xd0,
    )
    flat0, unravel = ravel_pytree(z0)
    flat0 = jnp.zeros_like(flat0)

    def step(flat, cstatic):
        z, cf, sbuf, ubuf, u_prev, xd = unravel(flat)
        x = z[:n]
        s = Sx @ x + Su @ u_prev
        y = gainj * jnp.stack([s[i] for i in idx]) if idx else jnp.zeros((0,))
        if nf:
            y = y.at[jnp.asarray(filt)].set(z[n:])
        xd_new = xd
        if nd:
            ys = y[jnp.asarray(digital)]
            v = jnp.sum(jnp.asarray(sens.fC) * xd, axis=-1) + jnp.asarray(sens.fD) * ys
            xd_new = (
                jnp.einsum("ijk,ik->ij", jnp.asarray(sens.fA), xd)
                + jnp.asarray(sens.fB) * ys[:, None]
            )
            y = y.at[jnp.asarray(digital)].set(v)
        sbuf = jnp.concatenate([y[None], sbuf[:-1]], axis=0)
        meas = {nm: sbuf[d, c] for c, (nm, d) in enumerate(zip(sens.names, delays, strict=True))}
        cstate, u_c = ctrl.step(eqx.combine(cf, cstatic), meas, refs0)
        cf_new, cstatic_new = eqx.partition(cstate, eqx.is_inexact_array)
        ubuf = jnp.concatenate([jnp.reshape(u_c, (1, m)), ubuf[:-1]], axis=0)
        u = ubuf[-1]
        z_new = Ad @ z + Bd @ u
        out, _ = ravel_pytree((z_new, cf_new, sbuf, ubuf, u, xd_new))
        return out, cstatic_new

    everies = _everies(ctrl)
    P = 1
    for e in everies:
        P = P * e // math.gcd(P, e)
    if P > MAX_HYPERPERIOD:
        raise ValueError(
            f"the controller blocks' periods make a hyper-period of {P} samples "
            f"(> {MAX_HYPERPERIOD}); the loop is not checked"
        )
    jac = eqx.filter_jit(lambda f, cs: jax.jacfwd(lambda g: step(g, cs)[0])(f))
    nxt = eqx.filter_jit(step)
    M = np.eye(flat0.size)
    cstatic = cstatic0
    for _ in range(P):
        M = np.asarray(jac(flat0, cstatic), float) @ M
        if P > 1:
            _, cstatic = nxt(flat0, cstatic)
    return M, P


def nominal_check(scenario, controller=None, *, tolerance: float = 1e-6) -> NominalCheck:
    """The nominal closed-loop stability check of ``scenario``'s sampled loop with its
    delays (module doc). Raises ValueError where the loop cannot be linearised."""
    M, P = loop_matrix(scenario, controller)
    poles = np.linalg.eigvals(M) if M.size else np.zeros(0, complex)
    r = float(np.max(np.abs(poles))) if poles.size else 0.0
    if not np.isfinite(r):
        raise ValueError("the linearised loop has non-finite entries")
    stable = r <= 1.0 + tolerance
    notes = ["linear check at rest: saturation, quantisation, noise and Coulomb friction left out"]
    if stable:
        verdict = "stable"
    else:
        per = f" over {P} samples" if P > 1 else ""
        verdict = (
            f"unstable on the nominal plant (the sampled loop with its delays has an "
            f"eigenvalue |z| = {r:.6g} > 1{per})"
        )
    return NominalCheck(stable, r, poles, P, verdict, notes)
