"""Issue #47 item 1 (a sensor's zero per session), #44 (signed parameters): a channel's
constant zero offset, ``[sensors.X] offset``, y = gain·x + offset, added after the analog
low-pass and before the noise, the A/D, the delay, the logger's zeroing and the digital
filter. Checked on the built-in rotary rig (a channel the controller does not read, a
channel it reads against the analytic equivalent reference shift, zeroing, a stacked batch),
the scenario TOML round trip, the bad input, and the filters' states and computed channels
read off a log whose channels carry offsets."""

from __future__ import annotations

import math

import numpy as np
import pytest

C = 0.0123  # m: a strain gauge's zero offset (the rig's tip deflection peaks near 0.01 m)


def _rig(duration: float = 0.5, **sensors) -> dict:
    """The built-in rotary rig as a dict, ``duration`` s, with extra channels; its square
    reference of period 0.4 s (steps of 0.5 rad at 0.2 s, 0.4 s, ...)."""
    from flexarm.specs.scenario import load_scenario

    d = load_scenario("rotary-flexible-link").model_dump(exclude_none=True)
    d["simulation"]["duration"] = duration
    d["reference"]["period"] = 0.4
    d["sensors"].update(sensors)
    return d


def _run(d: dict):
    from flexarm.sim.build import simulate
    from flexarm.specs.scenario import Scenario

    return simulate(Scenario.model_validate(d))


def test_offset_on_an_unread_channel_is_added_exactly():
    """A gauge channel the state feedback does not read (its own name; no quantisation,
    2 samples of delay, a 50 Hz analog low-pass on a second one) reads the offset-free run's
    values + c from the first sample on (3e-17: one rounding of g·x + c, |y| < 0.03 m); every
    other channel, the command and the states are bit-identical (the loop does not see it)."""
    extra = {
        "gauge": {"signal": "tip_deflection", "delay": 2},
        "gauge_f": {"signal": "tip_deflection", "bandwidth": "50 Hz"},
    }
    base = _run(_rig(**extra))
    extra["gauge"]["offset"] = C
    extra["gauge_f"]["offset"] = -4.5e-3  # signed
    off = _run(_rig(**extra))
    for name, c in (("gauge", C), ("gauge_f", -4.5e-3)):
        d = off.measured[name] - base.measured[name]
        np.testing.assert_allclose(d, c, rtol=0, atol=3e-17 + 1e-15 * abs(c))
    assert np.ptp(base.measured["gauge_f"]) > 1e-3  # the filtered channel moves: a real check
    for name in ("motor_angle", "tip_deflection"):
        assert np.array_equal(off.measured[name], base.measured[name])
    assert np.array_equal(off.command, base.command)
    assert np.array_equal(off.states, base.states)


def test_offset_on_a_read_channel_is_a_reference_shift():
    """The hub encoder's offset c on the channel the state feedback reads (u = k1 (r − θ_m)
    − k2 d − k3 Δθ_m / T, the rate a backward difference) acts on the loop exactly as the
    reference lowered by c: the states and command of the run with offset c and reference r
    equal those of the run with offset 0 and reference r − c to 1e-12 (one rounding of
    r − (θ + c) against (r − c) − θ per sample; measured 3e-15 rad, 9e-15 V over 2 s with
    stick-slip friction), and the hub channel reads θ + c. The encoder's 12 bits are set to
    0 (quantisation is not shift-invariant)."""
    c = math.radians(2.0)
    d1 = _rig(2.0)
    d1["sensors"]["motor_angle"] = {"offset": c}
    d2 = _rig(2.0)
    d2["sensors"]["motor_angle"] = {}
    d2["reference"]["offset"] = d1["reference"]["offset"] - c
    a, b = _run(d1), _run(d2)
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.command, b.command, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        a.measured["motor_angle"], b.measured["motor_angle"] + c, rtol=0, atol=1e-12
    )
    # and the offset moved the arm: the hub settles c below the offset-free run's
    free = _run(_rig(2.0, motor_angle={}))
    assert abs(a.signals["motor_angle"][-1] - free.signals["motor_angle"][-1]) > 0.5 * c


