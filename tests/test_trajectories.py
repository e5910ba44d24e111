"""Parabolic and quasi-parabolic references (FRB Sec. V-B, VI-B.3, VI-C.3), sizing."""

from __future__ import annotations

import control
import numpy as np
import pytest

from flexarm.control.trajectories import (
    acceleration_for_deflection,
    check_deflection,
    parabolic,
    peak_deflection,
    quasi_parabolic,
)
from flexarm.control.wiener import feedforward_signal, wiener_feedforward

S = control.tf("s")
G13 = control.tf([43.75], [1.0, 0.06, 43.75])  # single-mass arm, eq. (13)
G14 = control.tf([-45.475, 0.0, 45.475 * 1273.3], [1.0, 0.0, 1637.1, 0.0, 57903.3175])
A_PAPER = 7.875  # rad/s² (7875 mrad/s²)
SNAP_PAPER = 8648.646  # rad/s⁴ (8 648 646 mrad/s⁴)


def test_parabolic_profile():
    tr = parabolic(1.2, 3.0)
    assert tr.duration == pytest.approx(2 * np.sqrt(1.2 / 3.0), rel=1e-15)
    t = np.linspace(-0.1, tr.duration + 0.1, 20001)
    assert tr.position(np.array(tr.duration)) == 1.2
    assert abs(tr.position(np.array(tr.duration - 1e-12)) - 1.2) < 1e-11
    assert tr.velocity(np.array([tr.duration]))[0] == 0.0
    assert abs(tr.velocity(np.array(tr.duration - 1e-12))) < 1e-10
    assert np.max(np.abs(tr.acceleration(t))) == pytest.approx(3.0, rel=1e-15)
    # the grid is symmetric about duration/2 with an odd number of points, so one sample
    # sits on the velocity peak (up to rounding, ~1e-15): 1e-6 is not a grid effect
    assert np.max(tr.velocity(t)) == pytest.approx(3.0 * tr.duration / 2, rel=1e-6)
    assert np.all(tr.position(t[t < 0]) == 0.0)
    # central differences are exact on a parabola; across an acceleration jump ΔA = 6 they
    # err by ΔA·h/4 = 1.1e-4 (h = 7.3e-5 s): 1e-3
    np.testing.assert_allclose(np.gradient(tr.position(t), t), tr.velocity(t), atol=1e-3)
    with pytest.raises(ValueError, match="order 3"):
        tr.derivative(t, 3)


def test_quasi_parabolic_profile():
    d = 0.5
    tr = quasi_parabolic(d, A_PAPER, max_snap=SNAP_PAPER)
    t = np.linspace(0.0, tr.duration, 400001)
    # at rest at exactly the target from the end on
    tend = np.array([tr.duration, tr.duration + 1.0])
    np.testing.assert_array_equal(tr.position(tend), d)
    for k in range(1, 5):
        np.testing.assert_array_equal(tr.derivative(tend, k), 0.0)
    assert abs(tr.position(np.array(tr.duration - 1e-12)) - d) < 1e-12
    for k in range(1, 4):  # continuous up to the jerk at the end
        assert abs(tr.derivative(np.array(tr.duration - 1e-12), k)) < 1e-6
    peaks = [np.max(np.abs(tr.derivative(t, k))) for k in range(5)]
    assert peaks[2] == pytest.approx(A_PAPER, rel=1e-12)  # the acceleration is reached
    assert peaks[4] == pytest.approx(SNAP_PAPER, rel=1e-2)  # snap bounded by design value
    assert peaks[3] == pytest.approx(np.sqrt(2 * A_PAPER * SNAP_PAPER), rel=1e-6)
    # derivatives 0..3 continuous at every breakpoint, and consistent with each other
    for b in tr.breaks[1:]:
        for k in range(4):
            lo, hi = tr.derivative(np.array([b - 1e-10, b + 1e-10]), k)
            assert abs(hi - lo) < 1e-9 * max(1.0, peaks[k + 1])
    away = np.min(np.abs(t[:, None] - tr.breaks[None, :]), axis=1) > 3 * (t[1] - t[0])
    away &= t < tr.duration - 3 * (t[1] - t[0])
    for k in range(4):  # finite differences away from the snap's jumps
        np.testing.assert_allclose(
            np.gradient(tr.derivative(t, k), t)[away],
            tr.derivative(t, k + 1)[away],
            atol=1e-6 * peaks[k + 1],
        )
    with pytest.raises(ValueError, match="order 5"):
        tr.derivative(t, 5)
    # the acceleration profile is the parabolic one except near the corners
    par = parabolic(d, A_PAPER)
    assert tr.duration > par.duration
    tau1 = 2 * np.sqrt(A_PAPER / SNAP_PAPER)
    mid = tr.duration / 2
    hold = (t > tau1) & (t < mid - np.sqrt(2 * A_PAPER / SNAP_PAPER))
    np.testing.assert_allclose(tr.acceleration(t[hold]), A_PAPER, rtol=1e-12)
    # rounding_time alternative: S = 4 A / τ1²
    tr2 = quasi_parabolic(d, A_PAPER, rounding_time=tau1)
    assert tr2.max_snap == pytest.approx(SNAP_PAPER, rel=1e-12)
    assert tr2.duration == pytest.approx(tr.duration, rel=1e-12)


