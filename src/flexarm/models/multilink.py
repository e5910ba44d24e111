"""Planar multi-link flexible arm in a vertical plane: assumed-mode Lagrangian model.

De Luca & Siciliano (IEEE SMC 1991; IEEE TRA 1993, "DLS"). Generalised coordinates
q = (θ, δ): joint angles θ ∈ Rⁿ (rad) and modal deflections δ = (δ_1, …, δ_n), δ_i ∈ R^{m_i}
(m), link i's deflection w_i(x, t) = Σ_j φ_ij(x) δ_ij(t) with the modes of
:mod:`flexarm.models.modes`. Equations of motion (DLS eq. (1)):

    B(q) q̈ + c(q, q̇) + g(q) + [0; D δ̇ + K δ] = [u; 0].

Kinematics (standard DLS). Frame i (origin p_i at joint i, angle α_i from the x axis):

    α_1 = θ_1,   α_{i+1} = α_i + φ_i'(ℓ_i)ᵀ δ_i + θ_{i+1},
    p_1 = 0,     p_{i+1} = p_i + R(α_i) [ℓ_i, φ_i(ℓ_i)ᵀ δ_i]ᵀ,

and the point x ∈ [0, ℓ_i] of link i is at p_i + R(α_i) [x, w_i(x)]ᵀ. With (a, b) = R(α_i)ᵀ ṗ_i
the base velocity in frame i, the kinetic energy of link i is exact in the modal integrals
m_i = ρℓ, d_i = ∫ρx = ρℓ²/2, J_0i = ∫ρx² = ρℓ³/3, v = ∫ρφ, w = ∫ρxφ, Z = ∫ρφφᵀ:

    2T_i = m(a² + b²) + J_0 α̇² + 2 d b α̇ − 2 a α̇ vᵀδ + α̇² δᵀZδ + 2 b vᵀδ̇ + 2 α̇ wᵀδ̇ + δ̇ᵀZδ̇.

Hub i (mass m_hi at p_i, inertia J_hi turning with α_i) adds ½ m_hi |ṗ_i|² + ½ J_hi α̇_i²;
the payload (m_p, J_p) at p_{n+1} turning with α_n + φ_n'(ℓ)ᵀδ_n adds the same form.
Gravity (acceleration vector γ = g ĝ, default g = 9.81 m/s² along −y):

    U_g = −γᵀ [ Σ_i (m_i p_i + R(α_i) [d_i, v_iᵀδ_i]ᵀ) + Σ_{i≥2} m_hi p_i + m_p p_{n+1} ],

elastic energy U_e = ½ δᵀKδ, K = blockdiag(k_ij) (N/m), D modal damping (N·s/m), and the
joints' cable springs U_c = ½ Σ_i k_c,i (θ_i + φ_i'(ℓ)ᵀδ_i)² (N·m/rad; the turn across joint
i from its stator to link i's tip; 0 unless ``arm.joints[i].cable_stiffness`` is given).

Derivation. T and U_g above are the Lagrangian's definitions; the dynamics follow from them
by JAX automatic differentiation, once, for any number of links and modes:

    B(q) = ∂²T/∂q̇²  (jax.hessian),   c(q, q̇) = (∂²T/∂q̇∂q) q̇ − ∂T/∂q  (jax.jvp, jax.grad),
    g(q) = ∂U_g/∂q  (jax.grad),     C(q, q̇): Christoffel symbols of jax.jacfwd(B),

(``*_autodiff`` methods and :meth:`MultiLinkPlant.coriolis_matrix`). Differentiating T inside
the right-hand side is slow on CPU (measured: ≈ 60 µs per evaluation, 7–20 s compilation for
an RK4 loop of the benchmark arm), so the plant evaluates the same B, c, g in their explicit
particle form: every mass element dm at r moves with ṙ = J_r(q) q̇, hence

    B = Σ ∫ J_rᵀ J_r dm,     c + g = Σ ∫ J_rᵀ (J̇_r q̇ − γ) dm,

with the position Jacobians J_p of the joints and the velocity-product accelerations
p̈_vp = J̇_p q̇ propagated along the chain,

    J_p,i+1 = J_p,i + R(α_i) [−W_i a_i ; ℓ_i a_i + f_i],        W_i = φ_i(ℓ)ᵀδ_i,
    p̈_vp,i+1 = p̈_vp,i + R(α_i) [−α̇_i² ℓ_i − 2α̇_i Ẇ_i ; −α̇_i² W_i],

(a_i the constant row with α̇_i = a_iᵀq̇, f_i the row with Ẇ_i = f_iᵀq̇) and the modal
integrals closing the integrals over each link. With P = R(α_i)ᵀ(p̈_vp,i − γ), (A_x; A_y) =
R(α_i)ᵀ J_p,i and y_i = d_i a_i + v-row:

    B = B₀ + Σ_i [ m̄_i J_p,iᵀJ_p,i + sym(A_yᵀ y_i − vᵀδ_i A_xᵀ a_i) + δ_iᵀZδ_i a_iᵀa_i ]
        + m_p J_p,eᵀJ_p,e
    c + g = Σ_i [ m̄_i J_p,iᵀ(p̈_vp,i − γ) − A_xᵀ(α̇²d + 2α̇ vᵀδ̇) − A_yᵀ α̇² vᵀδ
                  + a_iᵀ(d P_y − vᵀδ P_x + 2α̇ δᵀZδ̇) ] + [0; v P_y − α̇² Zδ]_i
            + m_p J_p,eᵀ(p̈_vp,e − γ)

(m̄_i = m_i + m_hi, B₀ the constant rotary-inertia, ∫ρxφ and Z terms). The expressions are
traced as scalars, skipping structural zeros. For the right-hand side they are recorded once
per arm structure as a :class:`flexarm.layered.Program` together with the solve of
B q̈ = f (block LDLᵀ with 3×3 pivot blocks in closed form) and emitted as a few fused
kernels in which every shared value is computed once (7 layers for the benchmark arm;
measured 2.7x faster per rollout than the scalar trace with an unrolled Cholesky, and the
same program runs a batch carried as (n_x, batch) as one SIMD kernel per layer). Tests check
B, c, g against the autodiff derivation to round-off and Ḃ − 2C for skew-symmetry.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm import layered
from flexarm.models.modes import LinkModes, link_modes
from flexarm.models.plant import Plant
from flexarm.specs.multilink import MultiLinkArm


def _is_zero(a) -> bool:
    return isinstance(a, (int, float)) and a == 0


def _is_one(a) -> bool:
    return isinstance(a, (int, float)) and a == 1


def _mul(*fs):
    """Product of scalars skipping structural zeros and ones (Python numbers)."""
    out = 1.0
    for f in fs:
        if _is_zero(f):
            return 0.0
        if _is_one(f):
            continue
        out = f if _is_one(out) else out * f
    return out


def _add(*ts):
    """Sum of scalars skipping structural zeros."""
    out = 0.0
    for t in ts:
        if _is_zero(t):
            continue
        out = t if _is_zero(out) else out + t
    return out


def _dot(u, v):
    return _add(*(_mul(a, b) for a, b in zip(u, v, strict=False)))


def _chol_solve_lists(A, b):
    """Unrolled Cholesky solve of A y = b; A a list of rows of scalars, b a list."""
    n = len(b)
    L = [[0.0] * n for _ in range(n)]
    inv: list[Any] = [0.0] * n  # 1/√s: JAX scalars
    for j in range(n):
        s = A[j][j]
        for k in range(j):
            s = s - L[j][k] * L[j][k]
        r = 1.0 / jnp.sqrt(s)
        inv[j] = r
        for i in range(j + 1, n):
            t = A[i][j]
            for k in range(j):
                t = t - L[i][k] * L[j][k]
            L[i][j] = t * r
    z = [0.0] * n
    for i in range(n):
        t = b[i]
        for k in range(i):
            t = t - L[i][k] * z[k]
        z[i] = t * inv[i]
    y = [0.0] * n
    for i in reversed(range(n)):
        t = z[i]
        for k in range(i + 1, n):
            t = t - L[k][i] * y[k]
        y[i] = t * inv[i]
    return y


def chol_solve(A: Array, b: Array) -> Array:
    """Solve A y = b for a small symmetric positive-definite A (static size) by an unrolled
    Cholesky factorisation: a few hundred scalar operations, no LAPACK call."""
    n = A.shape[0]
    rows = [[A[i, j] for j in range(n)] for i in range(n)]
    return jnp.stack(_chol_solve_lists(rows, [b[i] for i in range(n)]))


def _rot(a: Array, v0: Array, v1: Array) -> Array:
    c, s = jnp.cos(a), jnp.sin(a)
    return jnp.stack([c * v0 - s * v1, s * v0 + c * v1])


class MultiLinkPlant(Plant):
    """The arm as a plant: x = (θ, δ, θ̇, δ̇) (rad, m, rad/s, m/s), u = joint torques (N·m).

    Signals: ``theta_i`` (rad), ``delta_i_j`` (m), ``tip_x``, ``tip_y`` (m, the end point
    p_{n+1}). Numeric fields are arrays (traceable, vmap-able); the mode counts are static.
    """

    n_modes: tuple[int, ...] = eqx.field(static=True)
    lengths: Array
    link_mass: Array
    link_d: Array
    link_J0: Array
    hub_mass: Array
    hub_inertia: Array
    payload_mass: Array
    payload_inertia: Array
    phi_tip: Array
    dphi_tip: Array
    v: Array
    w: Array
    Z: Array
    K: Array
    D: Array
    gamma: Array
    cable: Array
    torque_limit: Array
    rate_rows: Array
    tip_rows: Array
    v_rows: Array
    B0: Array

    # ----------------------------------------------------------------- sizes
    @property
    def n_links(self) -> int:
        return len(self.n_modes)

    @property
    def n_delta(self) -> int:
        return sum(self.n_modes)

    @property
    def n_q(self) -> int:
        return self.n_links + self.n_delta

    def _slices(self) -> list[slice]:
        out, k = [], 0
        for m in self.n_modes:
            out.append(slice(k, k + m))
            k += m
        return out

    # ----------------------------------------------------------------- kinematics / energy
    def _chain(self, q: Array, qd: Array | None):
        """Frames of the links: per link (α, α̇, p, ṗ, δ_i, δ̇_i, slice) and the end point
        (p_{n+1}, ṗ_{n+1}, angle, rate). With qd None the rates are None."""
        n = self.n_links
        th, dl = q[:n], q[n:]
        # the rates: arrays with qd, None without (every use is under "if qd is not None")
        thd: Any = None if qd is None else qd[:n]
        dld: Any = None if qd is None else qd[n:]
        alpha = th[0]
        alphad: Any = None if qd is None else thd[0]
        p = jnp.zeros(2)
        pd: Any = None if qd is None else jnp.zeros(2)
        links = []
        for i, sl in enumerate(self._slices()):
            di = dl[sl]
            ddi: Any = None if qd is None else dld[sl]
            links.append((alpha, alphad, p, pd, di, ddi, sl))
            if sl.stop > sl.start:
                wl = self.phi_tip[sl] @ di
                sl_ang = self.dphi_tip[sl] @ di
            else:
                wl = sl_ang = jnp.zeros(())
            p = p + _rot(alpha, self.lengths[i], wl)
            if qd is not None:
                if sl.stop > sl.start:
                    wld = self.phi_tip[sl] @ ddi
                    sld = self.dphi_tip[sl] @ ddi
                else:
                    wld = sld = jnp.zeros(())
                pd = pd + _rot(alpha, -alphad * wl, alphad * self.lengths[i] + wld)
            alpha = alpha + sl_ang
            if qd is not None:
                alphad = alphad + sld
            if i + 1 < n:
                alpha = alpha + th[i + 1]
                if qd is not None:
                    alphad = alphad + thd[i + 1]
        return links, (p, pd, alpha, alphad)

    def kinetic_energy(self, q: Array, qd: Array) -> Array:
        """T(q, q̇) (J): links in their own frames with the modal integrals, hubs, payload
        (module docstring)."""
        links, (_, pde, _, ae) = self._chain(q, qd)
        T = 0.0
        for i, (al, ald, _, pd, di, ddi, sl) in enumerate(links):
            c, s = jnp.cos(al), jnp.sin(al)
            a = c * pd[0] + s * pd[1]
            b = -s * pd[0] + c * pd[1]
            two_t = (
                self.link_mass[i] * (a * a + b * b)
                + self.link_J0[i] * ald * ald
                + 2.0 * self.link_d[i] * b * ald
                + self.hub_inertia[i] * ald * ald
            )
            if sl.stop > sl.start:
                Z = self.Z[sl, sl]
                two_t = (
                    two_t
                    - 2.0 * a * ald * (self.v[sl] @ di)
                    + ald * ald * (di @ Z @ di)
                    + 2.0 * b * (self.v[sl] @ ddi)
                    + 2.0 * ald * (self.w[sl] @ ddi)
                    + ddi @ Z @ ddi
                )
            if i > 0:
                two_t = two_t + self.hub_mass[i] * (pd @ pd)
            T = T + 0.5 * two_t
        return T + 0.5 * (self.payload_mass * (pde @ pde) + self.payload_inertia * ae * ae)

    def gravity_potential(self, q: Array) -> Array:
        """U_g(q) (J), zero with every mass at the origin."""
        links, (pe, _, _, _) = self._chain(q, None)
        moment = self.payload_mass * pe
        for i, (al, _, p, _, di, _, sl) in enumerate(links):
            vd = self.v[sl] @ di if sl.stop > sl.start else jnp.zeros(())
            moment = (
                moment
                + (self.link_mass[i] + self.hub_mass[i] * (i > 0)) * p
                + _rot(al, self.link_d[i], vd)
            )
        return -(self.gamma @ moment)

    def cable_angles(self, q: Array) -> Array:
        """a_i = θ_i + φ'_i(ℓ_i)ᵀδ_i (rad): the turn across joint i from its stator (the base,
        or link i−1's tip) to link i's tip, which a joint's cable spring (``cable_stiffness``
        k_c,i, :class:`flexarm.specs.multilink.Joint`) resists with the torque −k_c,i a_i."""
        n = self.n_links
        out = []
        for i, sl in enumerate(self._slices()):
            a = q[i]
            if sl.stop > sl.start:
                a = a + self.dphi_tip[sl] @ q[n + sl.start : n + sl.stop]
            out.append(a)
        return jnp.stack(out)

    def elastic_potential(self, q: Array) -> Array:
        """U_e = ½ δᵀKδ + ½ Σ_i k_c,i a_i² (J), a_i of :meth:`cable_angles`."""
        dl = q[self.n_links :]
        return 0.5 * dl @ self.K @ dl + self._cable_potential(q)

    def energy(self, x: Array) -> Array:
        """Total energy T + U_g + U_e (J) of the state x."""
        q, qd = x[: self.n_q], x[self.n_q :]
        return self.kinetic_energy(q, qd) + self.gravity_potential(q) + self.elastic_potential(q)

    def tip_position(self, q: Array) -> Array:
        """End point p_{n+1} (m)."""
        return self._chain(q, None)[1][0]

    def joint_positions(self, q: Array) -> Array:
        """p_1, …, p_{n+1} (m), shape (n+1, 2)."""
        links, (pe, _, _, _) = self._chain(q, None)
        return jnp.stack([lk[2] for lk in links] + [pe])

    # ----------------------------------------------------------------- dynamics terms
    def _terms_lists(self, q: list, qd: list, gamma: tuple) -> tuple[list, list]:
        """B(q) (list of rows) and h = c(q, q̇) + g(q) (list) in the explicit particle form
        (module docstring), traced scalar by scalar; Python zeros in q̇ or γ drop terms."""
        n, nq = self.n_links, self.n_q
        Bm = [[0.0] * nq for _ in range(nq)]  # upper triangle

        def add_sym(u, v):  # Bm += u vᵀ + v uᵀ
            for j in range(nq):
                for k in range(j, nq):
                    t = _add(_mul(u[j], v[k]), _mul(v[j], u[k]))
                    if not _is_zero(t):
                        Bm[j][k] = _add(Bm[j][k], t)

        def add_outer(u, f):  # Bm += f u uᵀ
            for j in range(nq):
                if _is_zero(u[j]):
                    continue
                for k in range(j, nq):
                    t = _mul(f, u[j], u[k])
                    if not _is_zero(t):
                        Bm[j][k] = _add(Bm[j][k], t)

        # rows of symbolic scalars (JAX arrays or layered leaves), 0.0 where structurally zero
        h: list[Any] = [0.0] * nq
        a: list[Any] = [0.0] * nq
        Jx: list[Any] = [0.0] * nq
        Jy: list[Any] = [0.0] * nq
        accx = accy = 0.0
        g0x, g0y = gamma
        alpha = q[0]
        for i, sl in enumerate(self._slices()):
            idx = list(range(n + sl.start, n + sl.stop))
            a = list(a)
            a[i] = 1.0
            mt = self.link_mass[i] + self.hub_mass[i] if i > 0 else self.link_mass[i]
            d = self.link_d[i]
            c, s = layered.cos(alpha), layered.sin(alpha)
            Ax = [_add(_mul(c, x), _mul(s, y)) for x, y in zip(Jx, Jy, strict=True)]
            Ay = [_add(_mul(-1.0, s, x), _mul(c, y)) for x, y in zip(Jx, Jy, strict=True)]
            ad = _dot(a, qd)
            ad2 = _mul(ad, ad)
            y = [_mul(d, t) for t in a]
            if idx:
                di = [q[k] for k in idx]
                ddi = [qd[k] for k in idx]
                vi = [self.v[k - n] for k in idx]
                fi = [self.phi_tip[k - n] for k in idx]
                Zd = [_dot([self.Z[j - n, k - n] for k in idx], di) for j in idx]
                vd, dZd, W = _dot(vi, di), _dot(di, Zd), _dot(fi, di)
                vdd, Wd, dZdd = _dot(vi, ddi), _dot(fi, ddi), _dot(Zd, ddi)
                for j, k in enumerate(idx):
                    y[k] = _add(y[k], vi[j])
                add_sym([_mul(-1.0, vd, t) for t in Ax], a)
                add_outer(a, dZd)
            else:
                fi = []
                vd = dZd = W = vdd = Wd = dZdd = 0.0
            add_outer(Jx, mt)
            add_outer(Jy, mt)
            add_sym(Ay, y)
            gx, gy = _add(accx, _mul(-1.0, g0x)), _add(accy, _mul(-1.0, g0y))
            Px, Py = _add(_mul(c, gx), _mul(s, gy)), _add(_mul(-1.0, s, gx), _mul(c, gy))
            ca = _add(_mul(ad2, d), _mul(2.0, ad, vdd))
            cb = _mul(ad2, vd)
            cc = _add(_mul(d, Py), _mul(-1.0, vd, Px), _mul(2.0, ad, dZdd))
            fx, fy = _mul(mt, gx), _mul(mt, gy)
            for k in range(nq):
                h[k] = _add(
                    h[k],
                    _mul(fx, Jx[k]),
                    _mul(fy, Jy[k]),
                    _mul(-1.0, ca, Ax[k]),
                    _mul(-1.0, cb, Ay[k]),
                    _mul(cc, a[k]),
                )
            for j, k in enumerate(idx):
                h[k] = _add(h[k], _mul(vi[j], Py), _mul(-1.0, ad2, Zd[j]))
            # next joint: position Jacobian and velocity-product acceleration
            ell = self.lengths[i]
            tip: list[Any] = [0.0] * nq
            for j, k in enumerate(idx):
                tip[k] = fi[j]
            tx = [_mul(-1.0, W, t) for t in a]
            ty = [_add(_mul(ell, t), f) for t, f in zip(a, tip, strict=True)]
            Jx, Jy = (
                [_add(x, _mul(c, u), _mul(-1.0, s, v)) for x, u, v in zip(Jx, tx, ty, strict=True)],
                [_add(w, _mul(s, u), _mul(c, v)) for w, u, v in zip(Jy, tx, ty, strict=True)],
            )
            lx, ly = _add(_mul(-1.0, ad2, ell), _mul(-2.0, ad, Wd)), _mul(-1.0, ad2, W)
            accx = _add(accx, _mul(c, lx), _mul(-1.0, s, ly))
            accy = _add(accy, _mul(s, lx), _mul(c, ly))
            if idx:
                a = list(a)
                ei = [self.dphi_tip[k - n] for k in idx]
                for j, k in enumerate(idx):
                    a[k] = ei[j]
                alpha = _add(alpha, _dot(ei, di))
            if i + 1 < n:
                alpha = _add(alpha, q[i + 1])
        mp = self.payload_mass
        add_outer(Jx, mp)
        add_outer(Jy, mp)
        gx, gy = _add(accx, _mul(-1.0, g0x)), _add(accy, _mul(-1.0, g0y))
        for k in range(nq):
            h[k] = _add(h[k], _mul(mp, gx, Jx[k]), _mul(mp, gy, Jy[k]))
        B: list[list[Any]] = [[None] * nq for _ in range(nq)]
        for j in range(nq):
            for k in range(j, nq):
                B[j][k] = B[k][j] = _add(Bm[j][k], self.B0[j, k])
        return B, h

    def _terms(self, q: Array, qd: Array | None, gamma: Array | None) -> tuple[Array, Array]:
        """B(q) and h = c + g as arrays (qd None: no velocity terms; gamma None: no gravity)."""
        nq = self.n_q
        ql = [q[k] for k in range(nq)]
        qdl = [0.0] * nq if qd is None else [qd[k] for k in range(nq)]
        gam = (0.0, 0.0) if gamma is None else (gamma[0], gamma[1])
        B, h = self._terms_lists(ql, qdl, gam)
        h = [jnp.zeros(()) if _is_zero(t) else t for t in h]
        return jnp.stack([jnp.stack(r) for r in B]), jnp.stack(h)

    def mass_matrix(self, q: Array) -> Array:
        """B(q) (kg, kg·m, kg·m² by entry), explicit form (equals ∂²T/∂q̇²)."""
        return self._terms(q, None, None)[0]

    def coriolis(self, q: Array, qd: Array) -> Array:
        """c(q, q̇), explicit velocity-product form (equals Ḃq̇ − ∂T/∂q)."""
        return self._terms(q, qd, None)[1]

    def gravity(self, q: Array) -> Array:
        """g(q) = ∂U_g/∂q (N·m for θ rows, N for δ rows), explicit form."""
        return self._terms(q, None, self.gamma)[1]

    # Reference derivations by automatic differentiation of T and U_g (tests compare).
    def mass_matrix_autodiff(self, q: Array) -> Array:
        """B(q) = ∂²T/∂q̇² by jax.hessian of the kinetic energy."""
        return jax.hessian(self.kinetic_energy, argnums=1)(q, jnp.zeros(self.n_q))

    def coriolis_autodiff(self, q: Array, qd: Array) -> Array:
        """c = d/dt(∂T/∂q̇) − ∂T/∂q − B q̈ = (∂²T/∂q̇∂q) q̇ − ∂T/∂q by jax.jvp / jax.grad."""

        def p_of(qq):
            return jax.grad(self.kinetic_energy, argnums=1)(qq, qd)

        _, bdot_qd = jax.jvp(p_of, (q,), (qd,))
        return bdot_qd - jax.grad(self.kinetic_energy, argnums=0)(q, qd)

    def gravity_autodiff(self, q: Array) -> Array:
        """g = ∂U_g/∂q by jax.grad of the gravity potential."""
        return jax.grad(self.gravity_potential)(q)

    def coriolis_matrix(self, q: Array, qd: Array) -> Array:
        """C(q, q̇) from the Christoffel symbols of jax.jacfwd(B):
        C_ij = Σ_k ½(∂_k B_ij + ∂_j B_ik − ∂_i B_jk) q̇_k  (C q̇ = c, Ḃ − 2C skew-symmetric)."""
        dB = jax.jacfwd(self.mass_matrix)(q)  # dB[i, j, k] = ∂B_ij/∂q_k
        return 0.5 * (
            jnp.einsum("ijk,k->ij", dB, qd)
            + jnp.einsum("ikj,k->ij", dB, qd)
            - jnp.einsum("jki,k->ij", dB, qd)
        )

    def mass_matrix_dot(self, q: Array, qd: Array) -> Array:
        """Ḃ = Σ_k ∂B/∂q_k q̇_k (jax.jvp)."""
        return jax.jvp(self.mass_matrix, (q,), (qd,))[1]

    def gravity_jacobian(self, q: Array) -> Array:
        """∂g/∂q = ∂²U_g/∂q² (symmetric; jax.jacfwd of g)."""
        J = jax.jacfwd(self.gravity)(q)
        return 0.5 * (J + J.T)

    def generalized_forces(self, x: Array, u: Array) -> Array:
        """[u; −Kδ − Dδ̇] − c − g − ∂U_c/∂q (U_c the joints' cable springs): what B q̈
        equals."""
        nq = self.n_q
        q, qd = x[:nq], x[nq:]
        return self._forces(q, qd, u, self._terms(q, qd, self.gamma)[1])

    def _forces(self, q: Array, qd: Array, u: Array, h: Array) -> Array:
        n = self.n_links
        elastic = self.K @ q[n:] + self.D @ qd[n:]
        return jnp.concatenate([u, -elastic]) - h - jax.grad(self._cable_potential)(q)

    def _cable_potential(self, q: Array) -> Array:
        """U_c = ½ Σ_i k_c,i a_i² (J), the joints' cable springs."""
        a = self.cable_angles(q)
        return 0.5 * jnp.sum(self.cable * a * a)

    def rhs(self, x: Array, u: Array) -> Array:
        """ẋ = (q̇, q̈), q̈ from :meth:`acceleration`; x may carry trailing batch dimensions."""
        return jnp.concatenate([x[self.n_q :], self.acceleration(x, u)])

    def acceleration(self, x: Array, u: Array) -> Array:
        """q̈ solving B q̈ = [u; −Kδ − Dδ̇] − c − g − ∂U_c/∂q. B, c + g and the forces
        are recorded once per arm structure as a :class:`flexarm.layered.Program` (the
        explicit particle form of :meth:`_terms_lists`, scalar by scalar) with the solve
        of B q̈ = f by block LDLᵀ elimination (:func:`flexarm.layered.solve_spd`, 3×3
        pivot blocks in closed form), and emitted as a few fused kernels that compute
        every shared value once. ``x`` may carry trailing batch dimensions, (n_x,
        *batch) with u (n_u, *batch): one kernel per layer then serves the whole batch."""
        return _emitted(self, False, x, u)

    def acceleration_and_mobility(self, x: Array, u: Array) -> tuple[Array, Array]:
        """q̈ of :meth:`acceleration` and the columns G_j = B⁻¹ e_j (j a joint) of the
        inverse mass matrix, shape (n_links, n_q): a unit torque at joint j changes q̈ by G_j,
        and G_jj is the joint's mobility (rad/s² per N·m) with every other coordinate free.
        Recorded in one :class:`flexarm.layered.Program` with the solve (the factorisation of
        B is shared by the n + 1 right-hand sides). Used for joint friction: the torque
        that holds joint j is q̈_j / G_jj, and a joint that sticks is stopped by the impulse
        along G_j (:class:`flexarm.models.assembly.Arm`)."""
        out = _emitted(self, True, x, u)
        nq, n = self.n_q, self.n_links
        return out[:nq], jnp.reshape(out[nq:], (n, nq) + out.shape[1:])

    #: per-link signals after q and the end point: θ̇_i, the tip deflection w_i(ℓ_i) (m) and
    #: the deflection angle w_i(ℓ_i)/ℓ_i (rad; the α of a torsional link)
    def signals(self, x: Array, u: Array) -> Array:
        nq, n = self.n_q, self.n_links
        q = x[:nq]
        w = self.tip_rows @ q
        return jnp.concatenate([q, self.tip_position(q), x[nq : nq + n], w, w / self.lengths])

    @property
    def command_limit(self) -> Array:
        return self.torque_limit


# Numbers of the plant read by the recorded right-hand side, and the scheduling threshold of
# the layered emission (measured on the benchmark arm: share = 8 and 3×3 pivot blocks give 7
# layers and the fastest rollout of the values tried, 4 to 128 and blocks of 2 or 3).
_PARAM_FIELDS = (
    "lengths",
    "link_mass",
    "link_d",
    "hub_mass",
    "payload_mass",
    "phi_tip",
    "dphi_tip",
    "v",
    "Z",
    "K",
    "D",
    "B0",
    "gamma",
    "cable",
)
_SHARE = 8
_SOLVE_BLOCK = 3


class _SymbolicPlant:
    """The plant's numbers as symbolic leaves of a :class:`layered.Program` (key (field,
    index)), with the plant's methods that trace B, c + g, for recording the right-hand side."""

    _slices = MultiLinkPlant._slices
    _terms_lists = MultiLinkPlant._terms_lists
    # the fields of _PARAM_FIELDS, set in __init__ (object arrays of leaves), for the checker
    lengths: Any
    link_mass: Any
    link_d: Any
    hub_mass: Any
    payload_mass: Any
    phi_tip: Any
    dphi_tip: Any
    v: Any
    Z: Any
    K: Any
    D: Any
    B0: Any
    gamma: Any
    cable: Any

    def __init__(self, prog: layered.Program, n_modes: tuple[int, ...]):
        self.n_modes = n_modes
        n, nd = len(n_modes), sum(n_modes)
        nq = n + nd
        shapes = {
            "lengths": (n,),
            "link_mass": (n,),
            "link_d": (n,),
            "hub_mass": (n,),
            "payload_mass": (),
            "phi_tip": (nd,),
            "dphi_tip": (nd,),
            "v": (nd,),
            "Z": (nd, nd),
            "K": (nd, nd),
            "D": (nd, nd),
            "B0": (nq, nq),
            "gamma": (2,),
            "cable": (n,),
        }
        for name in _PARAM_FIELDS:
            shape: tuple[int, ...] = shapes[name]
            if shape == ():
                setattr(self, name, prog.leaf((name, ())))
                continue
            arr = np.empty(shape, dtype=object)
            for idx in np.ndindex(shape):
                arr[idx] = prog.leaf((name, idx[0] if len(idx) == 1 else idx))
            setattr(self, name, arr)

    @property
    def n_links(self) -> int:
        return len(self.n_modes)

    @property
    def n_q(self) -> int:
        return len(self.n_modes) + sum(self.n_modes)


def _emitted(plant: MultiLinkPlant, columns: bool, x: Array, u: Array) -> Array:
    """The recorded program (:func:`_mobility_program` with ``columns``, else
    :func:`_rhs_program`) on ``plant``'s numbers, as a nested jit (:func:`_emitted_jit`):
    JAX traces it once per arm structure and argument shapes, and reuses that trace at every
    call inside a larger trace (a simulation step evaluates it 5 to 10 times: RK4's stages,
    the friction's projection, the signals), where tracing it each time took about half of
    the two-link fit's 8 s trace. XLA inlines the call: the compiled arithmetic is the
    same."""
    params = tuple(getattr(plant, f) for f in _PARAM_FIELDS)
    return _emitted_jit(plant.n_modes, columns, params, x, u)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _emitted_jit(n_modes: tuple[int, ...], columns: bool, params: tuple, x: Array, u: Array):
    prog, outputs = _mobility_program(n_modes) if columns else _rhs_program(n_modes)

    def value(key):
        name, idx = key
        if name == "x":
            return x[idx]
        if name == "u":
            return u[idx]
        return params[_PARAM_FIELDS.index(name)][idx]

    return prog.emit(outputs, value, share=_SHARE)


@functools.lru_cache(maxsize=64)
def _rhs_program(n_modes: tuple[int, ...]) -> tuple[layered.Program, list]:
    """q̈ = B⁻¹([u; −Kδ − Dδ̇] − c − g − ∂U_c/∂q) recorded symbolically for an arm
    structure (U_c the joints' cable springs, :meth:`MultiLinkPlant.cable_angles`)."""
    return _record(n_modes, columns=False)


@functools.lru_cache(maxsize=64)
def _mobility_program(n_modes: tuple[int, ...]) -> tuple[layered.Program, list]:
    """q̈ (as :func:`_rhs_program`) followed by the columns B⁻¹ e_j of the joints, recorded
    in a program of their own (the plain right-hand side's schedule is not touched)."""
    return _record(n_modes, columns=True)


def _record(n_modes: tuple[int, ...], columns: bool) -> tuple[layered.Program, list]:
    prog = layered.Program()
    sp = _SymbolicPlant(prog, n_modes)
    n, nq = sp.n_links, sp.n_q
    q = [prog.leaf(("x", k)) for k in range(nq)]
    qd = [prog.leaf(("x", nq + k)) for k in range(nq)]
    u = [prog.leaf(("u", k)) for k in range(n)]
    B, h = sp._terms_lists(q, qd, (sp.gamma[0], sp.gamma[1]))
    f = [u[k] - h[k] for k in range(n)]
    for sl in sp._slices():
        for i in range(sl.start, sl.stop):
            el = 0.0
            for j in range(sl.start, sl.stop):  # K and D are block diagonal
                el = el + sp.K[i, j] * q[n + j] + sp.D[i, j] * qd[n + j]
            f.append(-el - h[n + i])
    # the joints' cable springs: −k_c,i a_i on θ_i and −k_c,i a_i φ'_ij(ℓ) on δ_ij
    # (MultiLinkPlant.cable_angles); a spring of 0 subtracts exact zeros
    for i, sl in enumerate(sp._slices()):
        a = q[i]
        for j in range(sl.start, sl.stop):
            a = a + sp.dphi_tip[j] * q[n + j]
        tq = sp.cable[i] * a
        f[i] = f[i] - tq
        for j in range(sl.start, sl.stop):
            f[n + j] = f[n + j] - tq * sp.dphi_tip[j]
    out = layered.solve_spd(B, f, block=_SOLVE_BLOCK)
    if columns:
        for j in range(n):
            out = out + layered.solve_spd(
                B, [1.0 if k == j else 0.0 for k in range(nq)], block=_SOLVE_BLOCK
            )
    return prog, out


def signal_names(n_links: int, delta_names: list[str]) -> tuple[str, ...]:
    """Names of :meth:`MultiLinkPlant.signals`."""
    r = range(1, n_links + 1)
    return tuple(
        [f"theta_{i}" for i in r]
        + delta_names
        + ["tip_x", "tip_y"]
        + [f"theta_dot_{i}" for i in r]
        + [f"deflection_{i}" for i in r]
        + [f"deflection_angle_{i}" for i in r]
    )


@dataclass(frozen=True)
class MultiLinkModel:
    """An arm spec turned into numbers: the modes of each link and the plant.

    Convenience methods evaluate the plant's (jitted, cached) functions on NumPy inputs.
    """

    arm: MultiLinkArm
    modes: tuple[LinkModes, ...]
    tip_loads: tuple[tuple[float, float], ...]
    plant: MultiLinkPlant

    @property
    def n_links(self) -> int:
        return self.plant.n_links

    @property
    def n_modes(self) -> tuple[int, ...]:
        return self.plant.n_modes

    @property
    def n_q(self) -> int:
        return self.plant.n_q

    @property
    def n_delta(self) -> int:
        return self.plant.n_delta

    @property
    def K(self) -> np.ndarray:
        return np.asarray(self.plant.K)

    @property
    def D(self) -> np.ndarray:
        return np.asarray(self.plant.D)

    def state(self, theta=None, delta=None, theta_dot=None, delta_dot=None) -> np.ndarray:
        """Flat state (θ, δ, θ̇, δ̇) with zeros for what is not given."""
        n, nd = self.n_links, self.n_delta
        parts = []
        for v, k in ((theta, n), (delta, nd), (theta_dot, n), (delta_dot, nd)):
            a = np.zeros(k) if v is None else np.asarray(v, dtype=float).reshape(-1)
            if a.shape != (k,):
                raise ValueError(f"expected {k} values, got {a.shape[0]}")
            parts.append(a)
        return np.concatenate(parts)

    def mass_matrix(self, q) -> np.ndarray:
        return np.asarray(_jit_call(self.plant, "mass_matrix", jnp.asarray(q, float)))

    def coriolis(self, q, qd) -> np.ndarray:
        return np.asarray(
            _jit_call(self.plant, "coriolis", jnp.asarray(q, float), jnp.asarray(qd, float))
        )

    def coriolis_matrix(self, q, qd) -> np.ndarray:
        return np.asarray(
            _jit_call(self.plant, "coriolis_matrix", jnp.asarray(q, float), jnp.asarray(qd, float))
        )

    def mass_matrix_dot(self, q, qd) -> np.ndarray:
        return np.asarray(
            _jit_call(self.plant, "mass_matrix_dot", jnp.asarray(q, float), jnp.asarray(qd, float))
        )

    def gravity(self, q) -> np.ndarray:
        return np.asarray(_jit_call(self.plant, "gravity", jnp.asarray(q, float)))

    def call(self, name: str, *args) -> np.ndarray:
        """Any plant method ``name`` (jitted and cached) on NumPy arguments."""
        return np.asarray(_jit_call(self.plant, name, *(jnp.asarray(a, float) for a in args)))

    def gravity_jacobian(self, q) -> np.ndarray:
        return np.asarray(_jit_call(self.plant, "gravity_jacobian", jnp.asarray(q, float)))

    def energy(self, x) -> np.ndarray:
        """E(x) (J); x of shape (n_x,) or (N, n_x)."""
        x = jnp.asarray(x, float)
        if x.ndim == 2:
            return np.asarray(_jit_vcall(self.plant, "energy", x))
        return np.asarray(_jit_call(self.plant, "energy", x))

    def tip_position(self, q) -> np.ndarray:
        return np.asarray(_jit_call(self.plant, "tip_position", jnp.asarray(q, float)))

    def rhs(self, x, u) -> np.ndarray:
        return np.asarray(
            _jit_call(self.plant, "rhs", jnp.asarray(x, float), jnp.asarray(u, float))
        )


@eqx.filter_jit
def _jit_call(plant: MultiLinkPlant, name: str, *args):
    return getattr(plant, name)(*args)


@eqx.filter_jit
def _jit_vcall(plant: MultiLinkPlant, name: str, xs):
    return jax.vmap(getattr(plant, name))(xs)


def _tip_loads(arm: MultiLinkArm) -> list[tuple[float, float]]:
    """(M_L, J_L) at the tip of each link: everything distal with the following links
    straight (aligned with the link), J_L about the tip."""
    n = len(arm.links)
    out = []
    for i in range(n):
        M = J = 0.0
        r = 0.0  # distance from the tip of link i to joint k
        for k in range(i + 1, n):
            lk = arm.links[k]
            hk = arm.hubs[k]
            M += hk.mass + lk.link_mass
            J += hk.inertia + hk.mass * r**2
            J += lk.inertia_about(r)  # ∫ρ (x + r)² dx over link k
            r += lk.length
        M += arm.payload.mass
        J += arm.payload.inertia + arm.payload.mass * r**2
        out.append((M, J))
    return out


def torsional_modes(lk) -> LinkModes:
    """The one coordinate of a torsional link (a rigid body on a torsional spring at its
    root) as an assumed mode φ(x) = x, δ = α (rad): v = m c, w = Z = J_0, k = K,
    φ(ℓ) = ℓ, φ'(ℓ) = 1 (:class:`flexarm.specs.multilink.Link`)."""
    J0, K = lk.joint_inertia, lk.torsional_stiffness
    return LinkModes(
        length=lk.length,
        linear_density=lk.rho,
        flexural_rigidity=float("nan"),
        tip_mass=0.0,
        tip_inertia=0.0,
        mode_type="torsional",
        beta_l=np.array([np.nan]),
        omega=np.array([math.sqrt(K / J0)]),
        coeffs=np.full((1, 4), np.nan),
        tip_value=np.array([lk.length]),
        tip_slope=np.array([1.0]),
        v=np.array([lk.first_moment]),
        w=np.array([J0]),
        Z=np.array([[J0]]),
        K=np.array([[K]]),
    )


def build_multilink(arm: MultiLinkArm) -> MultiLinkModel:
    """Modes of every link (clamped-mass with the distal loads, clamped-free, or the one
    coordinate of a torsional link), modal integrals, stiffness and damping, and the plant."""
    loads = _tip_loads(arm)
    modes = []
    for i, (lk, (M, J)) in enumerate(zip(arm.links, loads, strict=True)):
        if lk.model == "torsional":
            modes.append(torsional_modes(lk))
            continue
        try:
            # a rigid link (modes = 0) may omit EI; any positive value gives no modes then
            EI = lk.flexural_rigidity if lk.flexural_rigidity is not None else 1.0
            modes.append(
                link_modes(
                    lk.length,
                    lk.rho,
                    EI,
                    lk.n_modes,
                    tip_mass=M,
                    tip_inertia=J,
                    mode_type=lk.mode_type,
                )
            )
        except ValueError as exc:
            raise type(exc)(f"link {i + 1}: {exc}") from None
    n_modes = tuple(m.n_modes for m in modes)
    nd = sum(n_modes)

    def cat(f):
        return np.concatenate([f(m) for m in modes]) if nd else np.zeros(0)

    def blk(f):
        out = np.zeros((nd, nd))
        k = 0
        for m in modes:
            out[k : k + m.n_modes, k : k + m.n_modes] = f(m)
            k += m.n_modes
        return out

    def damping(lk, m):
        if lk.model == "torsional":
            if lk.torsional_damping is not None:
                return np.array([[lk.torsional_damping]])
            return np.array([[2.0 * lk.damping_ratio * math.sqrt(m.K[0, 0] * m.Z[0, 0])]])
        if lk.modal_damping is not None:
            return np.diag(np.asarray(lk.modal_damping, float))
        return np.diag(2.0 * lk.damping_ratio * m.omega * m.mass)

    Dm = np.zeros((nd, nd))
    k = 0
    for lk, m in zip(arm.links, modes, strict=True):
        Dm[k : k + m.n_modes, k : k + m.n_modes] = damping(lk, m)
        k += m.n_modes

    n = len(arm.links)
    nq = n + nd
    # Constant rows: α̇_i = a_iᵀq̇ (last row: the tip of link n), Ẇ_i = f_iᵀq̇, v_iᵀδ̇_i = v_rowᵀq̇.
    rate = np.zeros((n + 1, nq))
    tip_rows = np.zeros((n, nq))
    v_rows = np.zeros((n, nq))
    w_rows = np.zeros((n, nq))
    a = np.zeros(nq)
    k = n
    for i, m in enumerate(modes):
        a = a.copy()
        a[i] = 1.0
        rate[i] = a
        sl = slice(k, k + m.n_modes)
        tip_rows[i, sl] = m.tip_value
        v_rows[i, sl] = m.v
        w_rows[i, sl] = m.w
        a = a.copy()
        a[sl] += m.tip_slope
        k += m.n_modes
    rate[n] = a
    # q-independent part of B: rotary inertias, ∫ρxφ coupling, modal mass Z.
    B0 = np.zeros((nq, nq))
    for i, lk in enumerate(arm.links):
        ai = rate[i]
        B0 += (lk.joint_inertia + arm.hubs[i].inertia) * np.outer(ai, ai)
        B0 += np.outer(ai, w_rows[i]) + np.outer(w_rows[i], ai)
    B0 += arm.payload.inertia * np.outer(rate[n], rate[n])
    B0[n:, n:] += blk(lambda m: m.Z)

    names_d = [f"delta_{i + 1}_{j + 1}" for i, m in enumerate(modes) for j in range(m.n_modes)]
    names_t = [f"theta_{i + 1}" for i in range(n)]
    state_names = tuple(
        names_t
        + names_d
        + [f"theta_dot_{i + 1}" for i in range(n)]
        + [f"{s.replace('delta', 'delta_dot')}" for s in names_d]
    )
    gx, gy = arm.gravity_unit
    lim = np.full(n, np.inf) if arm.torque_limit is None else np.asarray(arm.torque_limit, float)
    f = jnp.asarray
    plant = MultiLinkPlant(
        state_names=state_names,
        signal_names=signal_names(n, names_d),
        input_names=tuple(f"torque_{i + 1}" for i in range(n)),
        n_modes=n_modes,
        lengths=f([lk.length for lk in arm.links]),
        link_mass=f([lk.link_mass for lk in arm.links]),
        link_d=f([lk.first_moment for lk in arm.links]),
        link_J0=f([lk.joint_inertia for lk in arm.links]),
        hub_mass=f([h.mass for h in arm.hubs]),
        hub_inertia=f([h.inertia for h in arm.hubs]),
        payload_mass=f(arm.payload.mass),
        payload_inertia=f(arm.payload.inertia),
        phi_tip=f(cat(lambda m: m.tip_value)),
        dphi_tip=f(cat(lambda m: m.tip_slope)),
        v=f(cat(lambda m: m.v)),
        w=f(cat(lambda m: m.w)),
        Z=f(blk(lambda m: m.Z)),
        K=f(blk(lambda m: m.K)),
        D=f(Dm),
        gamma=f([arm.gravity * gx, arm.gravity * gy]),
        cable=f([j.cable_stiffness for j in arm.joint_specs]),
        torque_limit=f(lim),
        rate_rows=f(rate),
        tip_rows=f(tip_rows),
        v_rows=f(v_rows),
        B0=f(B0),
    )
    return MultiLinkModel(arm=arm, modes=tuple(modes), tip_loads=tuple(loads), plant=plant)
