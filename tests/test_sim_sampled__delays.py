"""The sensors' delays as data (issue #43: the delay search's compilations): each channel's
delay (whole samples) is an array of the loop, the reading buffer ``depth`` + 1 samples
long (:func:`flexarm.sim.sampled.with_depth`), so that loops that differ only in their
delays run one compiled program. Checked on the built-in rotary rig against the loop built
with the delays in its scenario (a channel read ``d`` samples late is the undelayed
channel shifted by ``d``: an analytic identity) and across buffer depths (bit for bit)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest


def _prep(delays: dict[str, int], extra: dict | None = None):
    from flexarm.sim.build import prepare
    from flexarm.specs.scenario import Scenario, load_scenario

    d = load_scenario("rotary-flexible-link").model_dump(exclude_none=True)
    d["simulation"]["duration"] = 0.6
    d["reference"]["period"] = 0.4  # steps of 0.5 rad at 0.2 s, 0.4 s, ...
    d["sensors"].update(extra or {})
    for name, k in delays.items():
        d["sensors"].setdefault(name, {})["delay"] = k
    return prepare(Scenario.model_validate(d))


def _run(loop, p):
    from flexarm.sim.sampled import simulate_loop

    return simulate_loop(loop, p.x0, p.references, p.n_samples)


def test_a_deeper_buffer_reads_the_same_bit_for_bit():
    """Delays 3 / 5 samples read from a buffer of 6 (their own) or of 41 samples: every
    measured channel, the command and the states identical to the bit."""
    from flexarm.sim.sampled import with_depth

    p = _prep({"motor_angle": 3, "tip_deflection": 5})
    assert p.loop.sensors.depth == 5
    a = _run(p.loop, p)
    b = _run(with_depth(p.loop, 40), p)
    for k in ("measured", "command", "states"):
        assert np.array_equal(a[k], b[k]), k
    with pytest.raises(ValueError, match="depth 4 below the largest delay, 5 samples"):
        with_depth(p.loop, 4)


def test_delays_set_as_data_equal_the_scenario_s_delays():
    """The loop built with no delays, its delays then set as data (buffer 41 deep), runs
    as the loop built with those delays in its scenario, bit for bit; and an extra channel
    the controller does not read, ``gauge`` (the tip, 7 samples late), is its undelayed
    twin ``gauge0`` shifted by 7 samples exactly (the first 7 hold the first reading)."""
    from flexarm.sim.sampled import with_depth

    extra = {"gauge": {"signal": "tip_deflection"}, "gauge0": {"signal": "tip_deflection"}}
    want = {"motor_angle": 3, "tip_deflection": 5, "gauge": 7}
    ref = _prep(want, extra)
    p0 = _prep({}, extra)
    names = p0.loop.sensors.names
    loop = with_depth(p0.loop, 40)
    delays = jnp.asarray([want.get(n, 0) for n in names], jnp.int32)
    loop = eqx.tree_at(lambda lp: lp.sensors.delays, loop, delays)
    a, b = _run(ref.loop, ref), _run(loop, p0)
    for k in ("measured", "command", "states"):
        assert np.array_equal(a[k], b[k]), k
    g, g0 = (b["measured"][:, names.index(n)] for n in ("gauge", "gauge0"))
    assert np.ptp(g0) > 1e-3  # the tip moves: a real check
    assert np.array_equal(g[7:], g0[:-7]) and np.all(g[:7] == g0[0])
