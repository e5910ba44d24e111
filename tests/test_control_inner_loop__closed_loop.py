"""InnerLoopDesign.closed_loop at a long loop delay (issue #46): the transfer function the
nested design simulates and tunes G_cb on is the loop itself.

The compensators are those the inner-loop search found for the rotary rig with 60 samples
of hub-sensor delay. ``control.minreal`` of the closed loop (order 64) rebuilt its
polynomials from their roots and put poles at |z| = 1.03 (at 86 samples 1.45): the move
sizing's profile diverged and the sizing halved A for ever. The loop's own poles (the
state-space feedback of the three blocks, an independent computation) are within 0.987
(0.994).
"""

from __future__ import annotations

import control
import numpy as np
import pytest

from flexarm.control.inner_loop import InnerLoopDesign, _plant_tf, motor_design_model
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs import load_scenario

DT = 1e-3  # s
# G_cm1 = (5.091 z − 0.2098)/(z − 0.04121) V/rad, G_cm2 = (7.225 z − 7.060)/(z − 0.8349)
GCM1 = control.tf([5.091362212104609, -0.20981721575112608], [1.0, -0.041210445443579394], DT)
GCM2 = control.tf([7.224998559733983, -7.0599341736834305], [1.0, -0.8349356139494475], DT)


def _design(delay: int) -> InnerLoopDesign:
    """The design's compensators; the search's figures play no part in closed_loop."""
    z = np.zeros(1)
    return InnerLoopDesign(
        GCM1, GCM2, DT, delay, 5.0, 0.3, 0.02, 0.0, 0.1, 1.0, 5.0, 10.0, 0.0, 0.0, z, z, z, z
    )


def _state_space_loop(model, delay: int):
    """θm/θ_mr as the state-space feedback of G_cm1, the ZOH motor model with the delay,
    and G_cm2 (no polynomial of the loop formed)."""
    j, v, k = motor_design_model(model)
    plant = control.sample_system(control.tf([k], [j, v, 0.0]), DT, method="zoh")
    shift = control.ss(control.tf([1.0], [1.0] + [0.0] * delay, DT))
    return control.feedback(control.ss(GCM1) * control.ss(plant) * shift, control.ss(GCM2))


@pytest.mark.parametrize("delay", [2, 60, 86])
def test_closed_loop_is_the_loop(delay):
    model = SingleLinkModel.from_spec(load_scenario("rotary-flexible-link").arm)
    g = _design(delay).closed_loop(model)
    ref = _state_space_loop(model, delay)
    radius = float(np.max(np.abs(np.linalg.eigvals(ref.A))))
    assert radius < 0.999  # the designed loop is stable
    den = np.trim_zeros(np.asarray(g.den[0][0], float), "f")
    assert float(np.max(np.abs(np.roots(den)))) == pytest.approx(radius, abs=1e-6)
    t = np.arange(0.0, 3.0, DT)
    u = np.minimum(t, 1.0)
    y_ref = control.forced_response(ref, t, u).outputs
    y = control.forced_response(g, t, u).outputs
    # both are the same loop: rounding of two realisations (measured ~1e-11)
    assert np.max(np.abs(y - y_ref)) < 1e-9 * np.max(np.abs(y_ref))


def test_short_delay_keeps_the_reduced_loop():
    """Where minreal is sound (2 samples) the result is minreal's, as before #46."""
    model = SingleLinkModel.from_spec(load_scenario("rotary-flexible-link").arm)
    d = _design(2)
    plant = _plant_tf(model, DT, 2)
    before = control.minreal(control.feedback(GCM1 * plant, GCM2), tol=1e-9, verbose=False)
    g = d.closed_loop(model)
    np.testing.assert_array_equal(g.den[0][0], before.den[0][0])
    np.testing.assert_array_equal(g.num[0][0], before.num[0][0])
