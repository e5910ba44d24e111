"""control.response: the response of a fixed SISO system from rest equals what
``control.forced_response`` gives (python-control's own per-sample loop, an independent
computation), for the systems the nested design simulates: the closed inner loop, a
discrete transfer function whose order grows with the loop delay (0, 3, 40 samples), and
the continuous link model G_b and a feedforward's proper part on a grid 30 times finer.

Tolerance 1e-9 of the response's peak: both sides run the same recursion in another order
(lfilter's direct form of the same coefficients; block sums of the same state-space
powers), so they differ by rounding amplified by the loop's slow poles (measured ~1e-12 at
most); a wrong discretisation or an off-by-one sample is off by 1e-3 or more.
"""

from __future__ import annotations

import control
import numpy as np
import pytest

from flexarm.control.inner_loop import motor_design_model
from flexarm.control.response import linear_response, response_function
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs import load_scenario

DT = 1e-3  # s


def _rel(y, ref) -> float:
    return float(np.max(np.abs(np.asarray(y) - np.asarray(ref))) / np.max(np.abs(ref)))


def _closed_inner_loop(delay: int) -> control.TransferFunction:
    """θm/θ_mr of a P loop on the rotary rig's motor model (ZOH, ``delay`` samples): a
    discrete transfer function of order 2 + delay, stable (gain lowered with the delay)."""
    model = SingleLinkModel.from_spec(load_scenario("rotary-flexible-link").arm)
    j, v, k = motor_design_model(model)
    plant = control.sample_system(control.tf([k], [j, v, 0.0]), DT, method="zoh")
    plant = plant * control.tf([1.0], [1.0] + [0.0] * delay, DT)
    gain = {0: 0.6, 3: 0.3, 40: 0.02}[delay]
    return control.feedback(gain * plant, 1)


@pytest.mark.parametrize("delay", [0, 3, 40])
def test_discrete_loop_matches_forced_response(delay):
    g = _closed_inner_loop(delay)
    assert np.max(np.abs(g.poles())) < 1.0  # the loop is stable: a bounded response
    assert len(g.den[0][0]) - 1 == 2 + delay
    t = np.arange(0.0, 4.0, DT)
    u = np.minimum(t, 1.0) + 0.2 * np.sin(7.0 * t)
    ref = control.forced_response(g, t, u).outputs
    assert _rel(linear_response(g, t, u), ref) < 1e-9
    # the same system as state space (the block recursion instead of lfilter)
    assert _rel(linear_response(control.ss(g), t, u), ref) < 1e-9


@pytest.mark.parametrize("name", ["rotary-flexible-link", "feliu-single-mass", "feliu-two-mass"])
def test_continuous_link_model_matches_forced_response(name):
    """G_b = θt/θm of each built-in single link (order 2 or 4) on the 1 kHz grid and on the
    30-times finer grid of the feedforward, driven from a non-zero first sample (the
    first-order hold's start)."""
    gb = SingleLinkModel.from_spec(load_scenario(name).arm).beam_tf()
    for step in (DT, DT / 30):
        t = np.arange(0.0, 2.5, step)
        u = 0.1 + np.sin(3.0 * t) ** 2 * (t < 2.0) + 0.1 * t
        ref = control.forced_response(gb, t, u).outputs
        assert _rel(linear_response(gb, t, u), ref) < 1e-9


def test_response_function_is_reused_across_inputs():
    """One conversion, several inputs of different lengths: each equals its own
    forced_response (the conversion holds nothing of an input)."""
    g = _closed_inner_loop(3)
    run = response_function(g, DT)
    for n in (5, 1000, 2501):
        t = np.arange(n) * DT
        u = np.cos(0.01 * np.arange(n))
        assert _rel(run(u), control.forced_response(g, t, u).outputs) < 1e-9


def test_bad_input_is_named():
    g = _closed_inner_loop(0)
    with pytest.raises(ValueError, match="differs from the system's period"):
        response_function(g, 2 * DT)
    with pytest.raises(ValueError, match="uniformly spaced"):
        linear_response(g, np.array([0.0, 0.001, 0.003]), np.ones(3))
    with pytest.raises(ValueError, match="one value per time"):
        linear_response(g, np.arange(3) * DT, np.ones(4))
    mimo = control.ss(np.eye(2) * -1.0, np.eye(2), np.eye(2), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="give a SISO system"):
        response_function(mimo, DT)
