"""The cheap estimates before the closed-loop fit
(:mod:`flexarm.identification.time_domain.estimates`)."""

import numpy as np
import pytest
import scipy.signal

from flexarm.identification.time_domain import estimates


def _reference(p, dt):
    """scipy's general ZOH route (state space, matrix exponential) for the model (1)."""
    wc, z, gL, fc = p
    a = 2 * np.pi * fc
    b, den, _ = scipy.signal.cont2discrete(
        ([-gL * a, 0.0, 0.0], np.polymul([1.0, 2 * z * wc, wc * wc], [1.0, a])), dt, method="zoh"
    )
    return np.ravel(b), den


@pytest.mark.parametrize("dt", [1e-3, 2e-3, 1e-2])
def test_tip_filter_closed_form_equals_scipy_zoh(dt):
    """The closed-form step-invariant transform of the hub → tip model equals scipy's
    cont2discrete over the search box of ``tip_model`` (ω_c 2-60 rad/s, ζ 0-0.7, f_c
    0.3 Hz to Nyquist): both are exact ZOH, so they differ by rounding only; 1e-9 of the
    largest coefficient is far above double rounding through exp and the partial fractions
    (their worst over these draws is about 1e-11) and far below the 1e-3 that a wrong
    residue or pole would give."""
    rng = np.random.default_rng(1)
    for _ in range(100):
        p = (
            rng.uniform(2, 60),
            rng.uniform(0, 0.7),
            rng.uniform(-1, 1),
            rng.uniform(0.3, 0.45 / dt),
        )
        b, a = estimates._tip_filter(p, dt)
        b0, a0 = _reference(p, dt)
        assert np.max(np.abs(b - b0)) <= 1e-9 * np.max(np.abs(b0)), p
        assert np.max(np.abs(a - a0)) <= 1e-9, p


def test_tip_filter_near_repeated_poles_takes_the_general_route():
    """ζ near 1 (a double pole) falls back to scipy's route, which stays exact there."""
    p = (10.0, 0.995, 0.3, 5.0)
    b, a = estimates._tip_filter(p, 1e-3)
    b0, a0 = _reference(p, 1e-3)
    np.testing.assert_allclose(b, b0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a, a0, rtol=0, atol=1e-12)


def test_tip_model_recovers_a_simulated_link():
    """A hub → tip record simulated from the model (1) itself (ω_c 11.3 rad/s, ζ 0.04,
    gain −0.7, tip lag 40 samples, low-pass 8 Hz, no noise) is found back: the lag exactly
    (the coarse 5-sample grid is refined to single samples around its best), ω_c, ζ and the
    gain to 1 % (the model is exact; what is left is the optimiser's stopping tolerance),
    fit above 99 %."""
    dt, L = 1e-3, 0.45
    t = np.arange(12000) * dt
    rng = np.random.default_rng(3)
    # a staircase hub angle through a first-order lag: rich enough to ring the link
    steps = np.repeat(rng.uniform(-0.3, 0.3, 12), 1000)
    th = scipy.signal.lfilter([1 - np.exp(-dt * 15)], [1, -np.exp(-dt * 15)], steps)
    true = (11.3, 0.04, -0.7 * L, 8.0)
    d = estimates._tip_response(true, th, 40, dt)
    from flexarm.io.logs import Log

    log = Log(path=None, time=t, signals={"motor_angle": th, "tip_deflection": d})
    m = estimates.tip_model([log], L, max_lag=60)
    assert m is not None
    assert m.lag == 40
    assert m.omega_c == pytest.approx(11.3, rel=0.01)
    assert m.zeta == pytest.approx(0.04, rel=0.01)
    assert m.gain == pytest.approx(-0.7, rel=0.01)
    assert m.fit_percent > 99
