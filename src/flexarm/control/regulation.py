"""Regulation of flexible arms under gravity: De Luca & Siciliano (IEEE TRA 9(4), 1993), "DLS".

Model (:mod:`flexarm.models.multilink`): B(q)q̈ + c(q, q̇) + g(q) + [0; Dδ̇ + Kδ] = [u; 0],
q = (θ, δ), g = (g_θ, g_δ). The paper's equations and data are only partly available; the
forms below are the project's reconstruction (shared/reference/deluca-siciliano.md).

* Residual deflection at the target, DLS eq. (9):  K δ_d + g_δ(θ_d, δ_d) = 0, solved for δ_d
  by Newton's method with the Jacobian K + ∂g_δ/∂δ from jax (:func:`residual_deflection`).
* PD law with constant gravity compensation, DLS eq. (8) (no deflection feedback):

      u = K_P (θ_d − θ) − K_D θ̇ + g_θ(θ_d, δ_d)                       (:func:`law_pd_constant`)

* Law (30), on-line gravity compensation; the exact form is unknown, two variants:

      (30a) u = K_P (θ_d − θ) − K_D θ̇ + g_θ(θ, δ)        measured δ    (:func:`law_pd_online`)
      (30b) u = K_P (θ_d − θ) − K_D θ̇ + g_θ(θ, δ̄(θ))    quasi-static δ̄ (:func:`law_pd_quasistatic`)

  with δ̄(θ) solving K δ̄ + g_δ(θ, δ̄) = 0 (a fixed number of Newton steps from δ = 0 inside
  the loop, default 4). At the target both reduce to eq. (8)'s compensation.
* Interpolating trajectory (the paper's remedy for large gains and large initial errors):
  with ``duration`` T > 0 the set point θ_d is replaced by the quintic
  θ_r(t) = θ_0 + (θ_d − θ_0) s(t/T), s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ (s = 1 after T), and the damping
  acts on θ̇ − θ̇_r.
* α, DLS eq. (6): a bound ‖∂g/∂q‖₂ ≤ α, over a region of (θ, δ) (:func:`alpha_bound`: random
  samples, then a bounded local maximisation from the best ones) or a posteriori along a
  simulated trajectory (:func:`alpha_along`; the paper reports α = 17.67 for its run).
* Sufficient conditions for global asymptotic stability, DLS eqs. (14)–(15), reconstructed as

      (14) λ_min(K) > α,        (15) λ_min(K_P) > α,

  which together give λ_min(diag(K_P, K)) > α: with V = ½q̇ᵀBq̇ + ½q̃ᵀdiag(K_P, K)q̃ + U_g(q)
  − U_g(q_d) − q̃ᵀg(q_d) positive definite and V̇ = −θ̇ᵀK_Dθ̇ − δ̇ᵀDδ̇ ≤ 0, LaSalle gives
  convergence (:func:`stability_conditions` reports which hold and the margins). Note the
  mixed units: K in N/m (δ in m), K_P in N·m/rad, α the 2-norm of a matrix in SI units.

Laws are pure JAX functions ``u = law(params, x, t)`` with a pytree ``params``
(:class:`RegulationParams`), usable in any JAX closed loop; gains are traced, so a sweep
compiles once. The one sampled-data loop runs them, evaluated at every integration stage
(:class:`flexarm.control.continuous_law.ContinuousLaw`); :mod:`flexarm.sim.continuous` is
its front-end (one rollout or a batch of gain variations).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from flexarm.errors import FlexarmError  # the one error base (issue #25)
from flexarm.models.multilink import MultiLinkModel, MultiLinkPlant, chol_solve


class RegulationError(FlexarmError, ValueError):
    """A regulation problem without a solution (e.g. no residual deflection found)."""


# --------------------------------------------------------------------------- statics
def _no_cable_springs(model: MultiLinkModel) -> None:
    """DLS's arm has gravity and the links' own stiffness only: refuse joints' cable springs
    (:class:`flexarm.specs.multilink.Joint` ``cable_stiffness``), which eqs. (6), (9) and
    (14) leave out."""
    k_c = np.asarray(model.plant.cable, float)
    if np.any(k_c != 0):
        i = int(np.flatnonzero(k_c)[0])
        raise RegulationError(
            f"arm.joints[{i}].cable_stiffness = {k_c[i]:g} N*m/rad: De Luca–Siciliano's "
            "regulation (eqs. (6), (9), (14)) has no cable springs; set it to 0 for this "
            "analysis, or simulate the arm with it (flexarm.simulate)"
        )


def _static_residual(plant: MultiLinkPlant, theta: Array, delta: Array) -> Array:
    """F(δ) = K δ + g_δ(θ, δ) (N)."""
    n = plant.n_links
    return plant.K @ delta + plant.gravity(jnp.concatenate([theta, delta]))[n:]


def quasi_static_deflection(
    plant: MultiLinkPlant, theta: Array, iterations: int = 4, delta0: Array | None = None
) -> Array:
    """δ̄(θ): K δ̄ + g_δ(θ, δ̄) = 0 by ``iterations`` Newton steps from ``delta0`` (default 0);
    pure JAX (a fori_loop, so the step is compiled once), usable inside a closed loop."""
    d0 = jnp.zeros(plant.n_delta) if delta0 is None else delta0
    if plant.n_delta == 0:
        return d0

    def newton(_, d):
        F = _static_residual(plant, theta, d)
        Jm = jax.jacfwd(lambda dd: _static_residual(plant, theta, dd))(d)
        return d - chol_solve(0.5 * (Jm + Jm.T), F)

    return jax.lax.fori_loop(0, iterations, newton, d0)


@eqx.filter_jit
def _newton_parts(plant: MultiLinkPlant, theta: Array, delta: Array):
    F = _static_residual(plant, theta, delta)
    Jm = jax.jacfwd(lambda dd: _static_residual(plant, theta, dd))(delta)
    return F, Jm


def residual_deflection(
    model: MultiLinkModel, theta_d, *, delta0=None, tol: float = 1e-12, max_iter: int = 50
) -> np.ndarray:
    """δ_d solving DLS eq. (9), K δ_d + g_δ(θ_d, δ_d) = 0 (m), by Newton's method.

    Converged when ‖F‖ ≤ tol·(1 + ‖g_δ(θ_d, 0)‖) (N). Raises :class:`RegulationError` if the
    Jacobian K + ∂g_δ/∂δ is singular or Newton does not converge (gravity too strong for
    the stiffness)."""
    _no_cable_springs(model)
    plant = model.plant
    theta = jnp.asarray(theta_d, float).reshape(plant.n_links)
    d = np.zeros(plant.n_delta) if delta0 is None else np.asarray(delta0, float)
    if plant.n_delta == 0:
        return d
    F0, _ = _newton_parts(plant, theta, jnp.zeros(plant.n_delta))
    scale = 1.0 + float(np.linalg.norm(F0))
    for _ in range(max_iter):
        F, Jm = (np.asarray(a) for a in _newton_parts(plant, theta, jnp.asarray(d)))
        if np.linalg.norm(F) <= tol * scale:
            return d
        try:
            step = np.linalg.solve(Jm, F)
        except np.linalg.LinAlgError:
            raise RegulationError(
                f"K + ∂g_δ/∂δ is singular at δ = {d}; no residual deflection at θ_d = "
                f"{np.asarray(theta)} rad"
            ) from None
        d = d - step
        if not np.all(np.isfinite(d)):
            break
    raise RegulationError(
        f"Newton for K δ + g_δ(θ_d, δ) = 0 did not converge in {max_iter} iterations at "
        f"θ_d = {np.asarray(theta)} rad (last |F| = {np.linalg.norm(F):.3g} N); the links may "
        "be too flexible for the load"
    )


def gravity_torque(model: MultiLinkModel, theta, delta) -> np.ndarray:
    """g_θ(θ, δ) (N·m): the joint torques that hold the arm at rest at (θ, δ)."""
    q = np.concatenate([np.asarray(theta, float).ravel(), np.asarray(delta, float).ravel()])
    return model.gravity(q)[: model.n_links]


# --------------------------------------------------------------------------- laws
class RegulationParams(eqx.Module):
    """Parameters of the regulation laws (a pytree: every array is traced).

    KP, KD: (n, n) gains (N·m/rad, N·m·s/rad); theta_d (rad), delta_d (m): the target and its
    residual deflection (eq. 9); g_d = g_θ(θ_d, δ_d) (N·m); theta_0 (rad), duration (s): the
    quintic interpolating trajectory (duration 0: step to θ_d); plant: for on-line gravity.
    """

    plant: MultiLinkPlant
    KP: Array
    KD: Array
    theta_d: Array
    delta_d: Array
    g_d: Array
    theta_0: Array
    duration: Array
    newton_iterations: int = eqx.field(static=True, default=4)


def _gain(k, n: int, name: str) -> np.ndarray:
    k = np.asarray(k, float)
    if k.ndim == 0:
        k = np.full(n, float(k))
    if k.ndim == 1:
        if k.shape != (n,):
            raise ValueError(f"{name}: expected {n} diagonal values, got {k.shape[0]}")
        k = np.diag(k)
    if k.shape != (n, n):
        raise ValueError(f"{name}: expected an ({n}, {n}) matrix, got shape {k.shape}")
    return k


def regulation_params(
    model: MultiLinkModel,
    KP,
    KD,
    theta_d,
    *,
    theta_0=None,
    duration: float = 0.0,
    newton_iterations: int = 4,
) -> RegulationParams:
    """Parameters for the laws: KP, KD as scalars, diagonals or matrices; δ_d from eq. (9)."""
    n = model.n_links
    theta_d = np.asarray(theta_d, float).reshape(n)
    delta_d = residual_deflection(model, theta_d)
    g_d = gravity_torque(model, theta_d, delta_d)
    if duration < 0:
        raise ValueError(f"duration must be >= 0 s; got {duration}")
    if duration > 0 and theta_0 is None:
        raise ValueError("an interpolating trajectory (duration > 0) needs theta_0")
    th0 = theta_d if theta_0 is None else np.asarray(theta_0, float).reshape(n)
    f = jnp.asarray
    return RegulationParams(
        plant=model.plant,
        KP=f(_gain(KP, n, "KP")),
        KD=f(_gain(KD, n, "KD")),
        theta_d=f(theta_d),
        delta_d=f(delta_d),
        g_d=f(g_d),
        theta_0=f(th0),
        duration=f(float(duration)),
        newton_iterations=newton_iterations,
    )


def reference(p: RegulationParams, t) -> tuple[Array, Array]:
    """θ_r(t), θ̇_r(t): quintic from θ_0 to θ_d over ``duration`` (θ_d, 0 when duration = 0)."""
    T = p.duration
    inv_T = jnp.where(T > 0, 1.0 / jnp.where(T > 0, T, 1.0), 0.0)  # loop-invariant: hoisted
    tau = jnp.clip(t * inv_T, 0.0, 1.0)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    sd = 30.0 * tau**2 * (1.0 - tau) ** 2 * inv_T
    s = jnp.where(T > 0, s, 1.0)
    dth = p.theta_d - p.theta_0
    return p.theta_0 + dth * s, dth * sd


def _matvec(M: Array, v: Array) -> Array:
    """M v for a small (n, n) M as a sum of column products: elementwise arithmetic that XLA
    fuses with its neighbours (a ``dot`` is a separate library call on CPU)."""
    out = M[:, 0] * v[0]
    for j in range(1, v.shape[0]):
        out = out + M[:, j] * v[j]
    return out


def _pd(p: RegulationParams, x: Array, t) -> Array:
    n, nq = p.plant.n_links, p.plant.n_q
    th_r, thd_r = reference(p, t)
    return _matvec(p.KP, th_r - x[:n]) - _matvec(p.KD, x[nq : nq + n] - thd_r)


def law_pd_constant(p: RegulationParams, x: Array, t) -> Array:
    """DLS eq. (8): u = K_P(θ_d − θ) − K_D θ̇ + g_θ(θ_d, δ_d) (N·m)."""
    return _pd(p, x, t) + p.g_d


def law_pd_online(p: RegulationParams, x: Array, t) -> Array:
    """Law (30), variant a: u = K_P(θ_d − θ) − K_D θ̇ + g_θ(θ, δ), measured (θ, δ)."""
    nq = p.plant.n_q
    return _pd(p, x, t) + p.plant.gravity(x[:nq])[: p.plant.n_links]


def law_pd_quasistatic(p: RegulationParams, x: Array, t) -> Array:
    """Law (30), variant b: u = K_P(θ_d − θ) − K_D θ̇ + g_θ(θ, δ̄(θ)), δ̄ quasi-static."""
    n = p.plant.n_links
    th = x[:n]
    db = quasi_static_deflection(p.plant, th, p.newton_iterations)
    return _pd(p, x, t) + p.plant.gravity(jnp.concatenate([th, db]))[:n]


def law_zero(p: MultiLinkPlant, x: Array, t) -> Array:
    """No input (free motion): u = 0; ``p`` is the plant (for the number of joints)."""
    return jnp.zeros(p.n_links) + 0.0 * x[0]


LAWS: dict[str, Callable] = {
    "pd_constant": law_pd_constant,
    "pd_online": law_pd_online,
    "pd_quasistatic": law_pd_quasistatic,
}


# --------------------------------------------------------------------------- α and conditions
@eqx.filter_jit
def _gjac_norms(plant: MultiLinkPlant, qs: Array) -> Array:
    def one(q):
        return jnp.max(jnp.abs(jnp.linalg.eigvalsh(plant.gravity_jacobian(q))))

    return jax.vmap(one)(qs)


@dataclass(frozen=True)
class AlphaBound:
    """α = max ‖∂g/∂q‖₂ found, and the configuration q where it is reached."""

    alpha: float
    q: np.ndarray
    n_evaluations: int


def alpha_bound(
    model: MultiLinkModel,
    theta_low,
    theta_high,
    delta_max,
    *,
    n_samples: int = 4000,
    seed: int = 0,
    refine: int = 5,
) -> AlphaBound:
    """α of DLS eq. (6) over the box θ ∈ [θ_low, θ_high] (rad), |δ| ≤ δ_max (m, per mode):
    the largest ‖∂g/∂q‖₂ over random samples, then a bounded local maximisation
    (L-BFGS-B) from the ``refine`` best samples. A lower estimate of the true supremum."""
    from scipy.optimize import minimize

    n, nd = model.n_links, model.n_delta
    lo = np.concatenate(
        [
            np.broadcast_to(np.asarray(theta_low, float), (n,)),
            -np.broadcast_to(np.abs(np.asarray(delta_max, float)), (nd,)),
        ]
    )
    hi = np.concatenate(
        [
            np.broadcast_to(np.asarray(theta_high, float), (n,)),
            np.broadcast_to(np.abs(np.asarray(delta_max, float)), (nd,)),
        ]
    )
    rng = np.random.default_rng(seed)
    qs = lo + (hi - lo) * rng.random((n_samples, n + nd))
    vals = np.asarray(_gjac_norms(model.plant, jnp.asarray(qs)))
    best = int(np.argmax(vals))
    alpha, qbest, nev = float(vals[best]), qs[best], n_samples

    def neg(q):
        return -float(_gjac_norms(model.plant, jnp.asarray(q[None, :]))[0])

    for k in np.argsort(vals)[::-1][:refine]:
        res = minimize(
            neg,
            qs[k],
            method="L-BFGS-B",
            bounds=list(zip(lo, hi, strict=True)),
            options={"maxiter": 50},
        )
        nev += res.nfev
        if -res.fun > alpha:
            alpha, qbest = float(-res.fun), res.x
    return AlphaBound(alpha, np.asarray(qbest), nev)


def alpha_along(model: MultiLinkModel, states) -> tuple[float, int]:
    """α a posteriori: max over the samples of a trajectory x(t) of ‖∂g/∂q(q(t))‖₂; returns
    (α, index of the sample where it is reached)."""
    x = np.atleast_2d(np.asarray(states, float))
    vals = np.asarray(_gjac_norms(model.plant, jnp.asarray(x[:, : model.n_q])))
    k = int(np.argmax(vals))
    return float(vals[k]), k


@dataclass(frozen=True)
class StabilityConditions:
    """DLS (14) λ_min(K) > α and (15) λ_min(K_P) > α (reconstructed forms), with margins."""

    alpha: float
    lambda_min_K: float
    lambda_min_KP: float

    @property
    def margin_14(self) -> float:
        return self.lambda_min_K - self.alpha

    @property
    def margin_15(self) -> float:
        return self.lambda_min_KP - self.alpha

    @property
    def holds_14(self) -> bool:
        return self.margin_14 > 0

    @property
    def holds_15(self) -> bool:
        return self.margin_15 > 0

    @property
    def holds(self) -> bool:
        return self.holds_14 and self.holds_15

    def summary(self) -> str:
        def line(tag, name, lam, margin, ok):
            return (
                f"({tag}) {name} = {lam:.4g} {'>' if ok else '<='} α = {self.alpha:.4g}: "
                f"{'holds' if ok else 'FAILS'} (margin {margin:+.4g})"
            )

        return "\n".join(
            [
                line("14", "λ_min(K)", self.lambda_min_K, self.margin_14, self.holds_14),
                line("15", "λ_min(K_P)", self.lambda_min_KP, self.margin_15, self.holds_15),
            ]
        )


def stability_conditions(model: MultiLinkModel, KP, alpha: float) -> StabilityConditions:
    """Check the sufficient conditions (14)–(15) for the gains KP and the bound α."""
    _no_cable_springs(model)
    n = model.n_links
    KPm = _gain(KP, n, "KP")
    lk = float(np.linalg.eigvalsh(model.K).min()) if model.n_delta else float("inf")
    return StabilityConditions(
        float(alpha), lk, float(np.linalg.eigvalsh(0.5 * (KPm + KPm.T)).min())
    )


# --------------------------------------------------------------------------- batches of parameters
def regulation_params_batch(
    model: MultiLinkModel,
    KP,
    KD,
    theta_d,
    *,
    theta_0=None,
    duration: float = 0.0,
    newton_iterations: int = 4,
) -> tuple[RegulationParams, RegulationParams]:
    """Parameters for N gain variations around one target, and their vmap-style batch axes.

    KP, KD: (N, n) diagonals or (N, n, n) matrices (N·m/rad, N·m·s/rad); one of the two may
    be a single gain shared by the batch, a scalar or an (n,) diagonal. Returns ``(params, axes)``
    for :func:`flexarm.sim.continuous.simulate_continuous_batch`: params with KP, KD of shape
    (N, n, n), axes with 0 on KP and KD and None elsewhere (the target, δ_d and g_θ(θ_d, δ_d)
    are shared)."""
    n = model.n_links
    base = regulation_params(
        model,
        np.eye(n),
        np.eye(n),
        theta_d,
        theta_0=theta_0,
        duration=duration,
        newton_iterations=newton_iterations,
    )

    def stack(k, name):
        k = np.asarray(k, float)
        if k.ndim == 0 or (k.ndim == 1 and k.shape == (n,)):
            return None
        if k.ndim == 2 and k.shape[1] == n:
            return np.stack([np.diag(r) for r in k])
        if k.ndim == 3 and k.shape[1:] == (n, n):
            return k
        raise ValueError(
            f"{name}: expected (N, {n}) diagonals or (N, {n}, {n}) matrices, got shape {k.shape}"
        )

    kp, kd = stack(KP, "KP"), stack(KD, "KD")
    if kp is None and kd is None:
        raise ValueError("KP or KD must hold a batch: (N, n) diagonals or (N, n, n) matrices")
    if kp is not None:
        N = kp.shape[0]
    else:
        assert kd is not None  # one of them holds the batch (checked above)
        N = kd.shape[0]
    if kp is not None and kd is not None and kd.shape[0] != N:
        raise ValueError(f"KP holds {N} gains and KD {kd.shape[0]}")
    kp = np.broadcast_to(_gain(KP, n, "KP"), (N, n, n)) if kp is None else kp
    kd = np.broadcast_to(_gain(KD, n, "KD"), (N, n, n)) if kd is None else kd
    params = eqx.tree_at(lambda p: (p.KP, p.KD), base, (jnp.asarray(kp), jnp.asarray(kd)))
    # the vmap axes of each field (0: batched, None: shared), in a RegulationParams of axes
    axes = cast(Any, RegulationParams)(
        plant=None,
        KP=0,
        KD=0,
        theta_d=None,
        delta_d=None,
        g_d=None,
        theta_0=None,
        duration=None,
        newton_iterations=newton_iterations,
    )
    return params, axes
