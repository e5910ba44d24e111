"""Wiener feedforward N(s), FRB (1993) eq. (11): paper result, closed forms, optimality.

ISE values here are computed independently of the Wiener formula: the error
e(s) = u(s)(1 − G_b(s)N(s)) is formed by exact polynomial arithmetic, its impulse
response is simulated with scipy.signal.impulse and ∫e² is integrated numerically.
"""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.integrate
import scipy.optimize
import scipy.signal
import sympy as sp

from flexarm.control.trajectories import parabolic, quasi_parabolic
from flexarm.control.wiener import (
    cancel_common_roots,
    discretize_feedforward,
    feedforward_signal,
    split_improper,
    wiener_feedforward,
)

S = control.tf("s")
# FRB eq. (14), paper units (rad/rad); the poles are undamped.
A2 = 1273.3
G14 = control.tf([-45.475, 0.0, 45.475 * A2], [1.0, 0.0, 1637.1, 0.0, 57903.3175])
# FRB Sec. VI-C.3: A = 7875 mrad/s², second derivative of acceleration 8 648 646 mrad/s⁴.
A_PAPER = 7.875  # rad/s²
SNAP_PAPER = 8648.646  # rad/s⁴


def _coeffs(sys):
    num = np.trim_zeros(np.asarray(sys.num[0][0], float), "f")
    den = np.trim_zeros(np.asarray(sys.den[0][0], float), "f")
    return num / den[0], den / den[0]


def paper_n():
    num = np.polymul([1.0, 0.0, 1637.1, 0.0, 57903.7175], [0.00157075, 0.05605, 1.0]) / 45.475
    den = np.polymul([1.0, 35.68333], [1.0, 35.68333])
    return num, den


# ----------------------------------------------------------------- ISE machinery
def error_tf(plant, n, u):
    """e(s) = u (1 − G N), with the exact common factors removed (s^k, plant poles)."""
    gn, gd = (np.asarray(x[0][0], float) for x in (plant.num, plant.den))
    nn, nd = (np.asarray(x[0][0], float) for x in (n.num, n.den))
    un, ud = (np.asarray(x[0][0], float) for x in (u.num, u.den))
    num = np.polymul(un, np.polysub(np.polymul(nd, gd), np.polymul(nn, gn)))
    den = np.polymul(ud, np.polymul(nd, gd))
    # remove the plant denominator when N's zeros cancel it (undamped modes)
    q, r = np.polydiv(num, gd)
    if np.max(np.abs(r)) < 1e-9 * np.max(np.abs(num)):
        num, den = q, np.polydiv(den, gd)[0]
    # remove the integrators of u: (1 − G N) must vanish to their order at s = 0
    while abs(den[-1]) < 1e-300 and den.size > 1:
        assert abs(num[-1]) < 1e-8 * np.max(np.abs(num)), "ISE infinite: steady error"
        num, den = num[:-1], den[:-1]
    num = np.trim_zeros(num, "f")
    scale = np.max(np.abs(num))
    while num.size > 1 and abs(num[0]) < 1e-12 * scale:
        num = num[1:]
    assert num.size < den.size, "ISE infinite: e(s) not strictly proper"
    return num, den


def ise(plant, n, u, horizon=40.0, steps=80001):
    """∫_0^∞ e(t)² dt by simulating the impulse response of e(s)."""
    num, den = error_tf(plant, n, u)
    t = np.linspace(0.0, horizon, steps)
    _, e = scipy.signal.impulse((num, den), T=t)
    return float(scipy.integrate.simpson(e**2, x=t))


