"""Reference arrays given to :func:`flexarm.sim.build.simulate` whose length does not match
``[simulation] duration`` (issue #44 item 8)."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.sim.build import ReferenceLengthError, simulate
from flexarm.specs.scenario import scenario_from_dict


def _scenario(duration):
    return scenario_from_dict(
        {
            "name": "rigid",
            "arm": {
                "motor": {
                    "drive": "current",
                    "inertia": 0.01,
                    "torque_constant": 0.5,
                    "current_limit": 10.0,
                },
                "friction": {"model": "none"},
                "beam": {"model": "rigid", "length": 0.3},
            },
            "sampling": {"period": 0.001},
            "simulation": {"duration": duration},
            "controller": {"type": "pd", "kp": 5.0, "kd": 0.2},
        }
    )


@pytest.mark.parametrize("extra", [-1, 0, 1])
def test_a_reference_within_one_sample_of_the_duration_sets_the_run(extra):
    """24.84 s at 1 ms is 24,841 samples; arrays of 24,840 .. 24,842 run as given (a
    duration rounded to the period), every sample simulated."""
    n = 24_841 + extra
    ref = np.full(n, 0.2)
    res = simulate(_scenario(24.84), references={"reference": ref})
    assert len(res.time) == n
    assert res.time[-1] == pytest.approx((n - 1) * 0.001, rel=1e-12)
    assert res.signals["motor_angle"][-1] == pytest.approx(0.2, abs=1e-6)


def test_a_reference_of_another_length_is_one_line():
    with pytest.raises(ReferenceLengthError) as e:
        simulate(_scenario(24.84), references={"reference": np.zeros(20_000)})
    msg = str(e.value)
    assert "\n" not in msg
    assert "'reference' has 20000 samples" in msg and "24841" in msg
    assert "duration = 19.999 s" in msg  # the fix: the duration that makes 20,000
    assert isinstance(e.value, ValueError)
