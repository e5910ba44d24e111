"""One plant for every arm: a body (the links' mechanics) driven at each joint through a
drive, against joint friction.

Every arm flexarm simulates or fits is an :class:`Arm`, assembled by :func:`assemble` from
the scenario's ``[arm]``:

* the **body**: the mechanics of the links with joint torques τ as inputs. Two explicit
  implementations stay behind the one protocol:

  - :class:`SingleLinkBody`: one hub of inertia J driving one link given as a linear beam
    block (lumped masses, transfer functions or rigid; FRB eqs. 12–16), written out by hand
    (:mod:`flexarm.models.lumped_beam`), J θ̈ = τ − C_t;
  - :class:`flexarm.models.multilink.MultiLinkPlant`: any number of links with assumed
    modes or torsional springs, under gravity (DLS eq. 1), its right-hand side recorded as
    a few fused kernels (:mod:`flexarm.layered`), B(q) q̈ + c + g + [0; Kδ + Dδ̇] = [τ; 0].

* per joint j a **drive** (FRB eq. 1 and the geared servo), linear in the command u_j:

      τ_d,j = k_u,j u_j − (k_ω,j + V_j) θ̇_j + b_j

  (torque source k_u = 1, k_ω = 0; current drive k_u = K_t, k_ω = 0; voltage drive
  k_u = η_g η_m K_g K_m / R, k_ω = k_u K_g K_m; V viscous friction, b a bias torque);

* per joint a **friction** model (:mod:`flexarm.models.friction`: Karnopp Coulomb with
  exact stick, Stribeck, LuGre, or none), acting against the *holding torque* τ_a,j: the
  friction that would keep joint j at rest with every other coordinate free,

      τ_a,j = q̈_j(τ_d) / G_jj,     G_j = B⁻¹ e_j

  (for the single link τ_a = τ_d − C_t, G = 1/J); the joints S that may stick at once
  (inside their velocity band, or crossing zero after a substep) share one balance,
  τ_a,S = G_SS⁻¹ q̈_S(τ_d), so that several stuck joints stay exactly at rest together.
  The joint accelerations are then
  q̈ = q̈(τ_d) − Σ_j G_j F_j, and after each integration substep a Karnopp joint that
  crossed zero velocity (or is inside the velocity band) while |τ_a,j| <= F_s,j is stopped
  by the impulse along G_j that zeroes θ̇_j (for several stuck joints at once, the impulses
  λ solve G_SS λ = θ̇_S exactly). For the single link this is ω = 0 with the link's absolute
  motion unchanged, as in FRB's hub.

The state is the body's followed by the friction states (LuGre bristles), the inputs are the
joints' commands (``current``/``voltage`` for one link, ``torque_i``/``current_i``/
``voltage_i`` for several), the signals are the body's, then per joint the friction torque
(``friction_torque`` or ``friction_torque_i``, N·m).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.models.friction import Friction
from flexarm.models.multilink import chol_solve
from flexarm.models.plant import Plant


def _mv(A: Array, x: Array) -> Array:
    """A @ x for tiny matrices: the column products A[:, j] x[j], summed pairwise. A batch
    may be carried last: A (rows, cols, *batch) with x (cols, *batch).

    Only elementwise operations, which XLA fuses into the right-hand side's kernel. On CPU
    ``@`` is a library call per product (~30x slower), and ``jnp.sum(A * x, -1)`` becomes,
    under ``vmap``, separate reduction kernels with a (batch, rows, cols) broadcast of
    ``A`` per RK stage (docs/performance.md). The pairwise order ((t1 + t0) + (t3 + t2))
    reproduces the results of that ``jnp.sum`` form bit for bit (XLA's reduce order)."""
    terms = [A[:, j] * x[j] for j in range(A.shape[1])]
    if not terms:
        return jnp.zeros(A.shape[:1] + A.shape[2:])
    while len(terms) > 1:
        pairs = [terms[i + 1] + terms[i] for i in range(0, len(terms) - 1, 2)]
        terms = pairs + ([terms[-1]] if len(terms) % 2 else [])
    return terms[0]


class SingleLinkBody(eqx.Module):
    """A hub of inertia J (kg·m²) and one link as a linear beam block with state z_b,

        J θ̈ = τ − C_t,   ż_b = A_b z_b + B_b (θ, θ̇),   (θ_t, C_t, w_tip) = C_b z_b + D_b (θ, θ̇)

    (FRB eqs. 12–16; :mod:`flexarm.models.lumped_beam`). State (θm, θ̇m, z_b...).

    ``pushed`` (static; off by default): a gear train that clamps the link more stiffly
    while the motor pushes it stuck. Where the hub is at rest (θ̇m = 0 exactly: a stuck
    Karnopp joint), the beam's elastic terms (its position columns: z_b = (positions,
    velocities)) act (1 + s φ) times, in ż_b and in the coupling torque C_t alike, with
    s = ``push_stiffening`` and φ = clip((|τ| − τ_0) / (τ_1 − τ_0), 0, 1) of the drive
    torque |τ| between ``push_threshold`` τ_0 and ``push_full`` τ_1 (N·m; a step at τ_0
    where τ_1 <= τ_0), so the clamped link rings √(1 + s φ) times faster (the servo rig's
    ``guesses.pushed_ringing`` estimates s, τ_0 and τ_1 from the logs' stuck phases)."""

    J: Array | float
    Ab: Array
    Bb: Array
    Cb: Array
    Db: Array
    state_names: tuple[str, ...] = eqx.field(static=True)
    push_stiffening: Array | float = 0.0
    push_threshold: Array | float = float("inf")
    push_full: Array | float = float("inf")
    pushed: bool = eqx.field(static=True, default=False)

    n_joints = 1
    signal_names = (
        "motor_angle",
        "motor_velocity",
        "tip_angle",
        "tip_deflection",
        "coupling_torque",
    )
    friction_names = ("friction_torque",)

    def joint_velocity(self, x: Array) -> Array:
        return x[1:2]

    def _beam(self, x: Array):
        nb = self.Ab.shape[0]
        hub = jnp.stack([x[0], x[1]])
        zb = x[2 : 2 + nb]
        return hub, zb, _mv(self.Cb, zb) + _mv(self.Db, hub)

    def balance(self, x: Array, tau: Array, bias: Array):
        """The holding torque τ_a = τ − C_t + b (N·m, shape (1,)) and what :meth:`derivative`
        reuses."""
        hub, zb, yb = self._beam(x)
        if not self.pushed:
            tau_a = tau[0] - yb[1] + bias[0]
            return tau_a[None], (hub, zb, yb, tau_a, None, yb[1])
        # the stiffened clamp (class docstring): the elastic part of C_t, s times more
        nb = self.Ab.shape[0]
        npos = nb // 2
        width = self.push_full - self.push_threshold
        over = jnp.abs(tau[0]) - self.push_threshold
        frac = jnp.where(
            width > 0,
            jnp.clip(over / jnp.where(width > 0, width, 1.0), 0.0, 1.0),
            (over > 0).astype(float),
        )
        ex = jnp.where(hub[1] == 0.0, self.push_stiffening * frac, 0.0)
        ct = yb[1] + ex * (_mv(self.Cb[1:2, :npos], zb[:npos])[0] + self.Db[1, 0] * hub[0])
        tau_a = tau[0] - ct + bias[0]
        return tau_a[None], (hub, zb, yb, tau_a, ex, ct)

    def derivative(self, x: Array, f: Array, aux) -> Array:
        """ẋ of the body under friction f (N·m, shape (1,))."""
        hub, zb, yb, tau_a, ex, _ = aux
        zb_dot = _mv(self.Ab, zb) + _mv(self.Bb, hub)
        if ex is not None:
            nb = self.Ab.shape[0]
            npos = nb // 2
            elastic = _mv(self.Ab[npos:, :npos], zb[:npos]) + self.Bb[npos:, 0] * hub[0]
            zb_dot = jnp.concatenate([zb_dot[:npos], zb_dot[npos:] + ex * elastic])
        return jnp.concatenate([jnp.stack([hub[1], (tau_a - f[0]) / self.J]), zb_dot])

    def signals(self, x: Array, aux) -> Array:
        hub, zb, yb, tau_a, _, ct = aux  # C_t with the pushed clamp's stiffening, if any
        return jnp.stack([hub[0], hub[1], yb[0], yb[2], ct])

    def stop(self, x: Array, stuck: Array, aux=None) -> Array:
        """Stop the stuck hub: θ̇m = 0; the beam's absolute coordinates are unchanged."""
        return x.at[1].set(jnp.where(stuck[0], 0.0, x[1]))


class _MultiBody:
    """The protocol methods of :class:`~flexarm.models.multilink.MultiLinkPlant` as a body
    (functions of the plant, kept here so the plant module does not know about friction)."""

    @staticmethod
    def balance(p, x: Array, tau: Array, bias: Array, held: Array):
        """Holding torques: for the joints ``held`` (a mask: those that may stick) together,
        τ_a,S = G_SS⁻¹ q̈_S(τ) (the friction torques that keep all of them at rest at once);
        for the others alone, τ_a,j = q̈_j(τ) / G_jj."""
        qdd, G = p.acceleration_and_mobility(x, tau + bias)
        n = p.n_links
        mob = jnp.stack([G[j, j] for j in range(n)])
        alone = qdd[:n] / mob
        if n == 1:
            return alone, (qdd, G)
        s = held.astype(x.dtype)
        M = G[:, :n] * s[:, None] * s[None, :] + jnp.diag(1.0 - s)
        # M is symmetric positive definite (G_SS, the stuck joints' block of the inverse
        # mass matrix, beside the identity): an unrolled Cholesky solve, not a LAPACK call
        # per trajectory (measured: the two-link fit's batch of 23, one call, 7.1 -> 4.6 s)
        together = chol_solve(M, s * qdd[:n])
        return jnp.where(held, together, alone), (qdd, G)

    @staticmethod
    def derivative(p, x: Array, f: Array, aux) -> Array:
        qdd, G = aux
        for j in range(p.n_links):
            qdd = qdd - G[j] * f[j]
        return jnp.concatenate([x[p.n_q :], qdd])

    @staticmethod
    def stop(p, x: Array, stuck: Array, aux) -> Array:
        """Impulses λ along G_j of the stuck joints S with G_SS λ = θ̇_S: θ̇_S = 0 after."""
        _, G = aux
        n, nq = p.n_links, p.n_q
        s = stuck.astype(x.dtype)
        M = G[:, :n] * s[:, None] * s[None, :] + jnp.diag(1.0 - s)
        lam = chol_solve(M, s * x[nq : nq + n])  # M SPD, as in balance
        dqd = sum(G[j] * lam[j] for j in range(n))
        x = x.at[nq:].add(-dqd)
        # exactly zero (not a round-off residue) for the stuck joints
        return x.at[nq : nq + n].set(jnp.where(stuck, 0.0, x[nq : nq + n]))


class Arm(Plant):
    """The assembled arm (see the module docstring): ``body`` with per-joint drives
    (``k_u``, ``k_omega``, ``viscous``, ``bias``, ``limit``; arrays of shape (n_joints,),
    or tuples of Python floats, which jit folds into the compiled code as constants, as the
    hand-written single-link plant had them: 0.90 → 1.00 ms for the single-link benchmark
    when they were traced arrays, docs/performance.md) and ``frictions`` (one
    :class:`~flexarm.models.friction.Friction` per joint)."""

    body: Any
    k_u: Array
    k_omega: Array
    viscous: Array
    bias: Array
    limit: Array
    frictions: tuple[Friction, ...]
    kind: str = eqx.field(static=True, default="single")  # "single" or "multi"

    # ---------------------------------------------------------------- structure
    @property
    def n_joints(self) -> int:
        return len(self.frictions)

    @property
    def _n_body(self) -> int:
        return len(self.state_names) - sum(f.n_states for f in self.frictions)

    def _split(self, x: Array):
        nb = self._n_body
        zs, k = [], nb
        for f in self.frictions:
            zs.append(x[k : k + f.n_states])
            k += f.n_states
        return x[:nb], zs

    def _omega(self, xb: Array) -> Array:
        if self.kind == "single":
            return self.body.joint_velocity(xb)
        return xb[self.body.n_q : self.body.n_q + self.body.n_links]

    def _drive(self, xb: Array, u: Array, tau_ext: Array | None = None) -> Array:
        om = self._omega(xb)
        f = jnp.asarray
        tau = f(self.k_u) * u - f(self.k_omega) * om - f(self.viscous) * om
        return tau if tau_ext is None else tau + tau_ext

    def _balance(self, xb, tau, held):
        if self.kind == "single":
            return self.body.balance(xb, tau, jnp.asarray(self.bias))
        return _MultiBody.balance(self.body, xb, tau, jnp.asarray(self.bias), held)

    def _karnopp(self) -> list[bool]:
        return [fr.model in ("coulomb", "stribeck") for fr in self.frictions]

    def _slow(self, om: Array) -> Array:
        """Joints inside their stick band |θ̇| < Δv (Karnopp models only)."""
        return jnp.stack(
            [
                (jnp.abs(om[j]) < fr.velocity_tolerance) if k else jnp.zeros_like(om[j], dtype=bool)
                for j, (fr, k) in enumerate(zip(self.frictions, self._karnopp(), strict=True))
            ]
        )

    def _derivative(self, xb, f, aux):
        if self.kind == "single":
            return self.body.derivative(xb, f, aux)
        return _MultiBody.derivative(self.body, xb, f, aux)

    def _forces(self, x: Array, u: Array, held: Array | None = None, tau_ext: Array | None = None):
        xb, zs = self._split(x)
        tau = self._drive(xb, u, tau_ext)
        om = self._omega(xb)
        tau_a, aux = self._balance(xb, tau, self._slow(om) if held is None else held)
        fs, zds = [], []
        for j, fr in enumerate(self.frictions):
            f, zd = fr.torque(om[j], tau_a[j], zs[j])
            fs.append(f)
            zds.append(zd)
        return xb, tau, tau_a, aux, jnp.stack(fs), zds

    # ---------------------------------------------------------------- protocol
    def rhs(self, x: Array, u: Array, tau_ext: Array | None = None) -> Array:
        """ẋ under the commands u and, optionally, external joint torques ``tau_ext``
        (N·m per joint, beside the drives': a logged force disturbance)."""
        if self.kind == "multi" and self._frictionless:
            # no friction: one evaluation of the body, no mobility columns
            xb, _ = self._split(x)
            return self.body.rhs(xb, self._drive(xb, u, tau_ext) + self.bias)
        xb, tau, tau_a, aux, f, zds = self._forces(x, u, tau_ext=tau_ext)
        return jnp.concatenate([self._derivative(xb, f, aux)] + zds)

    @property
    def _frictionless(self) -> bool:
        return all(fr.model == "none" for fr in self.frictions)

    def signals(self, x: Array, u: Array, tau_ext: Array | None = None) -> Array:
        if self.kind == "single":
            xb, tau, tau_a, aux, f, _ = self._forces(x, u, tau_ext=tau_ext)
            return jnp.concatenate([self.body.signals(xb, aux), f])
        xb, _ = self._split(x)
        if self._frictionless:
            f = jnp.zeros((self.n_joints,) + x.shape[1:])
        else:
            f = self._forces(x, u, tau_ext=tau_ext)[4]
        return jnp.concatenate([self.body.signals(xb, u), f])

    def project(
        self, x_prev: Array, x_next: Array, u: Array, tau_ext: Array | None = None
    ) -> Array:
        karnopp = self._karnopp()
        if not any(karnopp):
            return x_next
        om_prev = self._omega(self._split(x_prev)[0])
        om = self._omega(self._split(x_next)[0])
        # candidates: joints that crossed zero velocity or are inside the band
        cand = jnp.stack(
            [
                ((om_prev[j] * om[j] <= 0.0) | (jnp.abs(om[j]) < fr.velocity_tolerance))
                if karnopp[j]
                else jnp.zeros_like(om[j], dtype=bool)
                for j, fr in enumerate(self.frictions)
            ]
        )
        xb, tau, tau_a, aux, _, _ = self._forces(x_next, u, held=cand, tau_ext=tau_ext)
        stuck = jnp.stack(
            [
                fr.sticks(om_prev[j], om[j], tau_a[j])
                if karnopp[j]
                else jnp.zeros_like(om[j], dtype=bool)
                for j, fr in enumerate(self.frictions)
            ]
        )
        if self.kind == "single":
            xb = self.body.stop(xb, stuck)
        else:
            xb = _MultiBody.stop(self.body, xb, stuck, aux)
        return jnp.concatenate([xb, x_next[self._n_body :]])

    @property
    def command_limit(self) -> Array:
        return jnp.asarray(self.limit, dtype=float)


# -------------------------------------------------------------------- assembly
@dataclass(frozen=True)
class JointNumbers:
    """A joint's drive in numbers: τ = k_u u − k_ω θ̇ (N·m), its limit and input name."""

    kind: str
    k_u: float
    k_omega: float
    limit: float
    added_inertia: float = 0.0

    @property
    def input_prefix(self) -> str:
        return {"torque": "torque", "current": "current", "voltage": "voltage"}[self.kind]


def joint_numbers(joint) -> JointNumbers:
    """:class:`flexarm.specs.multilink.Joint` → numbers (see :mod:`flexarm.models.motor`)."""
    d = joint.drive
    inf = float("inf")
    if d.drive == "torque":
        return JointNumbers("torque", 1.0, 0.0, d.limit or inf)
    if d.drive == "current":
        return JointNumbers("current", d.torque_constant, 0.0, d.current_limit or inf)
    ke = d.gear_ratio * d.motor_constant
    ku = d.gear_efficiency * d.motor_efficiency * ke / d.armature_resistance
    return JointNumbers(
        "voltage", ku, ku * ke, d.voltage_limit or inf, d.rotor_inertia * d.gear_ratio**2
    )


def multi_link_arm(spec) -> tuple[Arm, Any]:
    """The :class:`Arm` of a :class:`flexarm.specs.multilink.MultiLinkArm` and its
    :class:`~flexarm.models.multilink.MultiLinkModel` (hub inertias include the geared
    rotors' K_g² J_m)."""
    from flexarm.models.multilink import build_multilink

    joints = spec.joint_specs
    for i, j in enumerate(joints):
        if j.friction.pushed_stiffening > 0:
            raise ValueError(
                f"joint {i + 1}: friction.pushed_stiffening = {j.friction.pushed_stiffening:g}"
                ": the stiffer clamp of a pushed stuck gear train is modelled for a single "
                "link only; set it to 0"
            )
    nums = [joint_numbers(j) for j in joints]
    if any(n.added_inertia for n in nums):
        hubs = [
            h.model_copy(update={"inertia": h.inertia + n.added_inertia})
            for h, n in zip(spec.hubs, nums, strict=False)
        ]
        spec = spec.model_copy(update={"hubs": hubs})
    model = build_multilink(spec)
    body = model.plant
    frictions = tuple(Friction.from_spec(j.friction) for j in joints)
    n = len(joints)
    names = body.state_names + tuple(
        f"friction_z_{i + 1}" for i, fr in enumerate(frictions) for _ in range(fr.n_states)
    )

    def f(v):
        return jnp.asarray(np.asarray(v, dtype=float))

    arm = Arm(
        state_names=names,
        signal_names=body.signal_names + tuple(f"friction_torque_{i + 1}" for i in range(n)),
        input_names=tuple(f"{m.input_prefix}_{i + 1}" for i, m in enumerate(nums)),
        body=body,
        k_u=f([m.k_u for m in nums]),
        k_omega=f([m.k_omega for m in nums]),
        viscous=f([j.viscous for j in joints]),
        bias=f([j.friction.bias for j in joints]),
        limit=f([m.limit for m in nums]),
        frictions=frictions,
        kind="multi",
    )
    return arm, model
