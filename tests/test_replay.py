"""Replay of a log on a scenario (analysis/replay.py): ``flexarm simulate SCENARIO --log``."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.analysis.replay import replay
from flexarm.io.logs import Log
from flexarm.sim.build import simulate
from flexarm.specs.scenario import scenario_from_dict


def _scenario(**extra):
    return scenario_from_dict(
        {
            "name": "rigid-pd",
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
            "simulation": {"duration": 0.5},
            "sensors": {"motor_angle": {}, "current": {}},
            "reference": {"type": "step", "amplitude": 0.5, "start": 0.05},
            "controller": {"type": "pd", "kp": 5.0, "kd": 0.2},
            **extra,
        }
    )


@pytest.mark.filterwarnings("ignore::flexarm.sim.filters.ControllerStateWarning")
def test_a_single_link_log_replays_on_its_scenario():
    """Issue #44: ``simulate --log`` refused every single-link scenario. A log simulated
    from the scenario (started at 0.1 rad, a pulse of 2 A after the saturation) replays at
    100 % (fit % to 1e-6: the same loop, the initial angle read off the log, the logged
    reference and the pulse column as inputs) and the command channel is compared too."""
    sc = _scenario(
        initial={"motor_angle": 0.1}, disturbances=[{"name": "pulse", "into": "command"}]
    )
    pulse = np.zeros(501)
    pulse[200:220] = 2.0
    res = simulate(sc, references={"pulse": pulse})
    log = Log(
        None,
        res.time,
        {
            "reference": res.references["reference"],
            "motor_angle": res.measured["motor_angle"],
            "current": res.measured["current"],
            "pulse": pulse,
        },
        disturbances=("pulse",),
    )
    # the scenario run on the log: its own [initial] is 0, the log says 0.1 rad
    rep = replay(_scenario(disturbances=[{"name": "pulse", "into": "command"}]), log)
    assert set(rep.fit_percent) == {"motor_angle", "current"}
    for v in rep.fit_percent.values():
        assert v == pytest.approx(100.0, abs=1e-6)
    # without the pulse the replay is worse: the log's motion is not the scenario's
    log.signals["pulse"] = np.zeros(501)
    worse = replay(_scenario(disturbances=[{"name": "pulse", "into": "command"}]), log)
    assert worse.fit_percent["motor_angle"] < 99.0


@pytest.mark.filterwarnings("ignore::flexarm.sim.filters.ControllerStateWarning")
def test_a_log_whose_clock_drifts_16_ppm_replays_on_the_scenarios_grid():
    """Issue #44 item 5: the log's stamps run 16 ppm slow (the public benchmark's first
    file): replayed on the scenario's grid at 100 % with a note saying so; at 250 ppm the
    replay is refused in one line naming the figure and the option."""
    from flexarm.io.logs import ClockError

    sc = _scenario()
    res = simulate(sc)
    sig = {
        "reference": res.references["reference"],
        "motor_angle": res.measured["motor_angle"],
    }
    drift = Log(None, res.time * (1 + 16e-6), sig)
    rep = replay(sc, drift)
    assert rep.fit_percent["motor_angle"] == pytest.approx(100.0, abs=1e-6)
    assert any("16 ppm off" in n for n in rep.notes)
    with pytest.raises(ClockError, match="250 ppm.*period_tolerance = 0.0001"):
        replay(sc, Log(None, res.time * (1 + 250e-6), sig))
    assert replay(sc, Log(None, res.time * (1 + 250e-6), sig), period_tolerance=3e-4).notes
