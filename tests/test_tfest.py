"""flexarm.identification.frequency_domain.tfest: the frequency-domain fit on FRDs of known systems
(exact on noise-free data; calibrated intervals and cost under noise of known variance) and the
two-mass structure."""

import control
import numpy as np
import pytest

from flexarm.identification.frequency_domain.structures import fit_two_mass, two_mass_response
from flexarm.identification.frequency_domain.tfest import TFEstError, tfest, tfest_orders


def _coef_err(fit, sys):
    """Largest relative coefficient error (numerator and denominator)."""
    n, d = fit.tf.num[0][0], fit.tf.den[0][0]
    N, D = np.trim_zeros(sys.num[0][0], "f"), sys.den[0][0]
    assert len(n) == len(N) and len(d) == len(D)
    nz = D != 0
    return max(np.max(np.abs(n / N - 1)), np.max(np.abs(d[nz] / D[nz] - 1)))


# Noise-free data fitted with the true orders: the estimator is exact up to rounding
# (the condition of the scaled coefficient problem is ~1e4 at most here, ×1e-16) → 1e-8.
W = np.geomspace(1, 1000, 60)
SYSTEMS = {
    # resonance 200 rad/s / antiresonance 20 rad/s, ζ = 0.001 each: 60 dB apart, and an integrator
    "two-mass": (control.tf([100, 4, 4e4], [1, 0.4, 4e4, 0]), 3, 2, 1),
    # close poles at −10, −11 and a zero at −30
    "close-poles": (control.tf([3, 90], np.polymul([1, 10], [1, 11])), 2, 1, 0),
    "double-integrator-lead": (control.tf([5, 50], [1, 200, 0, 0]), 3, 1, 2),
}


@pytest.mark.parametrize("name", SYSTEMS)
def test_noise_free_coefficients(name):
    sys, npl, nz, k = SYSTEMS[name]
    fit = tfest(control.frd(sys(1j * W), W), npl, nz, integrators=k)
    assert _coef_err(fit, sys) < 1e-8
    assert not fit.unstable_poles


def test_delay_estimated_noise_free():
    sys = control.tf([50.0], [1, 3, 50])
    w = W[:40]
    H = sys(1j * w) * np.exp(-1j * w * 0.002)
    fit = tfest(control.frd(H, w), 2, 0, delay=True)
    assert fit.delay == pytest.approx(0.002, rel=1e-8) and _coef_err(fit, sys) < 1e-8


def test_monte_carlo_coverage_and_cost():
    """200 runs with complex circular noise of known std σ_k = 0.05|G_k| on 25 lines: the
    95 % intervals (±1.96 std) cover the truth in 90–99 % of runs (binomial spread at
    p = 0.95, n = 200 is ±1.5 %; the band allows for the linearisation), and the mean cost
    is within 3 spreads/√200 of its expected value F − n_θ/2."""
    sys = control.tf([2.0, 40.0], [1.0, 4.0, 400.0])
    w = np.geomspace(2, 200, 25)
    G = sys(1j * w)
    sd = 0.05 * np.abs(G)
    rng = np.random.default_rng(1)
    truth = np.r_[sys.num[0][0][::-1], sys.den[0][0][::-1][:-1]]
    cover, costs = [], []
    for _ in range(200):
        H = G + sd * (rng.standard_normal(25) + 1j * rng.standard_normal(25)) / np.sqrt(2)
        f = tfest(control.frd(H, w), 2, 1, std=sd)
        v = np.array([f.parameters[k]["value"] for k in ("b0", "b1", "a0", "a1")])
        s = np.array([f.parameters[k]["std"] for k in ("b0", "b1", "a0", "a1")])
        cover.append(np.abs(v - truth) < 1.96 * s)
        costs.append(f.cost)
    rate = np.mean(cover, axis=0)
    assert np.all((rate >= 0.90) & (rate <= 0.99)), rate
    assert abs(np.mean(costs) - f.expected_cost) < 3 * f.cost_std / np.sqrt(200)
    assert "accepted" in f.verdict or "rejected" in f.verdict


def test_order_selection_and_errors():
    sys, npl, nz, k = SYSTEMS["close-poles"]
    w = W[:50]
    rng = np.random.default_rng(3)
    G = sys(1j * w)
    sd = 1e-3 * np.abs(G)
    H = G + sd * (rng.standard_normal(50) + 1j * rng.standard_normal(50)) / np.sqrt(2)
    best, fits = tfest_orders(control.frd(H, w), range(1, 5), relative_degree=1, std=sd)
    assert best.n_parameters == 4  # two poles, one zero
    with pytest.raises(TFEstError, match="real equations"):
        tfest(control.frd(G[:2], w[:2]), 4, 3)
    with pytest.raises(TFEstError, match="std has shape"):
        tfest(control.frd(G, w), 2, 1, std=sd[:3])


def test_two_mass_noise_free_and_noisy():
    p = dict(
        total_inertia=0.02,
        inertia_ratio=1.3,
        resonance_hz=80.0,
        shaft_damping=0.03,
        motor_viscous=0.01,
        load_viscous=0.005,
        delay_s=3e-4,
    )
    w = 2 * np.pi * np.arange(13, 250, 4.0)
    Gm, Gl = two_mass_response(p, w)
    f = fit_two_mass(w, Gm, Gl)
    for k, v in p.items():  # exact data: rounding and the solver's 1e-12 tolerances
        assert f.parameters[k]["value"] == pytest.approx(v, rel=1e-6), k
    assert f.parameters["antiresonance_hz"]["value"] == pytest.approx(80 / np.sqrt(2.3), rel=1e-9)
    rng = np.random.default_rng(0)
    sm, sl = 0.01 * abs(Gm), 0.01 * abs(Gl)

    def noise():
        return (rng.standard_normal(len(w)) + 1j * rng.standard_normal(len(w))) / np.sqrt(2)

    f = fit_two_mass(w, Gm + sm * noise(), Gl + sl * noise(), motor_std=sm, load_std=sl)
    for k, v in p.items():  # within 4 standard deviations (one draw; P(fail) ~ 1e-4 each)
        assert abs(f.parameters[k]["value"] - v) < 4 * f.parameters[k]["std"], k
    assert "accepted" in f.verdict
    assert not any("std_inflated" in v for v in f.parameters.values())  # only when rejected
    fixed = fit_two_mass(
        w,
        Gm,
        Gl,
        free=("total_inertia", "inertia_ratio", "resonance_hz"),
        initial={
            "delay_s": 3e-4,
            "motor_viscous": 0.01,
            "load_viscous": 0.005,
            "shaft_damping": 0.03,
        },
    )
    assert fixed.n_parameters == 3 and fixed.parameters["delay_s"]["std"] == 0.0
    with pytest.raises(TFEstError, match="unknown parameter"):
        fit_two_mass(w, Gm, Gl, free=("stiffness",))
