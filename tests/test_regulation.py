"""De Luca & Siciliano regulation under gravity on the benchmark arm (flexarm.control.regulation).

Paper setup: from the hanging configuration θ = (−90°, 0), δ = 0 to θ_d = (−45°, 0) with
K_P = diag(18, 18) N·m/rad, K_D = diag(10, 2) N·m·s/rad. All closed-loop runs have 2000
output samples so that each law compiles once (step and sample time are traced).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm.control import regulation as R
from flexarm.errors import SimulationDiverged
from flexarm.models.multilink import build_multilink
from flexarm.sim.continuous import simulate_continuous
from flexarm.specs.multilink import benchmark_arm

DEG = math.pi / 180
PAPER_DELTA_D = np.array([-0.15, -0.0045, -0.0056, -0.000076])
THETA_D = np.array([-45 * DEG, 0.0])


@pytest.fixture(scope="module")
def model():
    return build_multilink(benchmark_arm())


@pytest.fixture(scope="module")
def params(model):
    return R.regulation_params(model, [18, 18], [10, 2], THETA_D)


@pytest.fixture(scope="module")
def x0(model):
    return model.state(theta=[-90 * DEG, 0.0])


@pytest.fixture(scope="module")
def run8(model, params, x0):
    return simulate_continuous(model, R.law_pd_constant, x0, 2.0, 1e-3, params=params)


def test_residual_deflection_eq9(model, params):
    dd = np.asarray(params.delta_d)
    q = np.concatenate([THETA_D, dd])
    res = model.K @ dd + model.gravity(q)[2:]
    assert np.abs(res).max() < 1e-10
    print("\nδ_d  (ours) ", np.array2string(dd, precision=6))
    print("δ_d (paper) ", PAPER_DELTA_D)
    tip = model.modes[0].tip_value @ dd[:2]
    print(f"w_1(ℓ) = {tip * 1e3:.2f} mm, g_θ(θ_d, δ_d) = {np.asarray(params.g_d)} N·m")
    assert -0.2 < dd[0] < -0.1 and tip < 0  # same size and sense as the paper's δ_11
    np.testing.assert_allclose(params.g_d, R.gravity_torque(model, THETA_D, dd))


def test_pd_law_8_reaches_the_target_within_2s(model, params, x0, run8):
    np.testing.assert_allclose(
        run8.torque[0], 18 * 45 * DEG * np.array([1, 0]) + params.g_d, rtol=1e-12
    )
    k = 2000
    assert run8.time[k] == pytest.approx(2.0)
    eth = np.abs(run8.theta[k] - THETA_D) / DEG
    dd = np.asarray(params.delta_d)
    e_norm = np.linalg.norm(run8.delta[k] - dd) / np.linalg.norm(dd)
    e_comp = np.abs(run8.delta[k] - dd) / np.abs(dd)
    print(f"\nt = 2 s: |θ − θ_d| = {eth} deg, ‖δ − δ_d‖/‖δ_d‖ = {e_norm:.4f}, per mode {e_comp}")
    assert eth.max() < 0.5
    assert e_norm < 0.02


def test_pd_law_8_steady_torque_is_gravity_torque(model, params, x0):
    # Without structural damping the 64 rad/s mode of link 2 is damped only through joint 2
    # (closed-loop time constant ≈ 4.7 s): the torque settles to 1e-3 N·m after ≈ 12 s.
    run = simulate_continuous(model, R.law_pd_constant, x0, 15.0, 7.5e-3, params=params)
    du = np.abs(run.torque - np.asarray(params.g_d)).max(axis=1)
    last = run.time >= 14.5
    settled = run.time[np.nonzero(du > 1e-3)[0][-1]]
    print(
        f"\n|u − g_θ(θ_d, δ_d)| over the last 0.5 s: {du[last].max():.2e} N·m; "
        f"within 1e-3 after t = {settled:.2f} s"
    )
    assert du[last].max() < 1e-3


def test_law_30_smaller_initial_torque_and_converges(model, params, x0):
    laws = [R.law_pd_constant, R.law_pd_online, R.law_pd_quasistatic]
    xd = model.state(theta=THETA_D, delta=params.delta_d)

    @jax.jit
    def torques(p, x0, xd):
        return [(law(p, x0, 0.0), law(p, xd, 0.0)) for law in laws]

    (u8, e8), (ua, ea), (ub, eb) = torques(params, jnp.asarray(x0), jnp.asarray(xd))
    print(
        f"\n|u(0)|: (8) {np.linalg.norm(u8):.4f}, (30a) {np.linalg.norm(ua):.4f}, "
        f"(30b) {np.linalg.norm(ub):.4f} N·m"
    )
    assert np.linalg.norm(ua) < np.linalg.norm(u8)
    assert np.linalg.norm(ub) < np.linalg.norm(u8)
    for e in (e8, ea, eb):  # at the target every law holds the arm with g_θ(θ_d, δ_d)
        np.testing.assert_allclose(e, params.g_d, atol=1e-9)
    run = simulate_continuous(model, R.law_pd_online, x0, 3.0, 1.5e-3, params=params)
    eth = np.abs(run.theta[-1] - THETA_D) / DEG
    print(f"(30a) at t = 3 s: |θ − θ_d| = {eth} deg")
    assert eth.max() < 0.5


def test_alpha_and_sufficient_conditions(model, params, run8):
    alpha, k = R.alpha_along(model, run8.state_array)
    q = run8.state_array[:, : model.n_q]
    region = R.alpha_bound(
        model, q[:, :2].min(0), q[:, :2].max(0), np.abs(q[:, 2:]).max(0), n_samples=2000, refine=2
    )
    cond = R.stability_conditions(model, [18, 18], alpha)
    print(
        f"\nα a posteriori = {alpha:.4f} at t = {run8.time[k]:.3f} s (paper: 17.67); over the "
        f"box around the run α = {region.alpha:.4f}\n{cond.summary()}"
    )
    assert region.alpha >= alpha * (1 - 1e-9)
    assert cond.lambda_min_K == pytest.approx(np.diag(model.K).min(), rel=1e-9)
    assert cond.holds_14 and cond.holds_15
    weak = R.stability_conditions(model, [5, 5], alpha)
    assert not weak.holds_15 and weak.margin_15 == pytest.approx(5 - alpha)


def test_interpolating_trajectory_lowers_the_peak_torque(model, params, x0, run8):
    p = R.regulation_params(model, [18, 18], [10, 2], THETA_D, theta_0=x0[:2], duration=1.0)
    th, thd = jax.vmap(lambda t: R.reference(p, t))(jnp.asarray([0.0, 0.5, 1.0, 2.0]))
    np.testing.assert_allclose(th[:, 0], [-90 * DEG, -67.5 * DEG, -45 * DEG, -45 * DEG])
    np.testing.assert_allclose(thd[[0, 2, 3], 0], 0.0, atol=1e-15)
    run = simulate_continuous(model, R.law_pd_constant, x0, 2.0, 1e-3, params=p)
    peak, peak_step = np.abs(run.torque).max(), np.abs(run8.torque).max()
    eth = np.abs(run.theta[-1] - THETA_D) / DEG
    print(
        f"\npeak |u|: step {peak_step:.3f}, quintic over 1 s {peak:.3f} N·m; "
        f"|θ − θ_d| at 2 s {eth} deg"
    )
    assert peak < 0.5 * peak_step
    assert eth.max() < 1.0  # the move ends at 1 s; 0.49 deg left at 2 s (step: 0.27 deg)


def test_torque_limit_saturates_the_command(params, x0):
    limited = build_multilink(benchmark_arm().model_copy(update={"torque_limit": [5.0, 2.0]}))
    run = simulate_continuous(limited, R.law_pd_constant, x0, 2.0, 1e-3, params=params)
    np.testing.assert_allclose(run.torque[0], [5.0, params.g_d[1]], rtol=1e-12)
    assert np.all(np.abs(run.torque) <= np.array([5.0, 2.0]) + 1e-12)


def test_divergence_is_reported(model, x0):
    p = R.regulation_params(model, [1e5, 1e5], [1e3, 1e3], THETA_D)
    with pytest.raises(SimulationDiverged, match=r"t = .* s: \w+ =") as err:
        simulate_continuous(model, R.law_pd_constant, x0, 10.0, 5e-3, params=p, step=5e-3)
    print("\n" + str(err.value))


def test_bad_regulation_input(model):
    with pytest.raises(ValueError, match="KP"):
        R.regulation_params(model, [18, 18, 18], [10, 2], THETA_D)
    with pytest.raises(ValueError, match="theta_0"):
        R.regulation_params(model, 18, 10, THETA_D, duration=1.0)
    with pytest.raises(ValueError, match="method"):
        simulate_continuous(
            model, R.law_pd_constant, np.zeros(12), 1.0, 1e-3, params=None, method="euler"
        )
    p = R.regulation_params(model, 18, 10, THETA_D)
    with pytest.raises(ValueError, match=r"x0 has 4 values; this arm's state has 12: theta_1"):
        simulate_continuous(model, R.law_pd_constant, np.zeros(4), 1.0, 1e-3, params=p)
    with pytest.raises(ValueError, match="NaN"):
        simulate_continuous(model, R.law_pd_constant, np.full(12, np.nan), 1.0, 1e-3, params=p)


def test_regulation_refuses_cable_springs():
    """DLS's eqs. (9) and (14) have no joint cable springs: one line naming the field."""
    from flexarm.control.regulation import RegulationError, residual_deflection
    from flexarm.models.multilink import build_multilink
    from flexarm.specs.multilink import MultiLinkArm, benchmark_arm

    d = benchmark_arm().model_dump()
    d["joints"] = [{"cable_stiffness": 0.0}, {"cable_stiffness": 0.2}]
    model = build_multilink(MultiLinkArm(**d))
    with pytest.raises(RegulationError, match=r"arm.joints\[1\].cable_stiffness = 0.2"):
        residual_deflection(model, [0.1, 0.2])
