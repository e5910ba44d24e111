"""The tip loop of FRB Sec. V / Fig. 5: the paper's PID, trajectory sizing, the
feedforward channel, and the closed tip loops of Figs. 14 and 18 on the simulated arms."""

import control
import numpy as np
import pytest

from _feliu import COUNT, design, model, scenario
from flexarm.control.inner_loop import inner_loop
from flexarm.control.outer_loop import (
    deflection_report,
    pid_zpk,
    size_parabolic,
    tip_loop,
    trajectory_references,
)
from flexarm.control.trajectories import parabolic, quasi_parabolic
from flexarm.control.wiener import feedforward_signal, wiener_feedforward
from flexarm.metrics import step_metrics
from flexarm.reproduce.feliu import CHOICES, _mode_amplitudes, _modes
from flexarm.sim.build import prepare, run_prepared

DT = 0.003
G13 = control.tf([43.75], [1.0, 0.06, 43.75])  # FRB eq. (13)
G14 = control.tf([-45.475, 0.0, 45.475 * 1273.3], [1.0, 0.0, 1637.1, 0.0, 57903.3175])


def test_pid_zpk_is_the_papers_controller():
    g = pid_zpk(100.0, (0.98, 0.99), 0.61, DT)
    np.testing.assert_allclose(g.num[0][0], 100 * np.array([1.0, -1.97, 0.9702]), rtol=1e-14)
    np.testing.assert_allclose(g.den[0][0], [1.0, -1.61, 0.61], rtol=1e-14)
    assert np.any(np.isclose(g.poles(), 1.0))  # the integrator
    assert g.dt == DT


def test_parabolic_sizing_from_the_design_deflection():
    """A = 200 mrad · 43.75 s⁻² = 8750 mrad/s² and N = 1/G_b (FRB Sec. VI-B.3)."""
    traj, n, peak = size_parabolic(G13, 1.0, 0.2, 0.4)
    assert traj.max_acceleration == pytest.approx(8.75, rel=1e-12)
    assert traj.kind == "parabolic"
    num, den = (np.asarray(a, float) for a in (n.num[0][0], n.den[0][0]))
    np.testing.assert_allclose(num / den[-1], [1 / 43.75, 0.06 / 43.75, 1.0], rtol=1e-12)
    assert 0.2 <= peak <= 0.21  # the steady-acceleration bend, a little more from 2ζω u̇


def test_trajectory_that_breaks_the_deflection_limit_is_refused():
    with pytest.raises(
        ValueError,
        match=r"deflection limit not met: peak .* exceeds "
        r"max_deflection_rad = 0.4 rad by 0.1\d* rad",
    ):
        size_parabolic(G13, 1.0, 0.5, 0.4)
    with pytest.raises(ValueError, match="second-order"):
        size_parabolic(G14, 1.0, 0.2, 0.4)


def test_paper_two_mass_trajectory_bends_past_the_limit_at_its_corners():
    """FRB's A = 7875 mrad/s² and snap 8 648 646 mrad/s⁴ with eq. (14): the ideal
    feedforward bends the link 0.229 rad in steady acceleration (the s² term of 1 − G_b
    times A) and about 0.5 rad at the corners (the snap term of N u)."""
    tr = quasi_parabolic(0.3, 7.875, max_snap=8648.646)
    rep = deflection_report(G14, wiener_feedforward(G14, tr.laplace_model()), tr)
    assert rep.steady_acceleration == pytest.approx(7.875 * 1682.575 / 57903.3175, rel=1e-9)
    assert 0.45 < rep.peak < 0.55
    assert rep.time > tr.duration - 0.1  # at the last corner


def test_feedforward_channel_on_the_sample_grid():
    """θ̂_mr = N u on the 3 ms grid equals N u computed 100x finer: N = 1/G_b of the
    damped single-mass model has a fast pole (s ≈ −729) whose proper part, split from
    the polynomial part, loses ~0.1 rad between 3 ms samples unless oversampled."""
    gb = model().beam_tf()
    traj, n, _ = size_parabolic(gb, 0.2, 0.2, 0.4)
    t = np.arange(0, 0.6, DT)
    refs = trajectory_references(n, traj, t, start=0.05)
    fine = np.arange(0, 0.6 - DT / 2, DT / 300)
    truth = feedforward_signal(n, lambda tt, k: traj.derivative(tt - 0.05, k), fine)[::300]
    assert np.max(np.abs(refs["feedforward"] - truth)) < 1e-3
    coarse = trajectory_references(n, traj, t, start=0.05, oversample=1)
    assert np.max(np.abs(coarse["feedforward"] - truth)) > 1e-2
    np.testing.assert_array_equal(refs["reference"], traj.position(t - 0.05))


