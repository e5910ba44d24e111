"""Issue #47 item 1: channels with a zero offset (``[sensors.X] offset``) read off a log. A
digitally filtered channel computed from a logged unfiltered reading of another offset
(:func:`flexarm.sim.filters.computed_channels`), and a rate channel's low-pass state taken
from a logged sibling or reading of another offset
(:func:`flexarm.sim.filters.filter_state_from_log`), carry the channel's own offset: they
equal the simulator's sensor stage, which adds each channel's offset before its filter."""

from __future__ import annotations

from pathlib import Path

import numpy as np

DT = 2e-3
N = 1500
F2 = {"kind": "lowpass2", "cutoff": "2 Hz", "damping": 0.9}


def _simulate(specs: dict) -> dict[str, np.ndarray]:
    """The channels ``specs`` on a signal that rings, s'' = −(2π·3 Hz)² s, s(0) = 0.2, for
    N samples of DT."""
    import jax.numpy as jnp

    from flexarm.control import discrete
    from flexarm.models.plant import Plant
    from flexarm.sim.sampled import Actuator, SampledLoop, Sensors, simulate_loop

    w = 2 * np.pi * 3.0

    class Osc(Plant):
        def rhs(self, x, u):
            return jnp.stack([x[1], -w * w * x[0]])

        def signals(self, x, u):
            return x[:1]

    plant = Osc(("p", "v"), ("s",), ("u",))
    sens = Sensors.make(plant, {k: v.model_dump() for k, v in specs.items()}, DT)
    ctrl = discrete.from_transfer_function(([0.0], [1.0]), DT, measured="s")
    loop = SampledLoop(
        plant, ctrl, sens, Actuator(jnp.asarray([1.0]), jnp.asarray([0.0])), jnp.asarray(DT), 20
    )
    out = simulate_loop(loop, np.array([0.2, 0.0]), {}, N)
    return dict(zip(loop.sensors.names, out["measured"].T, strict=True))


def test_computed_channel_carries_its_own_offset():
    """A lowpass2 channel (gain 1, offset −0.05) computed from the logged reading of the same
    signal with gain 2 and offset 0.3: F run on (g_c / g_r)(r − o_r) + o_c equals the
    simulated channel to 1e-10 of its range (the same recursion, jit against numpy, as
    tests/test_sim_filters__computed_inputs.py); ignoring the offsets would leave
    o_c − o_r g_c / g_r = −0.2 between them."""
    from flexarm.io.logs import Log
    from flexarm.sim.filters import computed_channels
    from flexarm.specs.experiment import Sensor

    specs = {
        "s": Sensor(gain=2.0, offset=0.3),
        "lp": Sensor(signal="s", offset=-0.05, filter=F2),
    }
    meas = _simulate(specs)
    log = Log(Path("osc.csv"), np.arange(N) * DT, {"s": meas["s"]})
    got, notes = computed_channels(specs, log, DT)
    assert list(got) == ["lp"] and len(notes) == 1
    scale = np.abs(meas["lp"]).max()
    assert scale > 0.1
    np.testing.assert_allclose(got["lp"], meas["lp"], rtol=0, atol=1e-10 * scale)


def test_filter_state_off_a_log_carries_the_channels_offset():
    """The low-pass state ξ₁ of a lowpass2_rate channel with offset 0.1 at sample k = 1300
    (past the 2 Hz filter's memory, ~1190 samples to 1e-12): from the logged unfiltered
    reading (offset −0.2) and from a logged lowpass2 sibling (offset 0.7) it equals the
    output of a lowpass2 channel of the channel's own offset (not in the log; 1e-10 of the
    range), and its rate state ξ₂ is the logged rate."""
    from flexarm.io.logs import Log
    from flexarm.sim.filters import filter_state_from_log
    from flexarm.specs.experiment import Sensor

    k = 1300
    rate = {**F2, "kind": "lowpass2_rate"}
    specs = {
        "s": Sensor(offset=-0.2),
        "sib": Sensor(signal="s", offset=0.7, filter=F2),
        "own": Sensor(signal="s", offset=0.1, filter=F2),
        "r": Sensor(signal="s", offset=0.1, filter=rate),
    }
    meas = _simulate(specs)
    t = np.arange(N) * DT
    scale = np.abs(meas["own"]).max()
    for logged in (("s", "r"), ("sib", "r")):
        log = Log(Path("osc.csv"), t, {n: meas[n] for n in logged})
        x = filter_state_from_log(specs, log, k, DT)["r"]
        np.testing.assert_allclose(x[0], meas["own"][k], rtol=0, atol=1e-10 * scale)
        assert x[1] == meas["r"][k]
    assert abs(meas["sib"][k] - meas["own"][k] - 0.6) < 1e-12  # the offsets do differ
