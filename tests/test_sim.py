"""The sampled-data simulator: against the linear discrete model, friction, batches,
converters, delays, divergence, results."""

import control
import jax.numpy as jnp
import numpy as np
import pytest

from _helpers import scenario
from flexarm.control import discrete
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.build import prepare, simulate, to_result
from flexarm.sim.sampled import SimulationDiverged, simulate_batch

K = 2.184 * 0.112984829027616
FS = 0.288288 * 0.112984829027616
KP, KD, T = 15.0, 0.3, 0.003


def linear_scenario(step=0.02, friction="none", bits=0):
    return scenario(
        arm={"friction": {"model": friction, "coulomb": FS, "static": FS}},
        sensors={"motor_angle": {"bits": bits}, "tip_angle": {"bits": 0}},
        actuator={"bits": 0},
        reference={"type": "step", "amplitude": step, "start": 0.0},
        controller={"type": "pd", "kp": KP, "kd": KD, "measured": "motor_angle"},
    )


def test_pd_loop_without_friction_matches_the_linear_model():
    """θm of the simulated PD loop equals the discrete linear closed loop (ZOH plant,
    one-period delay) within 1 % of the step (no quantisation, no saturation)."""
    sc = linear_scenario()
    res = simulate(sc)
    assert np.max(np.abs(res["current"])) < 4.12  # linear range
    Gd = control.c2d(SingleLinkModel.from_spec(sc.arm).motor_tf(), T, "zoh")
    z = control.tf("z")
    C = KP + KD * (1 - 1 / z) / T
    L = Gd * C / z
    cl = control.feedback(L, 1)
    lin = control.forced_response(cl, T=res.time, U=res["reference"]).outputs
    assert np.max(np.abs(res["motor_angle"] - lin)) < 0.01 * 0.02
    # and it is not trivially flat: the response rises to the step
    assert res["motor_angle"][-1] == pytest.approx(0.02, rel=0.02)


def test_pd_loop_with_friction_keeps_a_steady_state_error():
    """With Coulomb friction the PD loop sticks short of the step while the undamped
    link rings on (FRB Sec. IV: the error friction leaves). At the end the hub is stuck,
    as Karnopp's condition |K u − C_t| <= F_s says; without friction the error vanishes."""
    on = simulate(linear_scenario(step=0.4, friction="coulomb", bits=12))
    off = simulate(linear_scenario(step=0.4, friction="none", bits=12))
    e_on = 0.4 - on["motor_angle"][-1]
    assert abs(e_on) > 1e-3  # a steady-state error of about a count or more
    assert np.ptp(on["motor_angle"][-100:]) == 0.0  # stuck for the last 0.3 s
    assert np.ptp(off["motor_angle"][-100:]) > 1e-4  # without friction the hub follows the link
    assert np.ptp(on["tip_angle"][-100:]) > 0.1  # while the link rings
    u, ct = on["current"][-100:], on["coupling_torque"][-100:]
    assert np.all(np.abs(K * u - ct) <= FS + 1e-12)


def test_batch_of_gains_equals_single_runs():
    sc = linear_scenario()
    p = prepare(sc)
    kps = np.array([5.0, 10.0, 20.0])
    ctrls = [discrete.pd(k, KD, T) for k in kps]
    stacked = discrete.LinearController(
        jnp.stack([c.A for c in ctrls]),
        jnp.stack([c.B for c in ctrls]),
        jnp.stack([c.C for c in ctrls]),
        jnp.stack([c.D for c in ctrls]),
    )
    import equinox as eqx
    import jax

    loop = eqx.tree_at(lambda lp: lp.controller, p.loop, stacked)
    axes = jax.tree.map(lambda _: None, loop)
    axes = eqx.tree_at(lambda lp: lp.controller, axes, discrete.LinearController(0, 0, 0, 0))
    out = simulate_batch(loop, p.x0, p.references, p.n_samples, in_axes=axes)
    for i, c in enumerate(ctrls):
        single = simulate(sc, controller=c)
        got = to_result(p, out, index=i)
        np.testing.assert_allclose(got["motor_angle"], single["motor_angle"], atol=1e-12)


def test_converters_noise_and_delays():
    sc = scenario(
        sensors={
            "motor_angle": {"bits": 12, "range": "360 deg", "noise": 1e-3},
            "tip_angle": {"delay": 3, "bits": 0},
        }
    )
    a, b = simulate(sc), simulate(sc)
    np.testing.assert_array_equal(a.measured["motor_angle"], b.measured["motor_angle"])  # seeded
    count = 2 * np.pi / 4096
    q = a.measured["motor_angle"] / count
    np.testing.assert_allclose(q, np.round(q), atol=1e-9)  # on the A/D grid
    assert np.std(a.measured["motor_angle"] - a["motor_angle"]) == pytest.approx(1e-3, rel=0.15)
    # pure delay of 3 samples on the tip sensor (no noise or quantisation there)
    np.testing.assert_allclose(a.measured["tip_angle"][3:], a["tip_angle"][:-3], atol=1e-15)
    # D/A: the applied current is on the 12-bit grid of ±4.12 A
    qa = a["current"] / (2 * 4.12 / 4096)
    np.testing.assert_allclose(qa, np.round(qa), atol=1e-9)
    assert np.max(np.abs(a["current"])) <= 4.12
    c = simulate(scenario(simulation={"seed": 7}, sensors={"motor_angle": {"noise": 1e-3}}))
    assert not np.array_equal(c.measured["motor_angle"], a.measured["motor_angle"])