def test_advance_shifts_the_feedforward():
    traj = parabolic(0.2, 8.75)
    n = control.tf([1.0, 0.06, 43.75], [43.75])  # polynomial N: u + (0.06 u̇ + ü)/43.75
    t = np.arange(0, 0.5, DT)
    ff = trajectory_references(n, traj, t, start=0.05, advance=0.0215)["feedforward"]
    tau = t - 0.05 + 0.0215  # jumps of ü fall between samples
    want = traj.position(tau) + (0.06 * traj.velocity(tau) + traj.acceleration(tau)) / 43.75
    np.testing.assert_allclose(ff, want, atol=1e-12)
    with pytest.raises(ValueError, match=r"advance must be in \[0, start\]"):
        trajectory_references(n, traj, t, start=0.01, advance=0.02)


def test_tip_loop_needs_its_own_motor_reference_channel():
    inner = inner_loop(15.0, 1.0, dt=DT, torque_constant=0.25)
    with pytest.raises(ValueError, match="reference='motor_reference'"):
        tip_loop(inner, (1.0, 0.0), DT)


def _tip_run(name, gcb, n, traj, duration, advance):
    m = model(name)
    inner = design().controller(m, angle_resolution=COUNT, reference="motor_reference")
    p = prepare(scenario(name, duration), controller=tip_loop(inner, gcb, DT))
    p.references.update(
        trajectory_references(n, traj, p.time, start=CHOICES.move_start, advance=advance)
    )
    return run_prepared(p)


def test_single_mass_tip_loop_fig14():
    """Paper's G_cb, parabolic move sized for 200 mrad: settles within 0.3 s (paper
    0.22 s) and keeps |θm − θt| within 400 mrad."""
    c = CHOICES
    traj, n, _ = size_parabolic(
        model().beam_tf(), c.single_distance, c.design_deflection, c.max_deflection
    )
    gcb = pid_zpk(c.gcb_gain, c.gcb_zeros, c.gcb_pole, DT)
    r = _tip_run("feliu-single-mass", gcb, n, traj, c.duration_single, design().lag)
    m = step_metrics(
        r.time,
        r["tip_angle"],
        r["reference"],
        band=0.02,
        t_step=c.move_start,
        target=c.single_distance,
    )
    assert m.settling_time <= 0.3
    assert np.max(np.abs(r["motor_angle"] - r["tip_angle"])) <= 0.4
    tip_count = np.pi / 4096  # 180° over 12 bits
    assert abs(c.single_distance - r.measured["tip_angle"][-1]) <= tip_count


def test_two_mass_tip_loop_fig18():
    """Wiener feedforward, the paper's A and snap, PD feedback: the first mode is
    removed (vs. N = 1), the ripple stays below 3 % of the step, 5 % settling within
    0.4 s (paper 0.3 s)."""
    c = CHOICES
    gb = model("feliu-two-mass").beam_tf()
    traj = quasi_parabolic(c.two_mass_distance, c.two_mass_acceleration, max_snap=c.two_mass_snap)
    n = wiener_feedforward(gb, traj.laplace_model())
    d = c.two_mass_distance
    t_end = c.move_start + traj.duration
    amp = {}
    for key, nn in (("wiener", n), ("rigid", control.tf([1.0], [1.0]))):
        r = _tip_run("feliu-two-mass", c.two_mass_pd, nn, traj, c.duration_two_mass, design().lag)
        amp[key] = _mode_amplitudes(
            r.time, r["tip_angle"], d, t_end + c.ripple_fit_delay, _modes(gb)
        )
        if key == "wiener":
            m = step_metrics(
                r.time, r["tip_angle"], r["reference"], band=0.05, t_step=c.move_start, target=d
            )
            assert m.settling_time <= 0.4
            after = r.time > t_end
            assert np.max(np.abs(r["tip_angle"][after] - d)) < 0.03 * d
            assert np.max(np.abs(r["motor_angle"] - r["tip_angle"])) <= 0.4
    assert amp["wiener"][0] < 0.01 * d
    assert amp["wiener"][0] < 0.05 * amp["rigid"][0]
