"""Layered scalar programs (flexarm.layered) and the fast multi-link closed loops built on
them: the same numbers as the plain derivation, for one state and for a batch."""

import math

import control
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm import layered as L
from flexarm.control import regulation as R
from flexarm.models.multilink import build_multilink
from flexarm.sim.continuous import simulate_continuous, simulate_continuous_batch
from flexarm.specs.multilink import Hub, Link, MultiLinkArm, benchmark_arm

DEG = math.pi / 180


@pytest.mark.parametrize("n", [1, 2, 5, 7])
@pytest.mark.parametrize("block", [1, 2, 3])
def test_solve_spd_on_numbers(n, block):
    rng = np.random.default_rng(n)
    M = rng.normal(size=(n, n))
    A = M @ M.T + n * np.eye(n)
    b = rng.normal(size=n)
    y = L.solve_spd(A.tolist(), b.tolist(), block)
    np.testing.assert_allclose(A @ np.array(y), b, atol=1e-12)


def test_program_folds_shares_and_emits_the_same_values():
    p = L.Program()
    x, y = p.leaf("x"), p.leaf("y")
    assert (x * 1.0) is x and (x * 0.0) == 0.0 and (0.0 + x) is x
    assert (x * y).id == (y * x).id  # hash-consed, commutative
    s = L.sin(x) * y
    outs = [s + L.cos(y) / (1.0 + x * x), s * s - L.rsqrt(2.0 + y * y), -x + 3.0 * s]
    assert p.n_layers(outs, share=0) >= 1

    def direct(xv, yv):
        s = np.sin(xv) * yv
        return np.array(
            [s + np.cos(yv) / (1 + xv * xv), s * s - 1 / np.sqrt(2 + yv * yv), -xv + 3 * s]
        )

    vals = {"x": jnp.asarray(0.3), "y": jnp.asarray(-1.7)}
    got = jax.jit(lambda v: p.emit(outs, v.__getitem__, share=0))(vals)
    np.testing.assert_allclose(got, direct(0.3, -1.7), rtol=1e-14)
    xb, yb = np.linspace(-1, 1, 11), np.linspace(2, 3, 11)  # trailing batch, > 8 outputs path
    gotb = p.emit(outs * 4, {"x": jnp.asarray(xb), "y": jnp.asarray(yb)}.__getitem__, share=2)
    np.testing.assert_allclose(gotb[:3], direct(xb, yb), rtol=1e-14)
    np.testing.assert_allclose(gotb[9:12], direct(xb, yb), rtol=1e-14)
    with pytest.raises(TypeError, match="Sym and Python numbers"):
        x + jnp.ones(())


