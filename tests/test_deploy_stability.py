"""deploy/stability.py: the nominal check of the sampled loop with its delays (issue #45),
the check every ``export-c`` runs.

Figures: the rotary rig's own state feedback (k1 = 6 V/rad) has max |z| = 0.99755 at 1 kHz;
with the hub feedback's sign flipped (k1 = -6) 1.00571 (a real pole outside the unit
circle: growth by e^(5.7 s^-1 t)); an LQR design's own closed-loop poles
(``design_linear``'s ``info["closed_loop_poles"]``, computed on its design model) are found
by the check to 1.7e-14.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.deploy.stability import nominal_check
from flexarm.specs import load_scenario
from flexarm.specs.scenario import Scenario


def _with_k1(k1: float) -> Scenario:
    sc = load_scenario("rotary-flexible-link")
    d = sc.model_dump(mode="json", exclude_none=True)
    d["controller"]["k1"] = k1
    return Scenario.model_validate(d)


def test_the_rigs_own_loop_is_stable_and_positive_hub_feedback_is_not():
    ok = nominal_check(load_scenario("rotary-flexible-link"))
    assert ok.stable and ok.verdict == "stable"
    assert ok.radius == pytest.approx(0.997547, abs=1e-5)
    bad = nominal_check(_with_k1(-6.0))
    assert not bad.stable
    assert bad.radius == pytest.approx(1.00571, abs=1e-4)
    assert bad.verdict.startswith("unstable on the nominal plant")
    assert "1.00571" in bad.verdict


def test_the_check_finds_an_lqr_designs_own_closed_loop_poles():
    """The design model (design/linear.py: the arm ZOH-sampled with its computation and
    sensor delays) and the check's loop are built independently; the designed loop's
    poles must be the check's, to round-off."""
    from flexarm.design import design

    des = design("rotary-flexible-link", "lqr")
    z = np.array([complex(re, im) for re, im in des.info["closed_loop_poles"]])
    nc = nominal_check(des.scenario)
    assert nc.stable
    assert nc.radius == pytest.approx(float(np.max(np.abs(z))), abs=1e-9)
    for p in z[np.abs(z) > 1e-3]:  # the check's extra registers add poles at 0 only
        assert np.min(np.abs(nc.poles - p)) < 1e-9


@pytest.mark.parametrize("name", ["quanser-two-link", "deluca-two-link-geared"])
def test_two_link_scenarios_with_digital_filters_and_joint_pd_are_checked_stable(name):
    nc = nominal_check(load_scenario(name))
    assert nc.stable, nc.verdict
    assert 0.99 < nc.radius <= 1.0 + 1e-6  # slow rigid modes: near, not outside, the circle
