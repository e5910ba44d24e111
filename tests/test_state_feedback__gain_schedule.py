"""A state-feedback law whose gains change during the run (a logged gain schedule,
``[controller] gain_signals``): the law reads K1..K4 of each sample from input channels, as
the lab's logger records them (the 5/2 session's K4 0.2 -> 0.4 at 0.915 s)."""

from __future__ import annotations

import numpy as np
import pytest

import flexarm
from flexarm.control.state_feedback import from_spec, state_feedback
from flexarm.specs.controllers_bench import StateFeedbackController

NAMES = ("gain_K1", "gain_K2", "gain_K3", "gain_K4")


def test_scheduled_law_is_the_plain_law_with_each_samples_gains():
    """Sample by sample, the scheduled law's command equals the plain law's built with that
    sample's gains (the same arithmetic: to the last bit, 0 tolerance), over a schedule
    that switches K4 and K1 mid-run, on random measurements."""
    T = 1e-3
    spec = StateFeedbackController(
        type="state_feedback", k1=6, k2=-3, k3=0.213, k4=0.2, gain_signals=NAMES
    )
    sched = from_spec(spec, T)
    rng = np.random.default_rng(1)
    n = 40
    K = np.tile([6.0, -3.0, 0.213, 0.2], (n, 1))
    K[15:, 3] = 0.4
    K[30:, 0] = 7.5
    th, d, r = rng.normal(size=(3, n))
    s = sched.init()
    states = {}
    for k in range(n):
        plain = state_feedback(*K[k], T)
        s_plain = states.get("plain", plain.init())
        ref = {"reference": r[k], **{nm: K[k, i] for i, nm in enumerate(NAMES)}}
        meas = {"motor_angle": th[k], "tip_deflection": d[k]}
        s, u = sched.step(s, meas, ref)
        s_plain, u_plain = plain.step(s_plain, meas, {"reference": r[k]})
        states["plain"] = s_plain
        assert float(u[0]) == float(u_plain[0]), k


def test_a_schedule_without_arrays_runs_its_declared_gains():
    """Without arrays for the gain channels (a simulation, not a log), the scheduled law
    runs the declared k1..k4 throughout: the same run as the plain law, to 1e-12 rad."""
    sc = flexarm.load_scenario("rotary-flexible-link")
    d = sc.model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = 1.0
    plain = flexarm.specs.scenario_from_dict(d)
    ctrl = d.get("controller")
    if not ctrl or ctrl.get("type") != "state_feedback":
        d["controller"] = {"type": "state_feedback", "k1": 5.0, "k2": -2.0, "k3": 0.1, "k4": 0.1}
        plain = flexarm.specs.scenario_from_dict(d)
    d["controller"]["gain_signals"] = list(NAMES)
    sched = flexarm.specs.scenario_from_dict(d)
    a, b = flexarm.simulate(plain), flexarm.simulate(sched)
    np.testing.assert_allclose(b.outputs, a.outputs, rtol=0, atol=1e-12)
    with pytest.raises(ValueError):
        StateFeedbackController(type="state_feedback", k1=1, gain_signals=("a", "b"))