def test_laplace_model_is_acceleration_step():
    """A/s³ reproduces the paper's N(s) (see test_wiener); it is independent of S."""
    tr = quasi_parabolic(1.0, A_PAPER, max_snap=SNAP_PAPER)
    u = tr.laplace_model()
    assert u.num[0][0][-1] == A_PAPER
    np.testing.assert_array_equal(u.den[0][0], [1.0, 0.0, 0.0, 0.0])
    n1 = wiener_feedforward(G14, u)
    n2 = wiener_feedforward(G14, quasi_parabolic(1.0, 2.0, max_snap=100.0).laplace_model())
    np.testing.assert_allclose(n1.num[0][0], n2.num[0][0], rtol=1e-10)


def test_feedforward_bounded_only_for_quasi_parabolic():
    """FRB Sec. V-B: with the non-minimum-phase N(s) (polynomial part of degree 4) the
    parabolic reference's feedforward is impulsive: computed from samples it grows as
    the sampling is refined (×~100 for dt/10: the 4th finite difference of a jump in
    acceleration ∝ 1/dt²); the quasi-parabolic one converges to the bounded analytic
    signal. Observed peaks (distance 0.5 rad): parabolic 89 rad → 9.1e3 rad,
    quasi-parabolic 0.612 → 0.6385 rad (analytic 0.6416 rad)."""
    d = 0.5
    qp = quasi_parabolic(d, A_PAPER, max_snap=SNAP_PAPER)
    pb = parabolic(d, A_PAPER)
    n = wiener_feedforward(G14, qp.laplace_model())
    peak = {}
    for dt in (1e-3, 1e-4):
        for tr in (pb, qp):
            t = tr.time_grid(dt, 0.3)
            peak[tr.kind, dt] = np.max(np.abs(feedforward_signal(n, tr.position(t), t)))
    assert peak["parabolic", 1e-4] > 10 * peak["parabolic", 1e-3]
    assert peak["parabolic", 1e-3] > 50 * d
    t = qp.time_grid(1e-4, 0.3)
    analytic = np.max(np.abs(feedforward_signal(n, qp, t)))
    assert analytic < 2 * d  # bounded, same order as the move
    assert peak["quasi-parabolic", 1e-4] == pytest.approx(analytic, rel=1e-2)
    assert peak["quasi-parabolic", 1e-3] == pytest.approx(analytic, rel=5e-2)
    with pytest.raises(ValueError, match="order 3"):
        feedforward_signal(n, pb, t)  # analytic parabolic: refused, not impulsive


def test_acceleration_for_deflection_single_mass():
    """FRB Sec. VI-B.3: 200 mrad at ω² = 43.75 → 8750 mrad/s²; the simulated peak
    deflection of a parabolic move with N = 1/G_b is (A + 0.06 v_max)/43.75."""
    a = acceleration_for_deflection(0.2, 43.75)
    assert a == pytest.approx(8.75, rel=1e-15)
    tr = parabolic(1.0, a)
    n = wiener_feedforward(G13, tr.laplace_model())
    vmax = a * tr.duration / 2
    peak = peak_deflection(G13, n, tr)
    assert peak == pytest.approx((a + 0.06 * vmax) / 43.75, rel=1e-3)
    assert check_deflection(G13, n, tr, 0.4) == peak  # FRB's 400 mrad limit holds


def test_deflection_limit_not_met():
    tr = parabolic(1.0, 8.75)
    n = wiener_feedforward(G13, tr.laplace_model())
    with pytest.raises(ValueError, match=r"max_deflection_rad = 0\.15 rad by 0\.054") as exc:
        check_deflection(G13, n, tr, 0.15)
    msg = str(exc.value)
    assert "exceeds" in msg and "%" in msg and "scale max_acceleration" in msg
    factor = float(msg.rsplit("by about", 1)[1])
    tr2 = parabolic(1.0, 8.75 * factor)
    assert peak_deflection(G13, n, tr2) == pytest.approx(0.15, rel=5e-3)


def test_two_mass_deflection_and_parabolic_refused():
    """Eq. (14), paper's A and S: the deflection is bounded and settles; the parabolic
    move cannot be sized this way (unbounded feedforward)."""
    qp = quasi_parabolic(0.5, A_PAPER, max_snap=SNAP_PAPER)
    n = wiener_feedforward(G14, qp.laplace_model())
    peak = peak_deflection(G14, n, qp)
    # at least the steady-acceleration value −G_b''(0)/2 · A = 0.02906 A, at most ~2 rad
    assert 0.0290 * A_PAPER < peak < 2.0
    with pytest.raises(ValueError, match="order 3"):
        peak_deflection(G14, n, parabolic(0.5, A_PAPER))


@pytest.mark.parametrize(
    "call,match",
    [
        (lambda: parabolic(0.0, 1.0), "distance must be positive"),
        (lambda: parabolic(-1.0, 1.0), "distance must be positive"),
        (lambda: parabolic(1.0, 0.0), "max_acceleration must be positive"),
        (lambda: quasi_parabolic(1.0, -2.0, max_snap=10.0), "max_acceleration"),
        (lambda: quasi_parabolic(1.0, 2.0, max_snap=0.0), "max_snap"),
        (lambda: quasi_parabolic(1.0, 2.0), "exactly one"),
        (lambda: quasi_parabolic(1.0, 2.0, max_snap=1.0, rounding_time=1.0), "exactly one"),
        (lambda: quasi_parabolic(1e-3, A_PAPER, max_snap=SNAP_PAPER), r"short by 0\.0"),
        (lambda: acceleration_for_deflection(0.0, 43.75), "max_deflection_rad"),
        (lambda: acceleration_for_deflection(0.2, -1.0), "omega2"),
        (lambda: check_deflection(G13, 1 / G13, parabolic(1.0, 1.0), 0.0), "max_deflection_rad"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()