def test_unstable_loop_raises_with_time_and_signal():
    sc = scenario(
        actuator={"limit": 1e9, "bits": 0}, controller={"type": "pd", "kp": 2000.0, "kd": 5.0}
    )
    with pytest.raises(SimulationDiverged, match=r"diverged at t = .* signal '\w+'"):
        simulate(sc)


def test_result_is_python_control_style(tmp_path):
    res = simulate(scenario())
    assert res.outputs.shape == (len(res.output_labels), len(res.time))
    assert res.inputs.shape == (1, len(res.time))
    assert "tip_angle" in res.output_labels
    fig = res.plot_arm()
    assert len(fig.axes) == 2
    path = res.to_csv(tmp_path / "log.csv")
    with pytest.raises(FileExistsError):
        res.to_csv(path)
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    assert lines[0] == "time,reference,current,motor_angle,tip_angle"
    body = "\n".join(line for line in path.read_text().splitlines() if not line.startswith("#"))
    import io

    data = np.genfromtxt(io.StringIO(body), delimiter=",", names=True)
    np.testing.assert_allclose(data["motor_angle"], res.measured["motor_angle"], rtol=1e-9)


def test_voltage_drive_pd_reaches_the_step():
    sc = scenario(
        arm={
            "motor": {
                "drive": "voltage",
                "inertia": 2e-3,
                "viscous": 4e-3,
                "motor_constant": 7.68e-3,
                "armature_resistance": 2.6,
                "gear_ratio": 70,
                "voltage_limit": 10.0,
            },
            "friction": {"model": "none"},
            "beam": {"model": "rigid", "length": 0.3, "masses": [{"mass": 0.05}]},
        },
        actuator={"bits": 0},
        sampling={"period": 0.001, "delay": 0},
        controller={"type": "pd", "kp": 20.0, "kd": 0.5},
    )
    res = simulate(sc)
    assert res.input_names == ("voltage",)
    assert res["motor_angle"][-1] == pytest.approx(0.4, rel=0.01)


def test_hold_tip_scenario_runs_and_initial_deflection_is_static():
    """The Fig. 11 set-up (tip held) simulates; an initial tip deflection bends the link
    (at rest relative to the hub) into the static shape under a tip force, with exactly
    that deflection."""
    held = simulate(scenario(simulation={"hold_tip": True}))
    assert np.ptp(held["tip_angle"]) < 1e-12 and np.ptp(held["motor_angle"]) > 0.1  # round-off only
    from flexarm.models.single_link import SingleLinkModel as M

    sc2 = scenario("feliu-two-mass")
    m = M.from_spec(sc2.arm)
    x0 = m.initial_state(motor_angle=0.3, tip_deflection=0.01)
    p = m.plant()
    import jax.numpy as jnp

    sig = dict(
        zip(p.signal_names, np.asarray(p.signals(jnp.asarray(x0), jnp.zeros(1))), strict=True)
    )
    assert sig["motor_angle"] == pytest.approx(0.3)
    assert sig["tip_deflection"] == pytest.approx(0.01, rel=1e-12)
    # the static shape under a tip force: the internal forces K w act at the tip only
    # (M⁻¹K w from the block, w = y − x̄ θm); released, the link then rings
    n = m.beam.mass_dofs
    w = x0[2 : 2 + n] - m.beam.xbar * 0.3
    f = -m.beam.A[n:, :n] @ w
    tip = m.beam.tip_dof
    assert np.max(np.abs(np.delete(f, tip))) < 1e-9 * abs(f[tip])


def _short(scenario, seconds: float):
    """The scenario with its run cut to ``seconds`` (sampled loop or [regulation] law)."""
    upd = {}
    if scenario.simulation is not None and scenario.sampling is not None:
        upd["simulation"] = scenario.simulation.model_copy(update={"duration": seconds})
    if scenario.regulation is not None:
        upd["regulation"] = scenario.regulation.model_copy(update={"duration": seconds})
    return scenario.model_copy(update=upd)


@pytest.mark.parametrize("name", sorted(__import__("flexarm").builtin_scenarios()))
def test_every_builtin_scenario_runs_through_simulate(name):
    """flexarm.simulate runs every built-in scenario, the De Luca regulation ones (a
    continuous-time law, no [sampling]) too, and returns the one result type with finite
    traces over the (shortened) run."""
    import flexarm
    from flexarm.sim.result import SimulationResult

    sc = _short(flexarm.load_scenario(name), 0.05)
    res = flexarm.simulate(sc)
    assert isinstance(res, SimulationResult)
    step = float(res.time[1] - res.time[0])  # the run ends within one output period of 0.05 s
    assert 0.05 - step - 1e-12 <= res.time[-1] <= 0.05 + 1e-12
    assert np.all(np.isfinite(res.state_array))
