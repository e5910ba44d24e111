"""Property tests of the models over random physical arms (issue #12, item 3):

* the single-link plant with zero input and no friction loses energy (passivity), the
  energy computed here independently from the spec's J, masses and the textbook
  cantilever flexibility a²(3b − a)/(6 EI);
* the multi-link mass matrix B(q) is symmetric positive definite for random q and links;
* the linear transfer functions G_m, G_b equal the frequency response of the nonlinear
  plant linearised at rest by jax.jacfwd.

Bounded and derandomised (profile ``flexarm`` in conftest.py).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.integrate import rk4_path
from flexarm.specs.arm import SingleLinkArm

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import Phase, given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip


def logu(lo, hi):
    """Log-uniform positive numbers: physical data spans decades."""
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


@st.composite
def arms(draw, damping=True):
    L = draw(logu(0.05, 2.0))
    fr = draw(
        st.lists(st.sampled_from([0.25, 0.5, 0.75, 1.0]), min_size=1, max_size=3, unique=True)
    )
    pos = sorted(f * L for f in fr)
    masses = [{"mass": draw(logu(1e-3, 1.0)), "position": p} for p in pos]
    drive = draw(st.sampled_from(["current", "voltage"]))
    motor = {
        "drive": drive,
        "inertia": draw(logu(1e-5, 1e-1)),
        "viscous": draw(st.sampled_from([0.0, draw(logu(1e-5, 1e-1))])),
    }
    if drive == "current":
        motor.update(torque_constant=draw(logu(1e-2, 1.0)), current_limit=5.0)
    else:
        motor.update(
            motor_constant=draw(logu(1e-3, 0.1)),
            armature_resistance=draw(logu(0.5, 20)),
            gear_ratio=draw(logu(1, 100)),
            voltage_limit=10.0,
        )
    beam = {
        "model": "lumped",
        "length": L,
        "flexural_rigidity": draw(logu(1e-2, 1e2)),
        "damping_ratio": draw(st.floats(0.0, 0.1)) if damping else 0.0,
        "masses": masses,
    }
    return SingleLinkArm.model_validate(
        {"motor": motor, "friction": {"model": "none"}, "beam": beam}
    )


def energy(arm: SingleLinkArm, x: np.ndarray) -> np.ndarray:
    """½ J θ̇² + ½ ẏᵀ M ẏ + ½ wᵀ K w, w = y − x̄ θ (absolute coordinates y of the masses,
    x̄ their positions), K = F⁻¹ with F_ab = a²(3b − a)/(6 EI), a ≤ b (a textbook result,
    not the model's code). x: states over time (rows)."""
    b = arm.beam
    p = np.array([m.position for m in b.masses])
    m = np.array([mm.mass for mm in b.masses])
    lo, hi = np.minimum.outer(p, p), np.maximum.outer(p, p)
    K = np.linalg.inv(lo**2 * (3 * hi - lo) / (6 * b.EI))
    n = len(p)
    th, om, y, yd = x[:, 0], x[:, 1], x[:, 2 : 2 + n], x[:, 2 + n : 2 + 2 * n]
    w = y - np.outer(th, p)
    return (
        0.5 * arm.motor.inertia * om**2
        + 0.5 * np.sum(m * yd**2, axis=1)
        + 0.5 * np.einsum("ti,ij,tj->t", w, K, w)
    )


@settings(max_examples=12)
@given(arms(), st.integers(0, 2**31 - 1))
def test_unforced_frictionless_single_link_loses_energy(arm, seed):
    """RK4 with ω_max h = 0.1: its energy error per step on an oscillator is about
    (ω h)⁶/72 ≈ 1.4e-8 of the energy; we allow 1e-7 E0 per step (plus round-off),
    so a model that injected energy (a wrong sign in K, D, the coupling torque or the
    back-EMF) would fail at once."""
    model = SingleLinkModel.from_spec(arm)
    plant = model.plant()
    rng = np.random.default_rng(seed)
    n = len(arm.beam.masses)
    x0 = np.concatenate(
        [
            [rng.normal(), rng.normal()],
            rng.normal(size=n) * 0.01 * arm.beam.length,
            rng.normal(size=n),
        ]
    )
    A, _, _ = _lin(plant, len(x0))  # fastest mode of the whole arm (hub included)
    wmax = max(float(np.max(np.abs(np.linalg.eigvals(A)))), 1e-3)
    h = 0.1 / wmax
    u = jnp.zeros(1)
    xs = rk4_path(lambda x, t: plant.rhs(x, u), jnp.asarray(x0), h, 10, 60)
    E = energy(arm, np.asarray(xs))
    assert np.all(np.isfinite(E)) and E[0] > 0
    inc = np.diff(E)
    assert np.all(inc <= 10 * 1e-7 * E[0] + 1e-12 * E[0]), inc.max() / E[0]
    if arm.beam.damping_ratio == 0 and arm.motor.viscous == 0 and arm.motor.drive == "current":
        # conservative: RK4 only loses (ω h)⁶/72 per step
        assert E[-1] >= E[0] * (1 - 600 * 1e-7)


def _lin(plant, nx):
    x0, u0 = jnp.zeros(nx), jnp.zeros(1)
    A = np.asarray(jax.jacfwd(lambda x: plant.rhs(x, u0))(x0))
    B = np.asarray(jax.jacfwd(lambda u: plant.rhs(x0, u))(u0))
    C = np.asarray(jax.jacfwd(lambda x: plant.signals(x, u0))(x0))
    return A, B, C


@pytest.mark.xfail(
    strict=True,
    reason=(
        "found by this test, not fixed yet: models.lumped_beam._clean zeroes coefficients below "
        "1e-11 of the largest one, so for a light hub (J = 1e-5 kg m^2) with a stiff short beam "
        "the s^4 coefficient of G_m's denominator is dropped and G_m loses its resonance "
        "(returned (0.0096 s^2 + 1.49e4)/s^2 instead of poles at +-3211j, zeros at +-1247j); "
        "trimming on frequency-scaled coefficients (tried 2026-11-28) mends this case, but then "
        "three 1 kg masses on a 0.14-0.17 m beam with EI = 1 N m^2 fail: the coefficient form "
        "itself is ill-conditioned there"
    ),
)
# a known failure (xfail above): finding a counter-example is the test; shrinking it took
# about 80 s of the suite, so the shrink phase is left out
@settings(max_examples=12, phases=(Phase.explicit, Phase.reuse, Phase.generate))
@given(arms())
def test_transfer_functions_match_the_linearised_plant(arm):
    """G_m = θm/u and G_b = θt/θm against C (jωI − A)⁻¹ B of the jacfwd linearisation at
    rest, at 0.3, 0.9 and 3 times the first beam frequency. Both sides are exact in exact
    arithmetic; the tolerance is round-off amplified by the conditioning of jωI − A
    (κ · 1e-13) plus 1e-6 for the coefficient form (the model's minreal with tol 1e-7)."""
    model = SingleLinkModel.from_spec(arm)
    plant = model.plant()
    nx = 2 + model.beam.n_states
    A, B, C = _lin(plant, nx)
    w1 = float(np.min(np.abs(np.linalg.eigvals(model.beam.A))))
    gm, gb = model.motor_tf(), model.beam_tf()
    for w in (0.3 * w1, 0.9 * w1, 3.0 * w1):
        M = 1j * w * np.eye(nx) - A
        X = np.linalg.solve(M, B[:, 0])
        th_m, th_t = C[0] @ X, C[2] @ X
        tol = 1e-6 + 1e-13 * np.linalg.cond(M)
        assert gm(1j * w) == pytest.approx(th_m, rel=tol)
        assert gb(1j * w) == pytest.approx(th_t / th_m, rel=tol)


@st.composite
def multilink_arms(draw):
    from flexarm.specs.multilink import MultiLinkArm

    n = draw(st.integers(1, 3))
    links = [
        {
            "length": draw(logu(0.1, 2.0)),
            "linear_density": draw(logu(0.05, 5.0)),
            "flexural_rigidity": draw(logu(0.5, 500.0)),
            "modes": draw(st.integers(0, 2)),
            "mode_type": draw(st.sampled_from(["clamped_mass", "clamped_free"])),
        }
        for _ in range(n)
    ]
    hubs = [{"mass": draw(logu(1e-3, 5.0)), "inertia": draw(logu(1e-4, 0.5))} for _ in range(n)]
    payload = {
        "mass": draw(st.sampled_from([0.0, 0.1, 1.0])),
        "inertia": draw(st.sampled_from([0.0, 1e-3])),
    }
    return MultiLinkArm.model_validate({"links": links, "hubs": hubs, "payload": payload})


@settings(max_examples=8)
@given(
    multilink_arms(),
    st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3),
    st.integers(0, 2**31 - 1),
)
def test_multilink_mass_matrix_is_symmetric_positive_definite(arm, angles, seed):
    """B(q) = B(q)ᵀ to round-off (1e-12 of its norm) and its smallest eigenvalue > 0, at
    random joint angles and random deflections (a few per cent of the link length)."""
    from flexarm.models.multilink import build_multilink

    model = build_multilink(arm)
    p = model.plant
    q = np.zeros(p.n_q)
    q[: p.n_links] = angles[: p.n_links]
    q[p.n_links :] = np.random.default_rng(seed).normal(size=p.n_delta) * 0.02
    Bq = np.asarray(p.mass_matrix(jnp.asarray(q)))
    nrm = np.linalg.norm(Bq)
    assert np.max(np.abs(Bq - Bq.T)) <= 1e-12 * nrm
    ev = np.linalg.eigvalsh(0.5 * (Bq + Bq.T))
    assert ev[0] > 1e-12 * ev[-1], ev
