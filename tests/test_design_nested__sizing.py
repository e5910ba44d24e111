"""The nested design's move sizing (design.nested._size_quasi_parabolic, issue #46) gives
the same move whether the loops are simulated by control.response (converted once, no
per-sample Python loop) or, as before, by ``control.forced_response`` on every trial.

The inner closed loop here is a P loop on the rotary rig's motor model with 0, 3 and 40
samples of delay (a discrete transfer function of order 2 + delay; the designed inner loop
costs minutes to search at long delays, and the sizing only needs a stable T_in).

Tolerances: each trial's peak deflection and command agree to 1e-9 relative (the profiles
do, tests/test_control_response.py), far from any trial's margin to its limits here
(> 1e-6), so the bisection takes the same steps and returns the same A: to 1e-12
relative (measured: bit for bit).
"""

from __future__ import annotations

import control
import numpy as np
import pytest

import flexarm.control.wiener as wiener
import flexarm.design.nested as nested
from flexarm.control.inner_loop import motor_design_model
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs import load_scenario

DT = 1e-3  # s
GAIN = {0: 20.0, 3: 10.0, 40: 3.0}  # V/rad: 17 %, 6 %, 0 % overshoot; settled in 0.25-0.45 s


@pytest.fixture(scope="module")
def rig():
    model = SingleLinkModel.from_spec(load_scenario("rotary-flexible-link").arm)
    return model, model.beam_tf()


def _inner(model, delay: int) -> control.TransferFunction:
    j, v, k = motor_design_model(model)
    plant = control.sample_system(control.tf([k], [j, v, 0.0]), DT, method="zoh")
    plant = plant * control.tf([1.0], [1.0] + [0.0] * delay, DT)
    return control.feedback(GAIN[delay] * plant, 1)


def _old_response(sys, t, u):
    """The simulation before issue #46: python-control's own loop, every call."""
    return np.asarray(control.forced_response(sys, t, u).outputs, float)


def _size(model, gb, delay):
    j, v, k_u = motor_design_model(model)
    trials = []
    profile = nested._move_profile

    def recorded(*a, **kw):
        out = profile(*a, **kw)
        trials.append(out)
        return out

    nested._move_profile = recorded
    try:
        tr, n, defl, u = nested._size_quasi_parabolic(
            model,
            gb,
            0.5,  # rad, the rig's move
            0.05,  # rad, design deflection
            5.0,  # V, half the limit
            float(np.real(control.dcgain(model.coupling_tf()))),
            float(model.friction.coulomb) / k_u,
            0.3,  # s, corner time
            _inner(model, delay),
            delay,
        )
    finally:
        nested._move_profile = profile
    return float(tr.max_acceleration), defl, u, np.array(trials)


@pytest.mark.parametrize("delay", [0, 3, 40])
def test_sizing_gives_the_same_move_as_forced_response(rig, delay, monkeypatch):
    model, gb = rig
    a_new, d_new, u_new, t_new = _size(model, gb, delay)
    monkeypatch.setattr(nested, "linear_response", _old_response)
    monkeypatch.setattr(wiener, "linear_response", _old_response)
    a_old, d_old, u_old, t_old = _size(model, gb, delay)
    assert t_new.shape == t_old.shape and t_new.shape[0] >= 3  # the same trials, several
    np.testing.assert_allclose(t_new, t_old, rtol=1e-9)
    assert a_new == pytest.approx(a_old, rel=1e-12)
    assert (d_new, u_new) == pytest.approx((d_old, u_old), rel=1e-9)
    assert d_new <= 0.05 and u_new <= 5.0  # the sized move meets both limits


def test_unstable_inner_loop_is_refused_at_once(rig):
    """An unstable T_in (the P loop at 40 samples with 10 times the gain: a pole at
    |z| > 1) fails every trial; the sizing says so in one line instead of halving A
    without end (each halving lengthens the move by 41 %)."""
    model, gb = rig
    j, v, k = motor_design_model(model)
    plant = control.sample_system(control.tf([k], [j, v, 0.0]), DT, method="zoh")
    t_inner = control.feedback(30.0 * plant * control.tf([1.0], [1.0] + [0.0] * 40, DT), 1)
    assert np.max(np.abs(np.roots(t_inner.den[0][0]))) > 1.0
    with pytest.raises(ValueError, match=r"T_in \(order 42\) has a pole at \|z\| = 1\.0"):
        nested._size_quasi_parabolic(model, gb, 0.5, 0.05, 5.0, 1.2, 0.2, 0.3, t_inner, 40)


@pytest.mark.slow  # about 3 min on two cores: the inner-loop search at 80 samples
def test_long_delay_rig_is_designed():
    """The rotary rig with 80 samples of delay on every sensor (the fitted unit 7 rig has
    86): before issue #46 the closed inner loop came out unstable, every sizing trial
    diverged and A was halved for ever (20 min in, still at A = 2.6e-7 rad/s²). Now the
    move is sized through the stable loop: finite, within the design deflection."""
    sc = load_scenario("rotary-flexible-link")
    sensors = {k: s.model_copy(update={"delay": 80}) for k, s in sc.sensors.items()}
    des = nested.design_nested(sc.model_copy(update={"sensors": sensors}))
    tr = des.info["trajectory"]
    assert 0.1 < tr["acceleration"] < 17.0  # rad/s²: below the 2-sample rig's 17.1
    assert tr["loop_peak_deflection_rad"] <= 0.05 * (1 + 1e-9)  # the design deflection
    assert tr["loop_peak_command"] <= 5.0  # half the 10 V limit