@pytest.mark.parametrize("arm", ["bench", "three"])
def test_plant_rhs_equals_the_plain_solve(arm):
    if arm == "bench":
        spec = benchmark_arm()
    else:
        spec = MultiLinkArm(
            links=[
                Link(length=0.4, linear_density=0.5, flexural_rigidity=20, modes=2),
                Link(length=0.3, linear_density=0.3, modes=0),
                Link(
                    length=0.3,
                    linear_density=0.2,
                    flexural_rigidity=8,
                    modes=3,
                    mode_type="clamped_free",
                    damping_ratio=0.02,
                ),
            ],
            hubs=[Hub(inertia=0.05), Hub(mass=0.5, inertia=0.02), Hub(mass=0.3, inertia=0.01)],
        )
    model = build_multilink(spec)
    P, nq = model.plant, model.n_q
    rng = np.random.default_rng(1)
    xs = np.concatenate(
        [
            rng.uniform(-3, 3, (5, model.n_links)),
            rng.uniform(-0.05, 0.05, (5, model.n_delta)),
            rng.normal(size=(5, nq)),
        ],
        axis=1,
    )
    us = rng.normal(size=(5, model.n_links))

    @jax.jit
    def plain(x, u):
        B, h = P._terms(x[:nq], x[nq:], P.gamma)
        return jnp.linalg.solve(B, P._forces(x[:nq], x[nq:], u, h))

    rhs = jax.jit(lambda plant, x, u: plant.rhs(x, u))
    for x, u in zip(xs, us, strict=True):
        ref = plain(jnp.asarray(x), jnp.asarray(u))
        got = rhs(P, jnp.asarray(x), jnp.asarray(u))
        np.testing.assert_allclose(got[nq:], ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
        np.testing.assert_array_equal(got[:nq], x[nq:])
    batched = rhs(P, jnp.asarray(xs.T), jnp.asarray(us.T))  # (n_x, batch): batch last
    for k in range(5):
        # the same arithmetic, vectorised over the batch or not: the two can round
        # differently (FMA contraction, operand order) by a few ulps of the largest terms
        # summed, so the floor scales with the vector's largest entry (on an AMD EPYC
        # without AVX-512: 3.6e-11 on an entry of 306 beside entries of 8.9e5)
        one = np.asarray(rhs(P, jnp.asarray(xs[k]), jnp.asarray(us[k])))
        np.testing.assert_allclose(batched[:, k], one, rtol=1e-13, atol=1e-13 * np.abs(one).max())


def test_batch_of_gain_variations_equals_single_runs():
    model = build_multilink(benchmark_arm())
    theta_d = [-45 * DEG, 0.0]
    scale = np.array([0.8, 1.0, 1.3])
    pb, axes = R.regulation_params_batch(model, np.outer(scale, [18, 18]), [10, 2], theta_d)
    x0 = model.state(theta=[-90 * DEG, 0.0])
    out = simulate_continuous_batch(
        model, R.law_pd_constant, x0, 0.2, 1e-2, params=pb, axes=axes, chunk=2
    )  # 3 runs: one padded chunk
    assert out.state_array.shape == (3, 21, 12) and out.torque.shape == (3, 21, 2)
    assert not out.diverged.any()
    # python-control's trace layout: (n, traces, T)
    assert out.states.shape == (12, 3, 21) and out.inputs.shape == (2, 3, 21)
    for k, s in enumerate(scale):
        p = R.regulation_params(model, s * np.array([18, 18]), [10, 2], theta_d)
        one = simulate_continuous(model, R.law_pd_constant, x0, 0.2, 1e-2, params=p)
        np.testing.assert_allclose(out.state_array[k], one.state_array, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.torque[k], one.torque, rtol=0, atol=1e-10)
    # one rollout is a control.TimeResponseData: (n, T) arrays, labels, named access
    assert isinstance(one, control.TimeResponseData)
    assert one.states.shape == (12, 21) and one.inputs.shape == (2, 21)
    # outputs: the plant's signals (q = (θ, δ) first, then tip position, rates, deflections)
    assert one.outputs.shape == (len(model.plant.signal_names), 21)
    assert one.output_labels[:6] == one.state_labels[:6]
    assert one.input_labels == ["torque_1", "torque_2"] and one.state_labels[0] == "theta_1"
    np.testing.assert_array_equal(one["theta_1"], one.theta[:, 0])
    np.testing.assert_array_equal(one["torque_2"], one.torque[:, 1])
    np.testing.assert_array_equal(out.run(2).state_array, out.state_array[2])
    with pytest.raises(KeyError, match="no such signal"):
        one["tip_angle"]
    with pytest.raises(ValueError, match="batch"):
        R.regulation_params_batch(model, [18, 18], [10, 2], theta_d)


def test_continuous_run_to_csv_round_trip(tmp_path):
    from flexarm.io.logs import LogExistsError, read_log

    model = build_multilink(benchmark_arm())
    p = R.regulation_params(model, [18, 18], [10, 2], [-45 * DEG, 0.0])
    run = simulate_continuous(
        model, R.law_pd_constant, model.state(theta=[-90 * DEG, 0.0]), 0.1, 1e-2, params=p
    )
    path = run.to_csv(tmp_path / "run.csv")
    log = read_log(path, required=("time",), min_samples=2)
    assert list(log.signals) == [*run.state_names, "torque_1", "torque_2"]
    np.testing.assert_allclose(log["theta_1"], run.theta[:, 0], rtol=1e-9)
    np.testing.assert_allclose(log["torque_2"], run.torque[:, 1], rtol=1e-9, atol=1e-12)
    with pytest.raises(LogExistsError):
        run.to_csv(path)