# ------------------------------------------------------------------------ tests
def test_paper_two_mass_feedforward():
    """FRB Sec. VI-C.3: N(s) for eq. (14) and the quasi-parabolic reference model."""
    traj = quasi_parabolic(0.5, A_PAPER, max_snap=SNAP_PAPER)
    n = wiener_feedforward(G14, traj.laplace_model())
    num, den = _coeffs(n)
    pnum, pden = paper_n()
    assert num.size == pnum.size == 7 and den.size == pden.size == 3
    # the paper prints 4 significant digits (0.05605: half a unit in the last digit is
    # 9e-5 relative); measured 3.2e-5
    np.testing.assert_allclose(num, pnum, rtol=1e-4)
    np.testing.assert_allclose(den, pden, rtol=1e-4)
    # the model's gain (the acceleration) does not matter: it enters only through the
    # monic normalisation of u's polynomials (one rounding), hence 1e-13
    num1, den1 = _coeffs(wiener_feedforward(G14, 1 / S**3))
    np.testing.assert_allclose(num1, num, rtol=1e-13)
    np.testing.assert_allclose(den1, den, rtol=1e-13)


def test_paper_factor_is_the_reflected_zero_series():
    """N = D(s)(1 + 2s/a + … + 2(s/a)^(k−1)) / (K (s + a)²) for u = 1/s^k. Closed form;
    1e-12 of the largest coefficient: a few roundings of a Sylvester solve of condition
    < 1e2 (measured ≤ 1e-23 absolute, i.e. exact)."""
    a = np.sqrt(A2)
    d = [1.0, 0.0, 1637.1, 0.0, 57903.3175]
    for k in (1, 2, 3, 4):
        phi = np.array([2.0 / a**i for i in range(k - 1, 0, -1)] + [1.0])
        num, den = _coeffs(wiener_feedforward(G14, 1 / S**k))
        expect = np.polymul(d, phi) / 45.475
        np.testing.assert_allclose(num, expect, rtol=1e-12, atol=1e-12 * np.max(np.abs(expect)))
        np.testing.assert_allclose(den, [1.0, 2 * a, a * a], rtol=1e-12)


