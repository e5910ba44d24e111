"""One plant for every arm (flexarm.models.assembly): the single link as the one-link case,
multi-link arms with drives and friction at every joint, torsional links, and the scenario
only the union of the two papers runs (DLS arm, geared servos with stiction, sampled PD)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm.control.regulation import gravity_torque
from flexarm.models.assembly import Arm, multi_link_arm
from flexarm.models.multilink import build_multilink
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.build import prepare, run_prepared
from flexarm.specs import load_scenario
from flexarm.specs.multilink import Hub, Joint, Link, MultiLinkArm, benchmark_arm


def test_single_link_arm_is_the_written_out_plant():
    """The one-link Arm's ẋ equals FRB eq. (1) with the beam block written out here:
    J θ̈ = k_u u − (k_ω + V) θ̇ − C_t + b − F, F the Karnopp friction (to round-off)."""
    sc = load_scenario("rotary-flexible-link")
    m = SingleLinkModel.from_spec(sc.arm)
    arm = m.plant()
    assert isinstance(arm, Arm) and arm.n_joints == 1
    b = m.beam
    rng = np.random.default_rng(0)
    for _ in range(5):
        x = rng.normal(size=arm.n_states) * 0.1
        u = rng.normal(size=1)
        hub = x[:2]
        zb = x[2 : 2 + b.n_states]
        yb = b.C @ zb + b.D @ hub
        tau_a = m.drive.k_u * u[0] - (m.drive.k_omega + m.V) * hub[1] - yb[1] + m.friction.bias
        fr = m.friction
        f = (
            np.clip(tau_a, -fr.static, fr.static)
            if abs(hub[1]) < fr.velocity_tolerance
            else fr.coulomb * np.sign(hub[1])
        )
        want = np.concatenate([[hub[1], (tau_a - f) / m.J], b.A @ zb + b.B @ hub])
        got = np.asarray(arm.rhs(jnp.asarray(x), jnp.asarray(u)))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


def test_multi_link_torque_sources_are_the_body():
    """Without ``joints`` (ideal torque sources, no friction) the Arm is the DLS plant."""
    arm, model = multi_link_arm(benchmark_arm())
    x = model.state(theta=[-1.2, 0.4], delta=[1e-3, -2e-4, 5e-4, 1e-4], theta_dot=[0.3, -0.2])
    u = np.array([1.5, -0.7])
    np.testing.assert_array_equal(
        np.asarray(arm.rhs(jnp.asarray(x), jnp.asarray(u))),
        np.asarray(model.plant.rhs(jnp.asarray(x), jnp.asarray(u))),
    )
    assert arm.input_names == ("torque_1", "torque_2")


def _geared(friction: dict | None = None, drive: str = "current") -> MultiLinkArm:
    spec = benchmark_arm()
    d = (
        {"drive": "current", "torque_constant": 2.0, "current_limit": 3.0}
        if drive == "current"
        else {
            "drive": "voltage",
            "motor_constant": 0.03,
            "armature_resistance": 2.0,
            "gear_ratio": 50,
            "rotor_inertia": 4e-6,
        }
    )
    j = Joint.model_validate(
        {"drive": d, "viscous": 0.05, "friction": friction or {"model": "none"}}
    )
    return spec.model_copy(update={"joints": [j, j]})


def test_drives_and_mobility_columns():
    """τ = K_t i − V θ̇ enters the DLS plant as its torque; G_j = B⁻¹ e_j (the layered
    program's columns against numpy's inverse of the mass matrix)."""
    arm, model = multi_link_arm(_geared())
    x = model.state(theta=[-1.2, 0.4], delta=[1e-3, -2e-4, 5e-4, 1e-4], theta_dot=[0.3, -0.2])
    i = np.array([0.5, -0.25])
    want = model.rhs(x, 2.0 * i - 0.05 * x[6:8])
    np.testing.assert_allclose(
        np.asarray(arm.rhs(jnp.asarray(x), jnp.asarray(i))), want, rtol=1e-12, atol=1e-12
    )
    qdd, G = arm.body.acceleration_and_mobility(jnp.asarray(x), jnp.asarray(2.0 * i))
    Binv = np.linalg.inv(model.mass_matrix(x[:6]))
    np.testing.assert_allclose(np.asarray(G), Binv[:2], rtol=1e-10, atol=1e-12 * np.abs(Binv).max())
    assert arm.input_names == ("current_1", "current_2")
    np.testing.assert_array_equal(np.asarray(arm.command_limit), [3.0, 3.0])
    # a geared voltage drive adds K_g² J_m to the hub inertia
    _, mv = multi_link_arm(_geared(drive="voltage"))
    assert mv.arm.hubs[0].inertia == pytest.approx(0.1 + 50**2 * 4e-6, rel=1e-15)


def test_stuck_joints_hold_exactly_together():
    """Both joints stuck (|τ_a| < F_s): the coupled balance τ_a,S = G_SS⁻¹ q̈_S makes both
    joint accelerations exactly zero while the links still move."""
    arm, model = multi_link_arm(_geared({"model": "coulomb", "coulomb": 5.0, "static": 6.0}))
    x = jnp.asarray(model.state(theta=[-1.0, 0.3], delta=[1e-3, -2e-4, 5e-4, 1e-4]))
    xd = arm.rhs(x, jnp.asarray([0.1, -0.1]))
    assert np.abs(np.asarray(xd[6:8])).max() < 1e-12 * np.abs(np.asarray(xd[8:])).max()
    assert np.abs(np.asarray(xd[8:])).max() > 1.0
    # after a substep in which joint 2 crossed zero velocity, it is stopped by an impulse
    # along G_2 (θ̇_2 = 0, θ̇_1 changed by G_12 λ, momentum consistent)
    x_prev = x.at[7].set(1e-2)
    x_next = x.at[7].set(-1e-2).at[6].set(0.5)
    out = np.asarray(arm.project(x_prev, x_next, jnp.asarray([0.0, 0.0])))
    assert out[7] == 0.0 and out[6] != 0.5


def test_torsional_link_frequency():
    """A rigid link of inertia J_0 on a torsional spring K, driven by a free hub J_h:
    ω² = K (J_h + J_0) / (J_h J_0) (the two-inertia oscillator)."""
    J_h, J0, K = 0.02, 0.05, 3.0
    arm = MultiLinkArm(
        links=[Link(model="torsional", length=0.4, mass=0.5, inertia=J0, torsional_stiffness=K)],
        hubs=[Hub(inertia=J_h)],
        gravity=0.0,
    )
    model = build_multilink(arm)
    A = np.asarray(jax.jacfwd(lambda x: model.plant.rhs(x, jnp.zeros(1)))(jnp.zeros(4)))
    w = np.sort(np.abs(np.linalg.eigvals(A).imag))[-1]
    assert w == pytest.approx(math.sqrt(K * (J_h + J0) / (J_h * J0)), rel=1e-12)
    # its deflection angle signal is α itself
    sig = dict(
        zip(
            model.plant.signal_names,
            np.asarray(model.plant.signals(jnp.asarray([0.1, 0.02, 0, 0]), jnp.zeros(1))),
            strict=True,
        )
    )
    assert sig["deflection_angle_1"] == pytest.approx(0.02, rel=1e-15)


@pytest.fixture(scope="module")
def geared_runs():
    out = {}
    for name in ("deluca-two-link-geared", "deluca-two-link-geared-fc"):
        p = prepare(load_scenario(name))
        out[name] = (p, run_prepared(p))
    return out


def test_stiction_stops_law_8_short_by_what_static_friction_explains(geared_runs):
    """DLS law (8) sampled, geared voltage drives with stiction: the joints stop short of θ_d,
    and at rest the torque the drive applies minus the gravity torque at the actual
    configuration is within the static friction, |τ − g_θ(θ, δ)| <= F_s."""
    p, r = geared_runs["deluca-two-link-geared"]
    sc, arm, model = p.scenario, p.loop.plant, p.model
    q = 2 * math.pi / 2**16
    th = np.stack([r.signals["theta_1"], r.signals["theta_2"]], 1)
    err = np.asarray(sc.controller.target) - th[-1]
    assert np.all(np.abs(th[-1] - th[-100]) == 0.0)  # at rest for the last 0.1 s
    assert np.abs(err).max() > 10 * q  # stopped short by more than ten counts
    x = np.asarray(r.states)[:, -1]  # python-control layout: (n_x, T)
    u = np.asarray(r.inputs)[:, -1]
    tau = np.asarray(arm.k_u) * u - np.asarray(arm.k_omega + arm.viscous) * x[6:8]
    g = gravity_torque(model, x[:2], x[2:6])
    Fs = [j.friction.static for j in sc.arm.joints]
    assert np.all(np.abs(tau - g) <= np.asarray(Fs) * (1 + 1e-9))
    # the friction signal closes the joints' equations of motion (DLS eq. 1) with the
    # links still ringing: F = τ − [B q̈ + c + g]_θ at θ̈ = 0
    f = np.array([r.signals["friction_torque_1"][-1], r.signals["friction_torque_2"][-1]])
    qdd = np.asarray(arm.rhs(jnp.asarray(x), jnp.asarray(u)))[6:]
    assert np.abs(qdd[:2]).max() < 1e-12 * max(1.0, np.abs(qdd).max())  # held (round-off)
    q, qd = x[:6], x[6:]
    rhs = model.mass_matrix(q) @ qdd + model.coriolis(q, qd) + model.gravity(q)
    np.testing.assert_allclose(f, tau - rhs[:2], rtol=1e-9, atol=1e-9)


def test_friction_compensation_brings_the_error_below_one_count(geared_runs):
    p, r = geared_runs["deluca-two-link-geared-fc"]
    th = np.stack([r.signals["theta_1"], r.signals["theta_2"]], 1)
    err = np.asarray(p.scenario.controller.target) - th[-1]
    assert np.abs(err).max() < 2 * math.pi / 2**16
