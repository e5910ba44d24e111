"""flexarm.fastmath: vectorisable float64 sine and cosine against the platform libm."""

import jax
import numpy as np
import pytest

from flexarm import fastmath


@pytest.mark.parametrize("span", [1.0, 1e3, 1e5])
def test_sincos_within_two_ulp_of_libm(span):
    # fdlibm's kernels are < 1 ulp on |r| <= pi/4; the three-part reduction adds < 1 ulp
    # for |k| < 2**20 (|x| < 8e5): 2 ulp is the bound the module states.
    x = np.random.default_rng(0).uniform(-span, span, 100_000)
    s, c = (np.asarray(v) for v in jax.jit(fastmath.sincos)(x))
    for ours, ref in ((s, np.sin(x)), (c, np.cos(x))):
        ulp = np.abs(ours - ref) / np.spacing(np.abs(ref))
        assert ulp.max() <= 2.0


def test_sincos_quadrants_and_exact_points():
    # Every quadrant's sign and swap, at multiples of pi/4 (where the quadrant boundary
    # and the rounding of k meet), and x = 0 exactly.
    x = np.arange(-400, 401) * (np.pi / 4)
    s, c = (np.asarray(v) for v in fastmath.sincos(x))
    np.testing.assert_allclose(s, np.sin(x), rtol=0, atol=4e-16)
    np.testing.assert_allclose(c, np.cos(x), rtol=0, atol=4e-16)
    assert float(fastmath.sin(0.0)) == 0.0 and float(fastmath.cos(0.0)) == 1.0
    np.testing.assert_allclose(s * s + c * c, 1.0, rtol=0, atol=4.5e-16)
