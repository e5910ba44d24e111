"""Issue #44 item 8: a rate computed from a zeroed gauge. Zeroing subtracts a constant,
which a rate does not see, so a rate channel need not share the zeroing of the logged
channel it is computed from (:func:`flexarm.sim.filters.computed_channels`)."""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from flexarm.control import discrete
from flexarm.io.logs import Log
from flexarm.models.plant import Plant
from flexarm.sim.filters import computed_channels
from flexarm.sim.sampled import Actuator, SampledLoop, Sensors, simulate_loop
from flexarm.specs.experiment import Sensor

DT = 2e-3
W = 2 * np.pi * 3.0


class Osc(Plant):
    """s'' = −(2π·3 Hz)² s about an offset of 0.5 (a gauge that does not read 0 at rest)."""

    def rhs(self, x, u):
        return jnp.stack([x[1], -W * W * x[0]])

    def signals(self, x, u):
        return x[:1] + 0.5


def _run(specs, n):
    plant = Osc(("p", "v"), ("s",), ("u",))
    sens = Sensors.make(plant, {k: v.model_dump() for k, v in specs.items()}, DT)
    ctrl = discrete.from_transfer_function(([0.0], [1.0]), DT, measured="s")
    loop = SampledLoop(
        plant, ctrl, sens, Actuator(jnp.asarray([1.0]), jnp.asarray([0.0])), jnp.asarray(DT), 20
    )
    out = simulate_loop(loop, np.array([0.2, 0.0]), {}, n)
    return dict(zip(loop.sensors.names, out["measured"].T, strict=True))


def test_a_rate_is_computed_from_a_zeroed_gauge_it_does_not_share_the_zeroing_with():
    """The log holds the zeroed low-pass gauge ``lp`` (zeroing 0.2 s) and the zeroed raw
    reading ``s``; the controller's rates ``lpr`` (the low-pass's rate state) and ``d`` (a
    40 Hz derivative) are not zeroed. Both are computed, and equal the simulator's
    unzeroed rates once the window and the filters' memory have passed: to 1e-9 of their
    range after 3.5 s (the 2 Hz low-pass, ζ = 0.9, forgets the window's end as
    exp(−ζω t) = 6e-17 by then; measured 3e-7 at 1.5 s, as exp(−ζω·1.3 s) = 4e-7 says;
    the derivative after ~30 ms); inside the window the zeroed channel reads 0, so there
    the computed rate is 0."""
    f2 = {"kind": "lowpass2", "cutoff": "2 Hz", "damping": 0.9}
    specs = {
        "s": Sensor(zeroing=0.2),
        "lp": Sensor(signal="s", filter=f2, zeroing=0.2),
        "lpr": Sensor(signal="s", filter={**f2, "kind": "lowpass2_rate"}),
        "d": Sensor(signal="s", filter={"kind": "derivative2", "cutoff": "40 Hz"}),
    }
    n = 2500
    meas = _run(specs, n)
    log = Log(Path("zeroed.csv"), np.arange(n) * DT, {"s": meas["s"], "lp": meas["lp"]})
    got, notes = computed_channels(specs, log, DT)
    assert set(got) == {"lpr", "d"}
    assert all("zeroing subtracts a constant" in x for x in notes), notes
    k = int(3.5 / DT)
    for name in ("lpr", "d"):
        scale = np.abs(meas[name]).max()
        assert scale > 1.0  # rad/s: the ringing angle's rate, ~0.2·2π·3
        err = np.abs(got[name][k:-1] - meas[name][k:-1]).max()
        assert err < 1e-9 * scale, (name, err)
    assert np.all(got["lpr"][: int(0.2 / DT) - 1] == 0.0)


def test_an_angle_channel_still_needs_the_same_zeroing():
    """A low-pass (not a rate) sees the constant: not computed from a channel zeroed
    otherwise."""
    f2 = {"kind": "lowpass2", "cutoff": "2 Hz", "damping": 0.9}
    specs = {"s": Sensor(zeroing=0.2), "lp": Sensor(signal="s", filter=f2)}
    log = Log(Path("z.csv"), np.arange(50) * DT, {"s": np.zeros(50)})
    got, _ = computed_channels(specs, log, DT)
    assert got == {}
