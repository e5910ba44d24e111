"""Logged disturbances in the sampled loop on an arm of several joints (issue #44 item 2):
a force on joint j is the command disturbance F / k_u,j on its drive (τ = k_u u + F)."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.sim.build import simulate
from flexarm.specs.scenario import ScenarioError, load_scenario, scenario_from_dict

KT2 = 0.87  # N m / A, the elbow's current drive (quanser-two-link.toml)


def _two_link(disturbances):
    sc = load_scenario("quanser-two-link")
    data = sc.model_dump(mode="json", exclude_none=True)
    data["simulation"]["duration"] = 1.0
    data["disturbances"] = disturbances
    return scenario_from_dict(data)


def test_a_force_on_the_elbow_equals_its_command_disturbance_over_k_u():
    """The lab's LQR on the two-link arm (stiction, filters, 2 ms) with a 0.4 N m push on
    the elbow over 0.2 s: the run equals the one with a 0.4 / K_t2 A pulse into the
    elbow's command, to 1e-9 rad (the same torque, through the drive's k_u: round-off
    only), and differs from the run without it by more than 1 mrad."""
    n = 501
    push = np.zeros(n)
    push[100:200] = 0.4
    forced = simulate(
        _two_link([{"name": "push", "into": "force", "joint": 2}]), references={"push": push}
    )
    pulsed = simulate(
        _two_link([{"name": "pulse", "into": "command", "joint": 2}]),
        references={"pulse": push / KT2},
    )
    none = simulate(_two_link([]))
    for s in ("theta_1", "theta_2"):
        assert np.abs(forced.signals[s] - pulsed.signals[s]).max() < 1e-9
    assert np.abs(forced.signals["theta_2"] - none.signals["theta_2"]).max() > 1e-3
    # the force is no command; the pulse is in the applied command of joint 2 only
    assert not np.array_equal(forced.command, none.command)  # the loop reacted
    assert np.allclose(pulsed.command[:, 1] - forced.command[:, 1], push / KT2, atol=1e-9)


def test_a_disturbance_on_an_arm_of_several_joints_names_its_joint():
    with pytest.raises(ScenarioError, match="say which with joint = 1..2"):
        _two_link([{"name": "push", "into": "force"}])
