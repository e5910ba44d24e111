"""The cheap estimates before the closed-loop fit
(:mod:`flexarm.identification.time_domain.estimates`)."""

import numpy as np
import pytest
import scipy.signal

from flexarm.identification.time_domain import estimates
from flexarm.io.logs import Log


def test_tip_model_recovers_a_simulated_link():
    """A hub → tip record simulated from the model (1) itself (ω_c 11.3 rad/s, ζ 0.04,
    gain −0.7, tip lag 40 samples, low-pass 8 Hz, no noise) is found back: the lag exactly
    (the coarse 5-sample grid is refined to single samples around its best), ω_c, ζ and the
    gain to 1 % (the model is exact; what is left is the optimiser's stopping tolerance),
    fit above 99 %."""
    dt, L = 1e-3, 0.45
    t = np.arange(6000) * dt
    rng = np.random.default_rng(3)
    # a staircase hub angle through a first-order lag: rich enough to ring the link
    steps = np.repeat(rng.uniform(-0.3, 0.3, 12), 500)
    th = scipy.signal.lfilter([1 - np.exp(-dt * 15)], [1, -np.exp(-dt * 15)], steps)
    true = (11.3, 0.04, -0.7 * L, 8.0)
    d = estimates._tip_response(true, th, 40, dt)
    log = Log(path=None, time=t, signals={"motor_angle": th, "tip_deflection": d})
    m = estimates.tip_model([log], L, max_lag=45)
    assert m is not None
    assert m.lag == 40
    assert m.omega_c == pytest.approx(11.3, rel=0.01)
    assert m.zeta == pytest.approx(0.04, rel=0.01)
    assert m.gain == pytest.approx(-0.7, rel=0.01)
    assert m.fit_percent > 99
