"""Joint friction: real stiction (no creep below breakaway), motion above it."""

import numpy as np
import pytest

from _helpers import constant_command, scenario
from flexarm.sim.build import simulate

COUNT = 2 * np.pi / 4096  # one count of the 12-bit motor-angle sensor
K = 2.184 * 0.112984829027616  # N*m/A
FS = 0.288288 * 0.112984829027616  # N*m, breakaway


def run(model: str, current: float, tip_deflection: float = 0.0, **friction):
    sc = scenario(
        arm={"friction": {"model": model, "coulomb": "0.25 lbf*in", "static": FS, **friction}},
        simulation={"duration": "10 s", "substeps": 10},
        initial={"tip_deflection": tip_deflection},
    )
    return simulate(sc, controller=constant_command(current))


@pytest.mark.parametrize("model", ["coulomb", "stribeck"])
def test_stuck_joint_does_not_creep_while_link_rings(model):
    """Below breakaway (95 %), with the link ringing from a 0.5 mm tip deflection whose
    torque on the hub stays below the margin, the hub moves < 1 count in 10 s."""
    res = run(model, 0.95 * FS / K - 0.0, tip_deflection=0.0005)
    assert np.ptp(res["tip_deflection"]) > 5e-4  # the link does ring
    assert np.ptp(res["motor_angle"]) < COUNT
    assert np.ptp(res["motor_angle"]) == 0.0  # exactly held, not slow creep


@pytest.mark.parametrize("model", ["coulomb", "stribeck"])
def test_joint_breaks_away_above_the_level(model):
    res = run(model, 1.05 * FS / K)
    assert np.ptp(res["motor_angle"]) > 100 * COUNT


def test_lugre_presliding_is_small_and_breakaway_moves():
    below = run("lugre", 0.9 * FS / K, stiffness=1e3, damping=1.0)
    # presliding: the bristles deflect by about F/σ0 = 3e-5 rad, far below a count
    assert np.ptp(below["motor_angle"]) < COUNT
    above = run("lugre", 1.3 * FS / K, stiffness=1e3, damping=1.0)
    assert np.ptp(above["motor_angle"]) > 100 * COUNT