@pytest.mark.parametrize("u", [1 / S**3, 1 / S**2, 1 / (S * (S + 1)), 1 / (S + 2)])
def test_minimum_phase_gives_inverse(u):
    g = control.tf([43.75], [1.0, 0.06, 43.75])  # FRB eq. (13)
    num, den = _coeffs(wiener_feedforward(g, u))
    # N = 1/G_b is returned from the coefficients directly (one division): 1e-13
    np.testing.assert_allclose(num, np.array([1.0, 0.06, 43.75]) / 43.75, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(den, [1.0], rtol=1e-12)
    g2 = (S + 3) / ((S + 1) * (S**2 + S + 4))
    n2 = wiener_feedforward(g2, u)
    w = 1j * np.array([0.1, 1.0, 10.0])
    np.testing.assert_allclose(n2(w) * g2(w), 1.0, rtol=1e-12)  # polynomial evaluation: ~1e-16


G_NMP = (1 - S) / ((S + 1) * (S + 2))


def test_closed_forms_nmp():
    """Hand derivation for G = (1 − s)/((s+1)(s+2)):
    u = 1/s²: N = (2s + 1)(s + 2), e = 2/(s + 1), ISE = 2;
    u = 1/(s(s+1)): N = (s + 1)(s + 2), e = 1/(s + 1), ISE = 1/2."""
    num, den = _coeffs(wiener_feedforward(G_NMP, 1 / S**2))
    # 1e-12: exact integer answer; the method's rounding is a few ε times the condition
    # of the frequency-scaled Sylvester system (< 1e2 here), i.e. below 1e-13.
    np.testing.assert_allclose(num, [2.0, 5.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(den, [1.0], rtol=1e-12)
    # u shares the pole −1 with G and with the reflected zero: Q and A both carry
    # (s + 1), a double root of Q·A that must cancel exactly (it used to cost √ε).
    num, den = _coeffs(wiener_feedforward(G_NMP, 1 / (S * (S + 1))))
    np.testing.assert_allclose(num, [1.0, 3.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(den, [1.0], rtol=1e-12)
    # ISE by the exact impulse response on a grid and Simpson's rule: h = 5e-4 s against
    # a pole at −1 gives an O(h⁴) error ~1e-14, truncation at 40 s e^(−80): 1e-10
    # (measured 5e-14).
    assert ise(G_NMP, wiener_feedforward(G_NMP, 1 / S**2), 1 / S**2) == pytest.approx(
        2.0, rel=1e-10
    )
    assert ise(G_NMP, wiener_feedforward(G_NMP, 1 / (S * (S + 1))), 1 / (S * (S + 1))) == (
        pytest.approx(0.5, rel=1e-10)
    )


# ------------------------------------------- shared and repeated poles, exactly
SYM_S = sp.symbols("s")


def _sym_tf(expr):
    """control.tf of a sympy rational function with rational coefficients."""
    num, den = sp.fraction(sp.cancel(sp.together(expr)))
    return control.tf(
        [float(c) for c in sp.Poly(num, SYM_S).all_coeffs()],
        [float(c) for c in sp.Poly(den, SYM_S).all_coeffs()],
    )


def sympy_wiener(g, u):
    """Eq. (11) in exact rational arithmetic, independently of the module's algorithm:
    X = B̃_n/B_n · u by sympy's partial fractions (``apart``), [X]_+ = the terms that do
    not have all their poles in the right half-plane, N = [X]_+ / (G⁺ u) with
    G⁺ = G B̃_n/B_n. (u without right-half-plane zeros, so u⁺ = u.) Returns N's
    coefficients with a monic denominator, as floats."""
    s = SYM_S
    gn, _ = sp.fraction(sp.cancel(g))
    zeros = sp.roots(sp.Poly(gn, s))
    assert sum(zeros.values()) == sp.degree(gn, s)  # every zero found exactly
    bn = sp.Mul(*[(s - z) ** m for z, m in zeros.items() if sp.re(z) > 0])
    bnr = sp.Mul(*[(s + z) ** m for z, m in zeros.items() if sp.re(z) > 0])
    plus = sp.Integer(0)
    for term in sp.Add.make_args(sp.apart(sp.cancel(bnr / bn * u), s)):
        poles = sp.roots(sp.Poly(sp.fraction(sp.cancel(term))[1], s))
        if not (poles and all(sp.re(r) > 0 for r in poles)):
            plus += term
    num, den = (sp.Poly(x, s) for x in sp.fraction(sp.cancel(plus / (g * bnr / bn * u))))
    lc = den.LC()
    return (
        np.array([float(c / lc) for c in num.all_coeffs()]),
        np.array([float(c / lc) for c in den.all_coeffs()]),
    )


_s = SYM_S
_G_NMP_SYM = (1 - _s) / ((_s + 1) * (_s + 2))
SHARED = [
    # (plant G, reference u, hand-derived N or None); every u shares a pole with G
    (_G_NMP_SYM, 1 / (_s * (_s + 1)), (_s + 1) * (_s + 2)),
    # X = (s+1)/((s−1) s (s+2)): [X]_+ = −(2s+3)/(3 s (s+2)), G⁺ = −1/(s+2)
    (_G_NMP_SYM, 1 / (_s * (_s + 2)), (2 * _s + 3) * (_s + 2) / 3),
    # X = 1/(s²(s−1)): [X]_+ = −(s+1)/s², a double root of N at the shared pole
    (_G_NMP_SYM, 1 / (_s**2 * (_s + 1)), (_s + 1) ** 2 * (_s + 2)),
    # X = 1/((s−1)(s+1)): [X]_+ = −1/(2(s+1)), u's double pole is G's pole
    (_G_NMP_SYM, 1 / (_s + 1) ** 2, (_s + 1) * (_s + 2) / 2),
    # triple plant pole shared with u: X = 1/(s(s−1)), [X]_+ = −1/s, N = (s+1)³
    ((1 - _s) / (_s + 1) ** 3, 1 / (_s * (_s + 1)), (_s + 1) ** 3),
    # shared complex pair
    ((2 - _s) / ((_s**2 + 2 * _s + 2) * (_s + 3)), 1 / (_s * (_s**2 + 2 * _s + 2)), None),
    # double right-half-plane zero, triple plant pole shared once and twice
    ((_s - 1) ** 2 / (_s + 2) ** 3, 1 / (_s * (_s + 2)), None),
    ((_s - 1) ** 2 / (_s + 2) ** 3, 1 / (_s**2 * (_s + 2) ** 2), None),
    # shared lightly damped pair, and a reference zero on the plant pole −3
    (
        (2 - _s) * (_s + 4) / ((_s**2 + sp.Rational(2, 5) * _s + 4) * (_s + 3)),
        (_s + 3) / (_s * (_s**2 + sp.Rational(2, 5) * _s + 4)),
        None,
    ),
]


@pytest.mark.parametrize("g,u,hand", SHARED, ids=[f"{g}|{u}" for g, u, _ in SHARED])
def test_shared_and_repeated_poles_exact(g, u, hand):
    """Reference and plant share poles (some repeated): N agrees with the exact rational
    computation (and the hand derivation, where given) to 1e-12 of the largest
    coefficient. The reference is exact; our rounding is a few ε times the Sylvester
    system's condition (< 1e3 here, measured error ≤ 2e-15): 1e-12 leaves a margin and
    is four orders below the √ε ≈ 1.5e-8 that re-rooting a repeated root costs."""
    expect_num, expect_den = sympy_wiener(g, u)
    if hand is not None:
        hn, hd = sp.fraction(sp.cancel(hand))
        hn, hd = sp.Poly(hn, SYM_S), sp.Poly(hd, SYM_S)
        assert [float(c / hd.LC()) for c in hn.all_coeffs()] == pytest.approx(expect_num, rel=1e-15)
        assert [float(c / hd.LC()) for c in hd.all_coeffs()] == pytest.approx(expect_den, rel=1e-15)
    num, den = _coeffs(wiener_feedforward(_sym_tf(g), _sym_tf(u)))
    assert num.size == expect_num.size and den.size == expect_den.size  # all cancelled
    scale = np.max(np.abs(expect_num))
    np.testing.assert_allclose(num, expect_num, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(den, expect_den, rtol=1e-12, atol=1e-12)


def test_cancel_common_roots_repeated_factor():
    """A double common factor cancels to rounding: (s+1)²(s+3)/((s+1)²(s+2)) → (s+3)/(s+2)
    exactly (1e-12; a root-by-root match of the √ε-split double roots left 1e-8)."""
    g = cancel_common_roots((S + 1) ** 2 * (S + 3) / ((S + 1) ** 2 * (S + 2)))
    num, den = _coeffs(g)
    np.testing.assert_allclose(num, [1.0, 3.0], rtol=1e-12)
    np.testing.assert_allclose(den, [1.0, 2.0], rtol=1e-12)


def test_optimal_against_numerical_minimisation():
    """u = 1/(s(s+1)): minimise the simulated ISE over N = n2 s² + n1 s + 2 (n0 = 2 is
    forced by G(0)N(0) = 1, else ISE = ∞) from a poor start; Nelder–Mead must land on
    the Wiener N = s² + 3s + 2 (ISE 0.5), which beats the naive choices: the inverse of
    the minimum-phase part, s + 2 (ISE 1), and the static inverse 2."""
    u = 1 / (S * (S + 1))
    nw = wiener_feedforward(G_NMP, u)
    j_w = ise(G_NMP, nw, u, horizon=25.0, steps=2501)

    def cost(p):
        return ise(G_NMP, control.tf([p[0], p[1], 2.0], [1.0]), u, horizon=25.0, steps=2501)

    res = scipy.optimize.minimize(
        cost, x0=[0.0, 0.0], method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-10}
    )
    np.testing.assert_allclose(res.x, [1.0, 3.0], atol=2e-3)
    assert j_w <= res.fun + 1e-9
    assert j_w == pytest.approx(0.5, rel=1e-7)  # Simpson, h = 0.01 s: O(h⁴) ≈ 1e-8; measured 9e-10
    for naive in (S + 2, control.tf([2.0], [1.0])):
        assert ise(G_NMP, naive, u) > 1.9 * j_w


CASES = [
    # (plant, reference, admissible perturbation direction Δ: keeps ISE finite)
    (G_NMP, 1 / S**2, S**2 / (S + 1) ** 2),
    (G_NMP, 1 / (S * (S + 1)), S / (S + 3)),
    (G_NMP, 1 / (S**2 * (S + 1)), S**2 / (S + 3) ** 2),  # shared pole, N with a double root
    ((S**2 - 2 * S + 5) / ((S + 1) * (S + 2) * (S + 3)), 1 / S**2, S**2 / (S + 2) ** 3),
    ((S - 1) ** 2 / ((S + 2) ** 3), 1 / S**2, 20 * S**2 / (S + 1) ** 2),
    ((2 - S) * (S + 4) / ((S**2 + 0.4 * S + 4) * (S + 3)), 1 / (S**2 + 2 * S + 2), 1 / (S + 1)),
]


@pytest.mark.parametrize("plant,u,delta", CASES)
def test_stationary_and_minimal_under_perturbation(plant, u, delta):
    """ISE(N + εΔ) ≥ ISE(N) for ε = ±0.3, ±0.05, and the first variation vanishes:
    |ISE(+ε) − ISE(−ε)| ≤ 1e-4 · (ISE(+ε) + ISE(−ε) − 2 ISE(N)) (orthogonality of the
    error to every admissible direction, the Wiener–Hopf condition)."""
    n = wiener_feedforward(plant, u)
    j0 = ise(plant, n, u)
    for eps in (0.3, 0.05):
        jp = ise(plant, n + eps * delta, u)
        jm = ise(plant, n - eps * delta, u)
        curv = jp + jm - 2 * j0
        assert jp > j0 and jm > j0
        assert curv > 0
        assert abs(jp - jm) <= 1e-4 * curv


def test_paper_case_stationary():
    """Same check for eq. (14) with u = 1/s³; Δ keeps the undamped poles cancelled."""
    d = control.tf([1.0, 0.0, 1637.1, 0.0, 57903.3175], [1.0])
    u = 1 / S**3
    n = wiener_feedforward(G14, u)
    delta = S**3 * d / (S + 20) ** 7
    j0 = ise(G14, n, u, horizon=4.0, steps=40001)
    # closed form: e(s) = (2/a²)/(s + a), ISE = 2/a⁵. Simpson with h = 1e-4 s against
    # a = 35.7 rad/s: (a h)⁴ ≈ 2e-10 (measured 1.4e-11)
    assert j0 == pytest.approx(2.0 / A2**2.5, rel=1e-9)
    eps = 0.5
    jp = ise(G14, n + eps * delta, u, horizon=4.0, steps=40001)
    jm = ise(G14, n - eps * delta, u, horizon=4.0, steps=40001)
    assert jp > j0 and jm > j0
    assert abs(jp - jm) <= 1e-3 * (jp + jm - 2 * j0)


# ------------------------------------------------------------------- bad input
def test_unstable_plant_rejected():
    with pytest.raises(ValueError, match=r"unstable.*0\.5"):
        wiener_feedforward(1 / ((S - 0.5) * (S + 1)), 1 / S**2)
    with pytest.raises(ValueError, match="imaginary axis"):
        wiener_feedforward(G14, 1 / S**3, allow_marginal_poles=False)


def test_other_bad_inputs():
    mimo = control.tf([[[1.0], [1.0]]], [[[1.0, 1.0], [1.0, 2.0]]])
    with pytest.raises(ValueError, match="SISO"):
        wiener_feedforward(mimo, 1 / S**2)
    with pytest.raises(ValueError, match="SISO"):
        wiener_feedforward(G_NMP, mimo)
    with pytest.raises(TypeError, match="TransferFunction"):
        wiener_feedforward(lambda s: 1 / (s + 1), 1 / S**2)
    with pytest.raises(TypeError, match="TransferFunction"):
        wiener_feedforward(G_NMP, np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="continuous-time"):
        wiener_feedforward(control.tf([1.0], [1.0, -0.5], 0.1), 1 / S**2)
    with pytest.raises(ValueError, match="right half-plane at 2"):
        wiener_feedforward(G_NMP, 1 / (S - 2))
    with pytest.raises(ValueError, match="zeros on the imaginary axis"):
        wiener_feedforward((S**2 + 4) / (S + 1) ** 3, 1 / S**2)


# ------------------------------------------------------------- applying N(s)
def test_split_improper():
    poly, proper = split_improper(wiener_feedforward(G14, 1 / S**3))
    assert poly.size == 5  # degree 4: needs u … u⁗
    num, den = _coeffs(proper)
    assert num.size < den.size == 3


def test_feedforward_signal_minimum_phase_parabolic():
    """N = 1/G_b of eq. (13) on a parabolic move: θ̂ = u + (0.06 u̇ + ü)/43.75, and the
    tip θt = G_b θ̂ tracks u."""
    g = control.tf([43.75], [1.0, 0.06, 43.75])
    n = wiener_feedforward(g, 1 / S**3)
    traj = parabolic(1.0, 8.75)
    t = traj.time_grid(1e-3, 1.0)
    th = feedforward_signal(n, traj, t)
    expect = traj.position(t) + (0.06 * traj.velocity(t) + traj.acceleration(t)) / 43.75
    np.testing.assert_allclose(th, expect, atol=1e-12)
    tip = control.forced_response(g, t, th).outputs
    assert np.max(np.abs(tip - traj.position(t))) < 2e-3  # FOH of a jumping θ̂ only


def test_feedforward_signal_paper_arm_tracks():
    """Eq. (14), quasi-parabolic move: the tip error u − G_b N u is the causal Wiener
    residual, bounded by 2·(2A/a²) (the middle corner's acceleration change 2A times
    the 1/s³ residual 2/a² per unit step of acceleration)."""
    traj = quasi_parabolic(0.5, A_PAPER, max_snap=SNAP_PAPER)
    n = wiener_feedforward(G14, traj.laplace_model())
    gn = cancel_common_roots(G14 * n, rtol=1e-6)
    assert gn.den[0][0].size == 2  # undamped poles cancelled, (s + a) left
    t = traj.time_grid(2e-4, 0.3)
    err = traj.position(t) - feedforward_signal(gn, traj, t)
    assert np.max(np.abs(err)) < 4 * A_PAPER / A2
    assert abs(err[-1]) < 1e-6


def test_discretize_feedforward():
    traj = quasi_parabolic(0.5, A_PAPER, max_snap=SNAP_PAPER)
    n = wiener_feedforward(G14, traj.laplace_model())
    rms = []
    for dt in (1e-3, 2e-4):
        nd = discretize_feedforward(n, dt)
        assert isinstance(nd, control.StateSpace) and nd.dt == dt
        assert np.all(np.abs(nd.poles()) < 1)
        t = traj.time_grid(dt, 0.3)
        y = control.forced_response(nd, t, traj.position(t)).outputs
        ref = feedforward_signal(n, traj, t)
        assert abs(y[-1] - ref[-1]) < 1e-4  # static gain kept
        rms.append(np.sqrt(np.mean((y - ref) ** 2) / np.mean(ref**2)))
    # the low-pass lag shrinks with the sampling period (ω_f = π/(4 dt))
    assert rms[0] < 0.25 and rms[1] < 0.6 * rms[0]
    nm = discretize_feedforward(n, 1e-3, method="matched")
    y = control.forced_response(nm, t := traj.time_grid(1e-3, 0.3), traj.position(t)).outputs
    assert abs(y[-1] - 0.5) < 1e-4
    with pytest.raises(ValueError, match="dt"):
        discretize_feedforward(n, 0.0)
