"""Continuous-time laws in the one sampled-data loop (control/continuous_law.ContinuousLaw,
sim/integrate.integrate_law, sim/continuous front-ends).

The must-show of issue #13: the continuous-law loop equals the old ``simulate_continuous`` on
the De Luca reproduction to 1e-9. The old code's core was plain RK4 of
ẋ = f(x, sat(law(x, t))) with the law at every stage; :func:`plain_rk4` below is that
integrator written out independently of flexarm's (its own stage sums, its own time), and
the loop is checked against it. (Against the parent commit's ``simulate_continuous`` itself,
measured once: laws (8), (30a), (30b) over 2 s and 15 s and the batch bit for bit or within
4e-15, the quintic reference within 7e-13 rad/m.)
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm.control import regulation as R
from flexarm.control.continuous_law import ContinuousLaw
from flexarm.control.discrete import FunctionController
from flexarm.models.multilink import build_multilink
from flexarm.sim import sampled
from flexarm.sim.build import prepare
from flexarm.sim.continuous import law_loop, simulate_continuous, simulate_continuous_batch
from flexarm.specs import builtin_scenarios, load_scenario
from flexarm.specs.multilink import benchmark_arm

DEG = math.pi / 180
THETA_0, THETA_D = np.array([-90 * DEG, 0.0]), np.array([-45 * DEG, 0.0])


def plain_rk4(plant, law, params, x0, dt, n_sub, n_out):
    """The classical RK4 of ẋ = f(x, clip(law(params, x, t), ±limit)), step dt/n_sub, states
    and applied torques at t = k dt, k = 0..n_out: x + h/6 (k1 + 2k2 + 2k3 + k4)."""
    lim = plant.command_limit
    h = dt / n_sub

    def u_of(x, t):
        return jnp.clip(law(params, x, t), -lim, lim)

    def f(x, t):
        return plant.rhs(x, u_of(x, t))

    def step(i, c):
        x, t0 = c
        t = t0 + i * h
        k1 = f(x, t)
        k2 = f(x + 0.5 * h * k1, t + 0.5 * h)
        k3 = f(x + 0.5 * h * k2, t + 0.5 * h)
        k4 = f(x + h * k3, t + h)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), t0

    @jax.jit
    def run(x0):
        def sample(x, k):
            x1, _ = jax.lax.fori_loop(0, n_sub, step, (x, k * dt))
            return x1, (x, u_of(x, k * dt))

        _, (xs, us) = jax.lax.scan(sample, x0, jnp.arange(n_out + 1))
        return xs, us

    xs, us = run(jnp.asarray(x0))
    return np.asarray(xs), np.asarray(us)


@pytest.fixture(scope="module")
def model():
    return build_multilink(benchmark_arm())


@pytest.mark.parametrize("law, duration", [(R.law_pd_constant, 0.0), (R.law_pd_quasistatic, 1.0)])
def test_loop_equals_plain_rk4_of_the_law(model, law, duration):
    # De Luca's reproduction: law (8) from the hanging arm over 2 s (dt 1 ms, 10 RK4 steps of
    # 0.1 ms), and law (30b) (Newton steps inside the law) on the quintic reference
    # (time-dependent). Same method, same steps: they differ by the rounding of the stage
    # sums, amplified over 20 000 steps; the measured gap is <= 1e-14, the bound
    # 1e-9 is the tolerance.
    p = R.regulation_params(model, [18, 18], [10, 2], THETA_D, theta_0=THETA_0, duration=duration)
    x0 = model.state(theta=THETA_0)
    run = simulate_continuous(model, law, x0, 2.0, 1e-3, params=p)
    xs, us = plain_rk4(model.plant, law, p, x0, 1e-3, 10, 2000)
    dx, du = np.abs(run.state_array - xs).max(), np.abs(run.torque - us).max()
    print(f"\n{law.__name__}: loop vs plain RK4: states {dx:.1e}, torques {du:.1e} N·m")
    assert run.state_array.shape == (2001, 12) and run.time[-1] == pytest.approx(2.0)
    assert dx < 1e-9 and du < 1e-9
    # the applied torque at t = 0 is the law at x0 (eq. 8: K_P (θ_d − θ0) + g_θ(θ_d, δ_d))
    if law is R.law_pd_constant:
        np.testing.assert_allclose(
            run.torque[0], 18 * 45 * DEG * np.array([1, 0]) + p.g_d, rtol=1e-12
        )


def test_held_command_of_a_sampled_part_is_added(model):
    # A sampled part that holds a constant feed-forward c plus the law: the plant sees
    # sat(c + law(x, t)), the same as the law c + law alone (floating-point addition
    # commutes exactly), so the runs agree to rounding (1e-12).
    p = R.regulation_params(model, [18, 18], [10, 2], THETA_D)
    c = jnp.asarray([0.3, -0.1])
    x0 = model.state(theta=THETA_0)
    loop = law_loop(model, R.law_pd_constant, p, 1e-3, 10)
    ff = FunctionController(lambda prm, s, m, r: (s, prm), c, jnp.zeros(()))
    with_part = eqx.tree_at(
        lambda lp: lp.controller, loop, ContinuousLaw(R.law_pd_constant, p, loop.dt, 2, ff)
    )
    shifted = eqx.tree_at(
        lambda lp: lp.controller,
        loop,
        ContinuousLaw(lambda prm, x, t: R.law_pd_constant(prm, x, t) + c, p, loop.dt, 2),
    )
    a = sampled.simulate_loop(with_part, x0, {}, 500)
    b = sampled.simulate_loop(shifted, x0, {}, 500)
    np.testing.assert_allclose(a["states"], b["states"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a["command"], b["command"], rtol=0, atol=1e-12)
    # and c moved the run: the rest position differs from the law alone
    plain = sampled.simulate_loop(loop, x0, {}, 500)
    assert np.abs(a["states"][-1, :2] - plain["states"][-1, :2]).max() > 1e-3


def test_sampled_controller_through_the_law_path_equals_the_hold_path():
    # deluca-two-link-geared: geared voltage drives, stiction at both joints, 16-bit encoders,
    # sampled joint PD. Its controller as the sampled part of a ContinuousLaw whose law is
    # zero must give the zero-order-hold loop: the plant sees sat(u_k + 0) = u_k at every
    # stage. Both integrate with the same RK4 steps (stage sums in another order); over
    # 1 s with stick events the measured gap is at rounding level, 1e-9 rad is the bound.
    p = prepare(load_scenario(builtin_scenarios()["deluca-two-link-geared"]))
    n = 1001
    m = p.loop.plant.n_inputs
    zero = ContinuousLaw(lambda prm, x, t: jnp.zeros(m), None, p.loop.dt, m, p.loop.controller)
    refs = {k: v[:n] for k, v in p.references.items()}
    held = sampled.simulate_loop(p.loop, p.x0, refs, n)
    law = sampled.simulate_loop(eqx.tree_at(lambda lp: lp.controller, p.loop, zero), p.x0, refs, n)
    dx = np.abs(held["states"] - law["states"]).max()
    print(f"\nsampled PD: hold path vs law path, 1 s with stiction: {dx:.1e}")
    assert dx < 1e-9
    np.testing.assert_allclose(held["command"], law["command"], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(held["measured"], law["measured"])


def test_adaptive_tsit5_through_the_loop_agrees_with_rk4(model):
    # Law (8) over 0.5 s: Tsit5 (rtol 1e-10, atol 1e-12, adaptive within each 5 ms output
    # period) against RK4 at 25 µs. RK4's own error there, by Richardson from the 50 µs run,
    # is |x_25 − x_50| / 15 (measured 1e-11); Tsit5's is of the order of its tolerances times
    # the states (<= 1e-10). Their gap (measured 2e-13 on q) must stay below 1e-9 rad/m.
    p = R.regulation_params(model, [18, 18], [10, 2], THETA_D)
    x0 = model.state(theta=THETA_0)
    ts = simulate_continuous(
        model,
        R.law_pd_constant,
        x0,
        0.5,
        5e-3,
        params=p,
        method="tsit5",
        rtol=1e-10,
        atol=1e-12,
        step=1e-4,
    )
    r25 = simulate_continuous(model, R.law_pd_constant, x0, 0.5, 5e-3, params=p, step=2.5e-5)
    r50 = simulate_continuous(model, R.law_pd_constant, x0, 0.5, 5e-3, params=p, step=5e-5)
    rk_err = np.abs(r25.state_array - r50.state_array).max() / 15
    gap = np.abs(ts.state_array[:, :6] - r25.state_array[:, :6]).max()
    print(f"\ntsit5 vs RK4 25 µs: {gap:.1e} (RK4 error estimate {rk_err:.1e})")
    assert rk_err < 1e-10
    assert gap < 1e-9


def test_batch_is_one_result_and_checks_its_input(model):
    scale = np.array([0.9, 1.1])
    pb, axes = R.regulation_params_batch(model, np.outer(scale, [18, 18]), [10, 2], THETA_D)
    x0 = model.state(theta=THETA_0)
    out = simulate_continuous_batch(model, R.law_pd_constant, x0, 0.1, 1e-2, params=pb, axes=axes)
    assert out.is_batch and out["theta_1"].shape == (2, 11) and out.theta.shape == (2, 11, 2)
    one = out.run(1)
    p1 = R.regulation_params(model, [1.1 * 18] * 2, [10, 2], THETA_D)
    ref = simulate_continuous(model, R.law_pd_constant, x0, 0.1, 1e-2, params=p1)
    # same loop, same steps; the batch is carried (n_x, B): rounding only (1e-12)
    np.testing.assert_allclose(one.state_array, ref.state_array, rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="one rollout"):
        ref.run(0)
    with pytest.raises(ValueError, match="a batch has several rollouts"):
        out.to_csv("never.csv")
    # one initial state per rollout: rollout 1 from x0 equals the shared-x0 batch's
    x0s = np.stack([model.state(theta=[-80 * DEG, 0.0]), x0])
    per = simulate_continuous_batch(
        model, R.law_pd_constant, x0s, 0.1, 1e-2, params=pb, axes=axes, chunk=1
    )
    np.testing.assert_allclose(per.state_array[1], one.state_array, rtol=0, atol=1e-12)
    np.testing.assert_allclose(per.state_array[0, 0], x0s[0], rtol=0, atol=0)
    with pytest.raises(ValueError, match=r"x0 must be \(12,\) or \(N, 12\)"):
        simulate_continuous_batch(
            model, R.law_pd_constant, np.zeros(4), 0.1, 1e-2, params=pb, axes=axes
        )
    with pytest.raises(ValueError, match="x0 holds 3 initial states; the batch has 2"):
        simulate_continuous_batch(
            model, R.law_pd_constant, np.zeros((3, 12)), 0.1, 1e-2, params=pb, axes=axes
        )
    # the loop's generic batch (vmap over the batched gains, batch first) runs the same
    # rollouts as the batch-last layout: rounding only (1e-12)
    loop = law_loop(model, R.law_pd_constant, pb, 1e-2, 100)
    in_axes = eqx.tree_at(
        lambda lp: lp.controller.params,
        jax.tree.map(lambda _: None, loop),
        axes,
        is_leaf=lambda a: a is None,
    )
    vb = sampled.simulate_batch(loop, x0, {}, 11, in_axes=in_axes)
    np.testing.assert_allclose(vb["states"], out.state_array, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vb["command"], out.torque, rtol=0, atol=1e-10)
    with_sensor = eqx.tree_at(
        lambda lp: lp.sensors, loop, sampled.Sensors.make(model.plant, {"theta_1": {}})
    )
    with pytest.raises(ValueError, match="ContinuousLaw alone"):
        sampled.simulate_law_batch(with_sensor, x0, 11, axes)
