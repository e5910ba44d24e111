"""The drive's command as a measured channel of the sampled loop (issue #44 item 3):
``[sensors.current]`` records the controller's command after the saturation and the D/A,
``current_applied`` the drive's input with the command disturbances."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.sim.build import prepare, simulate
from flexarm.specs.scenario import ScenarioError, scenario_from_dict


def _scenario(sensors, **extra):
    return scenario_from_dict(
        {
            "name": "rigid-pd",
            "arm": {
                "motor": {
                    "drive": "voltage",
                    "inertia": 0.01,
                    "motor_constant": 0.05,
                    "armature_resistance": 2.0,
                    "voltage_limit": 5.0,
                },
                "friction": {"model": "none", "bias": -0.01},
                "beam": {"model": "rigid", "length": 0.3},
            },
            "sampling": {"period": 0.001, "delay": 1},
            "simulation": {"duration": 0.3},
            "sensors": sensors,
            "reference": {"type": "step", "amplitude": 0.5, "start": 0.05},
            "controller": {"type": "pd", "kp": 40.0, "kd": 1.0},
            "actuator": {"bits": 12},
            **extra,
        }
    )


def test_the_command_channel_records_the_command_at_each_sample():
    """With a computation delay of one sample, saturation at 5 V and a 12-bit D/A, the
    channel equals the result's applied command sample by sample (exactly), a gain of 2
    doubles it, and it saturates (the step asks for 20 V)."""
    sc = _scenario({"motor_angle": {}, "voltage": {}, "v2": {"signal": "voltage", "gain": 2.0}})
    res = simulate(sc)
    u = res.command[:, 0]
    assert np.array_equal(res.measured["voltage"], u)
    assert np.array_equal(res.measured["v2"], 2.0 * u)
    assert u.max() == pytest.approx(5.0 - 10 / 4096, abs=10 / 4096)  # at the limit, on the D/A
    q = 10.0 / 4096
    assert np.allclose(u / q, np.round(u / q), rtol=0, atol=1e-9)


def test_a_command_channel_reads_no_plant_signal():
    """A consumer that reads the channels as plant signals (gain·signal[index], e.g. a
    start-state estimate from a log's first sample) sees gain 0 on a command channel; the
    channel's own gain is kept apart."""
    loop = prepare(_scenario({"motor_angle": {}, "voltage": {"gain": 3.0}})).loop
    s = loop.sensors
    c = s.names.index("voltage")
    assert s.commands == (c,) and float(s.gain[c]) == 0.0
    assert float(s.command_gain[0]) == 3.0
    assert float(s.gain[s.names.index("motor_angle")]) == 1.0


def test_a_command_channel_takes_no_filter_delay_or_zeroing():
    with pytest.raises(ValueError, match="has no delay: set delay = 0"):
        prepare(_scenario({"motor_angle": {}, "voltage": {"delay": 2}}))
    with pytest.raises(ScenarioError, match="unknown sensor channel 'torque'"):
        _scenario({"torque": {}})