def test_zeroing_removes_the_offset():
    """A gauge zeroed over its first 0.1 s (the logger's tare): with offset c it reads what
    it reads without (< 1e-14 m: the window's mean carries c, subtracted after it; measured
    1.4e-17 on readings up to 0.08 m), 0 in the window."""
    z = {"signal": "tip_deflection", "zeroing": "0.1 s", "noise": 1e-5}
    base = _run(_rig(zeroed=dict(z)))
    off = _run(_rig(zeroed=dict(z, offset=C)))
    diff = off.measured["zeroed"] - base.measured["zeroed"]
    assert np.max(np.abs(diff)) < 1e-14
    assert np.all(off.measured["zeroed"][:100] == 0.0)  # 0.1 s at 1 kHz
    assert np.ptp(off.measured["zeroed"]) > 1e-3  # the arm moves after the window


def test_zeroing_start_holds_the_offsets_part():
    """A segment started at sample k (a fit's shooting segment) starts the zeroing stage with
    the window's sum offset · min(k, n): after the window its reading has the offset
    removed (y − Σ/n = gain·s), inside it the offsets read so far; at k = 0 the sum is 0."""
    import jax.numpy as jnp

    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Sensors, logged_offset, zeroing_start

    class One(Plant):
        def rhs(self, x, u):
            return jnp.zeros(1)

        def signals(self, x, u):
            return x[:1]

    plant = One(("p",), ("s",), ("u",))
    sens = Sensors.make(
        plant,
        {"z": {"signal": "s", "offset": 0.5, "zeroing": 0.01}, "r": {"signal": "s", "offset": 2}},
        1e-3,
    )
    assert sens.zero_n == (10,)
    for k, want in ((0, 0.0), (4, 2.0), (10, 5.0), (250, 5.0)):
        kk, acc = zeroing_start(sens, k)
        assert int(kk) == k and float(acc[0]) == pytest.approx(want, abs=1e-15)
    np.testing.assert_array_equal(np.asarray(logged_offset(sens)), [0.0, 2.0])


