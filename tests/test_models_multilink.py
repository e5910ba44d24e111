"""Multi-link flexible arm: specs, Lagrangian model, plant (flexarm.models.multilink)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss
from pydantic import ValidationError

from flexarm.control.regulation import law_zero
from flexarm.models.multilink import build_multilink
from flexarm.models.plant import Plant
from flexarm.sim.continuous import simulate_continuous
from flexarm.specs.multilink import Hub, Link, MultiLinkArm, Payload, benchmark_arm

G = 9.81


@pytest.fixture(scope="module")
def bench():
    return build_multilink(benchmark_arm())


def random_states(model, n, seed=0):
    rng = np.random.default_rng(seed)
    nq = model.n_q
    q = np.concatenate(
        [
            rng.uniform(-math.pi, math.pi, (n, model.n_links)),
            rng.uniform(-0.05, 0.05, (n, model.n_delta)),
        ],
        axis=1,
    )
    qd = rng.normal(0.0, 1.0, (n, nq))
    return q, qd


# ------------------------------------------------------------------ specs
def test_spec_reads_units_and_builds():
    arm = MultiLinkArm(
        links=[
            Link(length="50 cm", mass="100 g", flexural_rigidity="15 N*m**2", modes=2),
            Link(
                length="0.5 m",
                linear_density="0.2 kg/m",
                flexural_rigidity=15,
                modes=1,
                mode_type="clamped_free",
                damping_ratio=0.02,
            ),
        ],
        hubs=[Hub(inertia="0.1 kg*m**2"), Hub(mass="1 kg", inertia=0.1)],
        payload=Payload(mass="100 g", inertia=0.0005),
        torque_limit=["5 N*m", 2.0],
    )
    assert arm.links[0].rho == pytest.approx(0.2) and arm.links[0].length == pytest.approx(0.5)
    model = build_multilink(arm)
    assert model.n_modes == (2, 1)
    assert model.plant.state_names[:5] == (
        "theta_1",
        "theta_2",
        "delta_1_1",
        "delta_1_2",
        "delta_2_1",
    )
    assert model.plant.signal_names[5:] == (
        "tip_x",
        "tip_y",
        "theta_dot_1",
        "theta_dot_2",
        "deflection_1",
        "deflection_2",
        "deflection_angle_1",
        "deflection_angle_2",
    )
    np.testing.assert_allclose(model.plant.command_limit, [5.0, 2.0])
    m2 = model.modes[1]
    np.testing.assert_allclose(model.D[2, 2], 2 * 0.02 * m2.omega[0] * m2.mass, rtol=1e-12)
    # tip loads of the clamped-mass modes of link 1: everything distal, link 2 straight
    Ml, Jl = model.tip_loads[0]
    assert Ml == pytest.approx(1.0 + 0.1 + 0.1)
    assert Jl == pytest.approx(0.1 + 0.2 * 0.5**3 / 3 + 0.1 * 0.25 + 0.0005)


def test_spec_errors_are_clear():
    with pytest.raises(ValidationError, match="length"):
        Link(length=0.0, linear_density=0.2, flexural_rigidity=15)
    with pytest.raises(ValidationError, match="flexural_rigidity"):
        Link(length=0.5, linear_density=0.2, flexural_rigidity=-1.0)
    with pytest.raises(ValidationError, match="needs flexural_rigidity"):
        Link(length=0.5, linear_density=0.2, modes=2)
    with pytest.raises(ValidationError, match="exactly one"):
        Link(length=0.5, linear_density=0.2, mass=0.1, flexural_rigidity=15)
    link = Link(length=0.5, linear_density=0.2, flexural_rigidity=15)
    with pytest.raises(ValidationError, match="hubs"):
        MultiLinkArm(links=[link, link], hubs=[Hub()])
    with pytest.raises(ValidationError, match="gravity_direction"):
        MultiLinkArm(links=[link], hubs=[Hub()], gravity_direction=(0.0, 0.0))
    with pytest.raises(ValueError, match="βℓ"):
        build_multilink(MultiLinkArm(links=[link.model_copy(update={"modes": 60})], hubs=[Hub()]))


# ------------------------------------------------------------------ model structure
def test_mass_matrix_spd_and_terms_equal_autodiff(bench):
    q, qd = random_states(bench, 50)
    P = bench.plant

    @jax.jit
    def terms(q, qd):
        return (
            jax.vmap(P.mass_matrix)(q),
            jax.vmap(P.mass_matrix_autodiff)(q),
            jax.vmap(P.coriolis)(q, qd),
            jax.vmap(P.coriolis_autodiff)(q, qd),
            jax.vmap(P.gravity)(q),
            jax.vmap(P.gravity_autodiff)(q),
        )

    B, Bad, c, cad, g, gad = (np.asarray(a) for a in terms(q, qd))
    np.testing.assert_allclose(B, np.swapaxes(B, 1, 2), atol=1e-15)
    assert np.linalg.eigvalsh(B).min() > 0
    np.testing.assert_allclose(B, Bad, atol=1e-13)
    np.testing.assert_allclose(c, cad, atol=1e-12 * np.abs(cad).max())
    np.testing.assert_allclose(g, gad, atol=1e-13 * np.abs(gad).max())


def test_three_links_mixed_rigid_and_flexible():
    """Any number of links and modes: rigid link 1, 3 clamped-mass modes on link 2, one
    clamped-free mode on link 3; B and g against autodiff, q̈ against a LAPACK solve."""
    arm = MultiLinkArm(
        links=[
            Link(length=0.4, linear_density=0.3, modes=0),
            Link(length=0.5, linear_density=0.2, flexural_rigidity=10, modes=3),
            Link(length=0.3, mass=0.05, flexural_rigidity=2, modes=1, mode_type="clamped_free"),
        ],
        hubs=[Hub(inertia=0.05), Hub(mass=0.5, inertia=0.02), Hub(mass=0.3, inertia=0.01)],
        payload=Payload(mass=0.05, inertia=1e-4),
    )
    model = build_multilink(arm)
    assert model.n_modes == (0, 3, 1) and model.n_q == 7
    q, qd = random_states(model, 1, seed=4)
    q, qd = q[0], qd[0]
    u = np.array([0.3, -0.2, 0.1])
    P = model.plant

    @jax.jit
    def terms(q, qd, u):
        return (
            P.mass_matrix(q),
            P.mass_matrix_autodiff(q),
            P.gravity(q),
            P.gravity_autodiff(q),
            P.coriolis(q, qd),
            P.rhs(jnp.concatenate([q, qd]), u),
        )

    B, Bad, g, gad, c, xdot = (np.asarray(a) for a in terms(q, qd, u))
    np.testing.assert_allclose(B, Bad, atol=1e-13)
    np.testing.assert_allclose(g, gad, atol=1e-13)
    qdd = np.linalg.solve(B, np.concatenate([u, -(model.K @ q[3:] + model.D @ qd[3:])]) - c - g)
    np.testing.assert_allclose(xdot[7:], qdd, rtol=1e-9, atol=1e-12 * np.abs(qdd).max())


def test_bdot_minus_2c_is_skew_symmetric(bench):
    q, qd = random_states(bench, 5, seed=1)
    P = bench.plant

    @jax.jit
    def mats(q, qd):
        return (P.mass_matrix_dot(q, qd), P.coriolis_matrix(q, qd), P.coriolis(q, qd))

    for k in range(5):
        Bd, C, c = (np.asarray(a) for a in mats(q[k], qd[k]))
        N = Bd - 2 * C
        assert np.abs(N + N.T).max() < 1e-9
        np.testing.assert_allclose(C @ qd[k], c, atol=1e-12)


def test_energies_equal_direct_integration_over_the_beams(bench):
    """T and U_g from the modal integrals equal quadrature over points of the bent links."""
    arm, P = bench.arm, bench.plant
    t, w = leggauss(40)
    X = [0.5 * lk.length * (t + 1) for lk in arm.links]
    W = [0.5 * lk.length * w for lk in arm.links]
    PHI = [m.shape(x) for m, x in zip(bench.modes, X, strict=True)]

    def points(q):
        n = bench.n_links
        alpha, p, k = q[0], jnp.zeros(2), n
        out = []
        for i, m in enumerate(bench.modes):
            d = q[k : k + m.n_modes]
            k += m.n_modes
            c, s = jnp.cos(alpha), jnp.sin(alpha)
            wx = jnp.asarray(PHI[i]).T @ d
            r = p[:, None] + jnp.stack([c * X[i] - s * wx, s * X[i] + c * wx])
            wl = jnp.asarray(m.tip_value) @ d
            out.append((r, p, alpha))
            p = p + jnp.stack([c * arm.links[i].length - s * wl, s * arm.links[i].length + c * wl])
            alpha = alpha + jnp.asarray(m.tip_slope) @ d + (q[i + 1] if i + 1 < n else 0.0)
        return out, p, alpha

    def energies(q, qd):
        (out, pe, ae), (dout, dpe, dae) = jax.jvp(points, (q,), (qd,))
        T = U = 0.0
        for i, ((r, p, _a), (dr, dp, da)) in enumerate(zip(out, dout, strict=True)):
            rho = arm.links[i].rho
            T += 0.5 * rho * jnp.sum(W[i] * jnp.sum(dr**2, axis=0))
            U += rho * G * jnp.sum(W[i] * r[1])
            T += 0.5 * (arm.hubs[i].mass * (dp @ dp) + arm.hubs[i].inertia * da**2)
            U += arm.hubs[i].mass * G * p[1]
        T += 0.5 * (arm.payload.mass * (dpe @ dpe) + arm.payload.inertia * dae**2)
        U += arm.payload.mass * G * pe[1]
        return T, U

    @jax.jit
    def both(q, qd):
        return energies(q, qd), (P.kinetic_energy(q, qd), P.gravity_potential(q))

    q, qd = random_states(bench, 3, seed=2)
    for k in range(3):
        (T, U), (Tm, Um) = both(jnp.asarray(q[k]), jnp.asarray(qd[k]))
        assert float(Tm) == pytest.approx(float(T), rel=1e-12)
        assert float(Um) == pytest.approx(float(U), rel=1e-12, abs=1e-12)


def test_rigid_two_link_equals_textbook(bench):
    rigid = benchmark_arm(modes=0)
    model = build_multilink(rigid)
    assert model.n_q == 2
    l1 = l2 = 0.5
    rho, mh2, Jh, mp, Jp = 0.2, 1.0, 0.1, 0.1, 0.0005
    I1 = Jh + rho * l1**3 / 3  # body 1 about joint 1
    m1a1 = rho * l1**2 / 2
    m2 = mh2 + rho * l2 + mp  # body 2: hub 2, link 2, payload
    m2a2 = rho * l2**2 / 2 + mp * l2
    I2 = Jh + rho * l2**3 / 3 + mp * l2**2 + Jp  # body 2 about joint 2
    rng = np.random.default_rng(3)
    for _ in range(5):
        th = rng.uniform(-math.pi, math.pi, 2)
        thd = rng.normal(0, 2, 2)
        c2, s2 = math.cos(th[1]), math.sin(th[1])
        B = np.array(
            [
                [I1 + I2 + m2 * l1**2 + 2 * l1 * m2a2 * c2, I2 + l1 * m2a2 * c2],
                [I2 + l1 * m2a2 * c2, I2],
            ]
        )
        h = l1 * m2a2 * s2
        c = np.array([-h * (2 * thd[0] * thd[1] + thd[1] ** 2), h * thd[0] ** 2])
        g = G * np.array(
            [
                (m1a1 + m2 * l1) * math.cos(th[0]) + m2a2 * math.cos(th.sum()),
                m2a2 * math.cos(th.sum()),
            ]
        )
        np.testing.assert_allclose(model.mass_matrix(th), B, rtol=1e-13)
        np.testing.assert_allclose(model.coriolis(th, thd), c, atol=1e-13)
        np.testing.assert_allclose(model.gravity(th), g, atol=1e-13)


def test_plant_protocol_and_signals(bench):
    P = bench.plant
    assert isinstance(P, Plant) and P.n_states == 12 and P.n_inputs == 2
    x = bench.state(theta=[-math.pi / 2, 0.0])
    np.testing.assert_allclose(bench.tip_position(x[:6]), [0.0, -1.0], atol=1e-15)
    xs = np.tile(x, (4, 1))
    sig = np.asarray(jax.jit(jax.vmap(lambda x: P.signals(x, jnp.zeros(2))))(jnp.asarray(xs)))
    assert sig.shape == (4, 14)
    np.testing.assert_allclose(sig[:, :6], xs[:, :6])
    np.testing.assert_allclose(sig[:, 6:8], [[0.0, -1.0]] * 4, atol=1e-15)
    np.testing.assert_allclose(sig[:, 8:10], xs[:, 6:8])  # joint rates
    # tip deflection of link i: φ_i(ℓ)ᵀδ_i; deflection angle: that over ℓ_i
    xd = xs.copy()
    xd[:, 2:6] = [1e-3, -2e-4, 5e-4, 1e-4]
    sig = np.asarray(jax.vmap(lambda x: P.signals(x, jnp.zeros(2)))(jnp.asarray(xd)))
    w = [bench.modes[i].tip_value @ xd[0, 2 + 2 * i : 4 + 2 * i] for i in range(2)]
    np.testing.assert_allclose(sig[0, 10:12], w, rtol=1e-14)
    np.testing.assert_allclose(sig[0, 12:14], np.asarray(w) / 0.5, rtol=1e-14)
    # hanging straight down is an equilibrium with zero torque: ẋ = 0
    np.testing.assert_allclose(bench.rhs(x, np.zeros(2)), 0.0, atol=1e-12)
    assert np.all(np.isinf(np.asarray(P.command_limit)))
    # gravity along +x: the arm at rest along the x axis is the equilibrium instead
    sideways = build_multilink(benchmark_arm().model_copy(update={"gravity_direction": (2.0, 0.0)}))
    np.testing.assert_allclose(sideways.rhs(bench.state(), np.zeros(2)), 0.0, atol=1e-12)
    assert np.abs(bench.rhs(bench.state(), np.zeros(2))).max() > 1.0


@pytest.mark.parametrize("gravity", [0.0, G])
def test_energy_conserved_without_damping_and_input(gravity):
    model = build_multilink(benchmark_arm(gravity=gravity))
    x0 = model.state(
        theta=[-1.0, 0.6],
        delta=[0.03, -0.002, 0.004, 0.0001],
        theta_dot=[1.0, -2.0],
        delta_dot=[0.1, 0.0, -0.05, 0.0],
    )
    run = simulate_continuous(model, law_zero, x0, 10.0, 5e-3, params=model.plant, step=5e-5)
    E = model.energy(run.state_array)
    Tkin = np.asarray(
        jax.vmap(model.plant.kinetic_energy)(run.state_array[:, :6], run.state_array[:, 6:])
    )
    drift = np.abs(E - E[0]).max() / Tkin.max()
    print(f"g = {gravity}: energy drift over 10 s {drift:.2e} of max T = {Tkin.max():.3g} J")
    assert drift < 1e-6


# ------------------------------------------------------------------ cable springs
def _with_cables(arm, k_c):
    d = arm.model_dump()
    d["joints"] = [{"cable_stiffness": k} for k in k_c]
    return MultiLinkArm(**d)


def test_cable_springs_in_the_emitted_program_equal_the_potential_s_gradient(bench):
    """Joint cable springs (k_c = 3 and 1.5 N·m/rad on the benchmark's two flexible links):
    the recorded right-hand side's q̈ equals B⁻¹ f with B by autodiff of T and f the
    generalized forces, whose cable part is jax.grad of ½ Σ k_c a² (an independent
    computation), at random states; the energy with the springs is conserved."""
    model = build_multilink(_with_cables(benchmark_arm(gravity=G), [3.0, 1.5]))
    P = model.plant
    q, qd = random_states(model, 20, seed=3)
    u = np.random.default_rng(4).normal(0.0, 2.0, (20, model.n_links))

    @jax.jit
    def both(q, qd, u):
        x = jnp.concatenate([q, qd], axis=1)
        acc = jax.vmap(P.acceleration)(x, u)
        ref = jax.vmap(
            lambda x, u: jnp.linalg.solve(
                P.mass_matrix_autodiff(x[: P.n_q]), P.generalized_forces(x, u)
            )
        )(x, u)
        return acc, ref

    acc, ref = (np.asarray(a) for a in both(q, qd, u))
    np.testing.assert_allclose(acc, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    zero = build_multilink(benchmark_arm(gravity=G)).plant
    x = jnp.concatenate([q, qd], axis=1)
    # the springs change the motion (the test is not vacuous)
    assert (
        np.abs(np.asarray(jax.vmap(zero.acceleration)(x, u)) - acc).max() > 1e-3 * np.abs(acc).max()
    )
    x0 = model.state(theta=[-1.0, 0.6], delta=[0.03, -0.002, 0.004, 0.0001])
    run = simulate_continuous(model, law_zero, x0, 3.0, 5e-3, params=P, step=5e-5)
    E = model.energy(run.state_array)
    assert np.abs(E - E[0]).max() / np.abs(E).max() < 1e-6


def test_cable_spring_holds_a_torsional_link_at_its_static_deflection():
    """A torsional link on its spring K under a cable spring k_c, at rest at joint angle θ
    with the drive holding it: the static deflection is α = −k_c θ / (K + k_c) (the
    Joint docstring), where q̈ = 0 exactly; 10 % off it the link accelerates."""
    from flexarm.specs.scenario import load_scenario

    arm = load_scenario("quanser-two-link").arm
    K1 = arm.links[0].torsional_stiffness
    d = arm.model_dump()
    d["joints"][0]["cable_stiffness"] = 0.09
    model = build_multilink(MultiLinkArm(**d))
    th = 0.4
    alpha = -0.09 * th / (K1 + 0.09)
    u = np.array([0.09 * (th + alpha), 0.0])  # the drive's holding torque
    acc = model.rhs(model.state(theta=[th, 0.0], delta=[alpha, 0.0]), u)[model.n_q :]
    np.testing.assert_allclose(acc, 0.0, atol=1e-12)
    off = model.rhs(model.state(theta=[th, 0.0], delta=[1.1 * alpha, 0.0]), u)[model.n_q :]
    assert np.abs(off).max() > 1e-3
