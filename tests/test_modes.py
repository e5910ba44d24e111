"""Clamped-mass / clamped-free Euler–Bernoulli modes of one link (flexarm.models.modes)."""

import math

import numpy as np
import pytest
from scipy.linalg import eigh
from scipy.optimize import brentq

from flexarm.models.modes import ModeError, link_modes

ELL, RHO, EI = 0.5, 0.2, 15.0
M = RHO * ELL


def analytic_clamped_mass(b, mu):
    """1 + cos b cosh b + μ b (cos b sinh b − sin b cosh b), divided by cosh b."""
    return 1.0 / math.cosh(b) + math.cos(b) + mu * b * (math.cos(b) * math.tanh(b) - math.sin(b))


def test_clamped_free_matches_classical_roots():
    modes = link_modes(ELL, RHO, EI, 3, mode_type="clamped_free")
    np.testing.assert_allclose(modes.beta_l[:2], [1.8751, 4.6941], rtol=1e-3)
    for b in modes.beta_l:  # roots of 1 + cos b cosh b = 0 to round-off
        assert abs(brentq(lambda x: analytic_clamped_mass(x, 0.0), b - 0.01, b + 0.01) - b) < 1e-10
    np.testing.assert_allclose(modes.omega, (modes.beta_l / ELL) ** 2 * math.sqrt(EI / RHO))
    # no tip load: clamped-mass with M_L = J_L = 0 is clamped-free
    same = link_modes(ELL, RHO, EI, 3)
    np.testing.assert_allclose(same.beta_l, modes.beta_l, rtol=1e-12)


@pytest.mark.parametrize("ratio", [0.5, 2.0, 12.0])
def test_tip_mass_lowers_frequencies_and_solves_analytic_equation(ratio):
    free = link_modes(ELL, RHO, EI, 3, mode_type="clamped_free")
    modes = link_modes(ELL, RHO, EI, 3, tip_mass=ratio * M)
    assert np.all(modes.beta_l < free.beta_l)
    for b in modes.beta_l:
        root = brentq(lambda x: analytic_clamped_mass(x, ratio), b - 0.02, b + 0.02)
        assert abs(root - b) < 1e-10


def test_normalisation_orthogonality_and_stiffness():
    Ml, Jl = 1.2, 0.13383
    modes = link_modes(ELL, RHO, EI, 4, tip_mass=Ml, tip_inertia=Jl)
    gen = (
        modes.Z
        + Ml * np.outer(modes.tip_value, modes.tip_value)
        + Jl * np.outer(modes.tip_slope, modes.tip_slope)
    )
    np.testing.assert_allclose(gen, M * np.eye(4), atol=1e-10 * M)
    np.testing.assert_allclose(modes.modal_mass, M, rtol=1e-12)
    kjj = modes.omega**2 * M
    np.testing.assert_allclose(np.diag(modes.K), kjj, rtol=1e-6)
    off = modes.K - np.diag(np.diag(modes.K))
    assert np.abs(off).max() < 1e-8 * kjj.max()
    assert np.all(modes.tip_value > 0)
    # end values agree with the shape functions
    np.testing.assert_allclose(modes.shape(ELL)[:, 0], modes.tip_value, rtol=1e-12)
    np.testing.assert_allclose(modes.shape(ELL, 1)[:, 0], modes.tip_slope, rtol=1e-12)
    np.testing.assert_allclose(modes.shape(0.0)[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(modes.shape(0.0, 1)[:, 0], 0.0, atol=1e-10)


def _fe_frequencies(Ml, Jl, n_el=60):
    """Hermite beam elements with tip mass and inertia: independent check of the BCs."""
    h = ELL / n_el
    k = (
        EI
        / h**3
        * np.array(
            [
                [12, 6 * h, -12, 6 * h],
                [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                [-12, -6 * h, 12, -6 * h],
                [6 * h, 2 * h * h, -6 * h, 4 * h * h],
            ]
        )
    )
    m = (
        RHO
        * h
        / 420
        * np.array(
            [
                [156, 22 * h, 54, -13 * h],
                [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                [54, 13 * h, 156, -22 * h],
                [-13 * h, -3 * h * h, -22 * h, 4 * h * h],
            ]
        )
    )
    nd = 2 * (n_el + 1)
    K = np.zeros((nd, nd))
    Mm = np.zeros((nd, nd))
    for e in range(n_el):
        s = slice(2 * e, 2 * e + 4)
        K[s, s] += k
        Mm[s, s] += m
    Mm[-2, -2] += Ml
    Mm[-1, -1] += Jl
    w2 = eigh(K[2:, 2:], Mm[2:, 2:], eigvals_only=True)
    return np.sqrt(w2[:3])


def test_tip_inertia_boundary_condition_against_finite_elements():
    Ml, Jl = 1.2, 0.13383
    modes = link_modes(ELL, RHO, EI, 3, tip_mass=Ml, tip_inertia=Jl)
    np.testing.assert_allclose(modes.omega, _fe_frequencies(Ml, Jl), rtol=1e-5)


def test_rigid_link_has_no_modes():
    modes = link_modes(ELL, RHO, EI, 0)
    assert modes.n_modes == 0 and modes.K.shape == (0, 0)


def test_bad_input_is_refused_clearly():
    with pytest.raises(ModeError, match="length"):
        link_modes(0.0, RHO, EI, 2)
    with pytest.raises(ModeError, match="flexural_rigidity"):
        link_modes(ELL, RHO, 0.0, 2)
    with pytest.raises(ModeError, match="flexural_rigidity"):
        link_modes(ELL, RHO, -1.0, 2)
    with pytest.raises(ModeError, match="βℓ"):
        link_modes(ELL, RHO, EI, 60)
    with pytest.raises(ModeError, match="whole number"):
        link_modes(ELL, RHO, EI, -1)
    with pytest.raises(ModeError, match="mode_type"):
        link_modes(ELL, RHO, EI, 2, mode_type="pinned")