def test_stacked_loops_each_keep_their_offset():
    """Two prepared rigs with gauge offsets +c and −2c stacked (sim.batch.stack_loops) and run
    as one vmapped batch: each rollout's gauge equals its own single run's (1e-12 m), so the
    offset is a traced, batched leaf like the gain."""
    from flexarm.sim.batch import stack_loops
    from flexarm.sim.build import prepare
    from flexarm.sim.sampled import simulate_batch
    from flexarm.specs.scenario import Scenario

    offs = (C, -2 * C)
    preps = [
        prepare(Scenario.model_validate(_rig(0.3, gauge={"signal": "tip_deflection", "offset": c})))
        for c in offs
    ]
    loop = stack_loops([p.loop for p in preps])
    p = preps[0]
    g = p.loop.sensors.names.index("gauge")
    np.testing.assert_array_equal(np.asarray(loop.sensors.offset)[:, g], offs)
    out = simulate_batch(loop, p.x0, p.references, p.n_samples)
    singles = [_run(_rig(0.3, gauge={"signal": "tip_deflection", "offset": c})) for c in offs]
    for i, s in enumerate(singles):
        got = out["measured"][i, :, g]
        np.testing.assert_allclose(got, s.measured["gauge"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        out["measured"][0, :, g] - out["measured"][1, :, g], 3 * C, rtol=0, atol=1e-15
    )


def test_offset_scenario_toml_round_trip(tmp_path):
    """``offset`` in a scenario TOML (signed; an angle with its unit, a gauge's in its SI
    unit, m) loads in SI, its default is 0, and the loaded scenario written back to TOML and
    loaded again keeps it."""
    import tomllib

    from flexarm.io.write import write_toml
    from flexarm.specs.scenario import builtin_scenarios, load_scenario

    text = builtin_scenarios()["rotary-flexible-link"].read_text()
    text = text.replace(
        "[sensors.motor_angle]", '[sensors.motor_angle]\noffset = "-0.5 deg"', 1
    ).replace("noise = 2e-5", "noise = 2e-5\noffset = 1.5e-3", 1)
    p = tmp_path / "rig.toml"
    p.write_text(text)
    s = load_scenario(p)
    assert s.sensors["motor_angle"].offset == pytest.approx(math.radians(-0.5), rel=1e-15)
    assert s.sensors["tip_deflection"].offset == pytest.approx(1.5e-3, rel=1e-15)
    assert load_scenario("rotary-flexible-link").sensors["tip_deflection"].offset == 0.0
    q = write_toml(tmp_path / "again.toml", s.model_dump(exclude_none=True))
    assert tomllib.loads(q.read_text())["sensors"]["tip_deflection"]["offset"] == 1.5e-3
    again = load_scenario(q)
    assert again.sensors["motor_angle"].offset == s.sensors["motor_angle"].offset
    assert again.sensors["tip_deflection"].offset == s.sensors["tip_deflection"].offset


def test_offset_bad_input_names_the_field(tmp_path):
    """A wrong unit (a mass) is one line naming sensors.<channel>.offset; a
    non-finite offset reaching the simulator is one line naming the channel and the fix."""
    import jax.numpy as jnp

    from flexarm.errors import FlexarmError
    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Sensors
    from flexarm.specs.scenario import builtin_scenarios, load_scenario

    text = builtin_scenarios()["rotary-flexible-link"].read_text()
    p = tmp_path / "bad.toml"
    p.write_text(text.replace("noise = 2e-5", 'noise = 2e-5\noffset = "3 kg"', 1))
    with pytest.raises(
        (FlexarmError, ValueError), match=r"sensors\.tip_deflection\.offset: '3 kg'"
    ):
        load_scenario(p)

    class One(Plant):
        def rhs(self, x, u):
            return jnp.zeros(1)

        def signals(self, x, u):
            return x[:1]

    with pytest.raises(ValueError, match=r"sensors\.g\.offset = nan: give the channel's zero"):
        Sensors.make(One(("p",), ("s",), ("u",)), {"g": {"signal": "s", "offset": float("nan")}})


def test_logged_offset_after_the_digital_filter():
    """What each channel's output carries of its offset: the offset on a plain channel, 0 on
    a zeroed one, the offset through a lowpass2 (DC gain 1, 1e-12) and 0 through a rate
    filter (derivative2, lowpass2_rate: DC gain 0); before the filter, the offset."""
    import jax.numpy as jnp

    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Sensors, logged_offset

    class One(Plant):
        def rhs(self, x, u):
            return jnp.zeros(1)

        def signals(self, x, u):
            return x[:1]

    f2 = {"kind": "lowpass2", "cutoff": 2.0, "damping": 0.9}
    chans = {
        "a": {"signal": "s", "offset": 0.25},
        "z": {"signal": "s", "offset": 0.25, "zeroing": 0.01},
        "lp": {"signal": "s", "offset": -0.5, "filter": f2},
        "lpr": {"signal": "s", "offset": -0.5, "filter": {**f2, "kind": "lowpass2_rate"}},
        "d": {"signal": "s", "offset": 0.75, "filter": {"kind": "derivative2", "cutoff": 40.0}},
    }
    sens = Sensors.make(One(("p",), ("s",), ("u",)), chans, 2e-3)
    np.testing.assert_array_equal(np.asarray(logged_offset(sens)), [0.25, 0, -0.5, -0.5, 0.75])
    after = np.asarray(logged_offset(sens, filtered=True))
    np.testing.assert_allclose(after, [0.25, 0.0, -0.5, 0.0, 0.0], rtol=0, atol=1e-12)


def test_replay_initial_state_subtracts_the_offsets():
    """analysis.replay reads the rig's start off a log's first sample: with offsets on the
    hub encoder (2°) and the gauge (1.5 mm) it subtracts them, and gives the state of the
    log without offsets (1e-15)."""
    from flexarm.analysis.replay import initial_state_from_log
    from flexarm.io.logs import Log
    from flexarm.sim.build import prepare
    from flexarm.specs.scenario import Scenario

    c_th, c_d = math.radians(2.0), 1.5e-3
    d = _rig()
    d["sensors"]["motor_angle"]["offset"] = c_th
    d["sensors"]["tip_deflection"]["offset"] = c_d
    p = prepare(Scenario.model_validate(d))
    p0 = prepare(Scenario.model_validate(_rig()))
    t = np.arange(3) * 1e-3
    th, w = np.array([0.3, 0.3, 0.3]), np.array([2e-3, 2e-3, 2e-3])
    log = Log(None, t, {"motor_angle": th + c_th, "tip_deflection": w + c_d})
    log0 = Log(None, t, {"motor_angle": th, "tip_deflection": w})
    x, x0 = initial_state_from_log(p, log), initial_state_from_log(p0, log0)
    assert abs(x0[0] - 0.3) < 1e-15  # the hub angle is read
    np.testing.assert_allclose(x, x0, rtol=0, atol=1e-15)
