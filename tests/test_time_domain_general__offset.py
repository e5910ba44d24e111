"""Issue #47 item 1: the general engine reads a segment's start state off a log whose
channels carry zero offsets (``[sensors.X] offset``): the offsets are subtracted before the
state is solved for and before the analog filters' states are set, so a scenario predicts
its own simulated log exactly."""

from __future__ import annotations

import math
import warnings
from pathlib import Path


def test_predict_from_a_log_with_offsets_is_exact():
    """The rotary rig with a 2° hub-encoder offset and a 1.5 mm gauge offset behind a 30 Hz
    analog low-pass, simulated for 1.5 s (square reference of period 0.8 s); the log is the
    run from sample 300 on (the arm moving), and predict with initial = "log" reads its
    start off the log's first sample: fit % >= 99.99 on both channels (measured 100.0; 92.6
    and 96.5 without subtracting the offsets)."""
    from flexarm.identification.time_domain.general import predict_scenario
    from flexarm.io.logs import Log
    from flexarm.sim.build import simulate
    from flexarm.specs.scenario import Scenario, load_scenario

    d = load_scenario("rotary-flexible-link").model_dump(exclude_none=True)
    d["simulation"]["duration"] = 1.5
    d["reference"]["period"] = 0.8
    d["sensors"]["motor_angle"] = {"offset": math.radians(2.0)}
    d["sensors"]["tip_deflection"] = {"offset": 1.5e-3, "bandwidth": 30.0}
    s = Scenario.model_validate(d)
    r = simulate(s)
    k0 = 300
    sig = {n: r.measured[n][k0:] for n in r.measured}
    sig["reference"] = r.references["reference"][k0:]
    log = Log(Path("sim.csv"), r.time[k0:] - r.time[k0], sig)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = predict_scenario(s, [log], initial="log")
    fit = out["fit_percent"]["sim.csv"]
    assert fit["motor_angle"] >= 99.99 and fit["tip_deflection"] >= 99.99, fit
