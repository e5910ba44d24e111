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


def _rests_log(k_c: float, angles, seed: int = 0, dt: float = 2e-3, noise: float = 2e-5) -> Log:
    """A two-link log of holds at the shoulder ``angles`` (2 s each, 0.5 s moves between,
    the gauge ringing at 3 Hz while moving), the elbow still, the shoulder gauge reading
    g α + c with α = −k_c θ / (K + k_c) at rest (the quanser-two-link sheet's K, g = 1,
    c = 0.4 mrad), white noise of 20 µrad on the gauge and one-count dither on the encoder."""
    from flexarm.specs.scenario import load_scenario

    K = load_scenario("quanser-two-link").arm.links[0].torsional_stiffness
    rng = np.random.default_rng(seed)
    th, t_move = [], int(0.5 / dt)
    for a, b in zip(angles[:-1], angles[1:], strict=True):
        th += [a] * int(2.0 / dt)
        th += list(a + (b - a) * 0.5 * (1 - np.cos(np.pi * np.arange(t_move) / t_move)))
    th += [angles[-1]] * int(2.0 / dt)
    th = np.asarray(th)
    t = np.arange(th.size) * dt
    moving = np.convolve(np.abs(np.gradient(th)) > 0, np.ones(int(0.8 / dt)), "same") > 0
    q = 2 * np.pi / 409600
    gauge = -k_c * th / (K + k_c) + 4e-4 + moving * 5e-3 * np.sin(2 * np.pi * 3 * t)
    return Log(
        None,
        t,
        {
            "theta_1": np.round((th + q * rng.integers(-1, 2, th.size)) / q) * q,
            "alpha_f_1": gauge + rng.normal(0, noise, th.size),
            "theta_2": np.round(q * rng.integers(-1, 2, th.size) / q) * q,
            "alpha_f_2": rng.normal(0, 2e-5, th.size),
        },
    )


def test_cable_springs_read_the_static_gauge_slope_at_rest():
    """Eq. (1) of :func:`estimates.cable_springs` inverts the static deflection of the
    Joint docstring: holds at five shoulder angles with k_c = 0.1 N·m/rad give k_c back to
    1 % (the holds' means carry ~1 µrad of noise against ~1 mrad of slope); no spring gives
    none (with the reason), nor does a round-off slope; one hold gives none (too few
    rests)."""
    from flexarm.specs.scenario import load_scenario

    sc = load_scenario("quanser-two-link")
    angles = [0.0, 0.3, -0.2, 0.45, -0.4]
    est = estimates.cable_springs(sc, [_rests_log(0.1, angles)])
    e = est[0]
    assert e.gauge == "alpha_f_1" and e.angle == "theta_1" and e.holds == 5
    assert e.stiffness == pytest.approx(0.1, rel=0.01)
    assert est[1].stiffness is None  # the elbow never moves: no slope to read
    none = estimates.cable_springs(sc, [_rests_log(0.0, angles, seed=1)])[0]
    assert none.stiffness is None and "not a restoring spring" in none.reason
    # an exact log (no noise) of a spring of 1e-12 N·m/rad: significant, and nothing to fit
    tiny = estimates.cable_springs(sc, [_rests_log(1e-12, angles, seed=3, noise=0.0)])[0]
    assert tiny.stiffness is None and "nothing to fit" in tiny.reason, tiny
    one = estimates.cable_springs(sc, [_rests_log(0.1, [0.2, 0.2], seed=2)])[0]
    assert one.stiffness is None and "too few" in one.reason
