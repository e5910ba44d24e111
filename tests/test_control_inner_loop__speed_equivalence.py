"""The inner-loop search's faster evaluation (issue #46) is the old one: the objective of
candidate compensators equals the evaluator of commit 1ee883f (tests/_inner_loop_before.py,
verbatim), and the search designs the same compensators on short-delay rigs.

The new evaluation does the same arithmetic in another order (a block's motor states one
matrix product instead of an einsum, the compensators' filters a doubling scan, the fine
grid one product, the integral squared error one dot product per candidate): rounding
only, ~1e-15 of each value, grown by the loop's recursion over up to 1230 samples
(measured: at most 3e-14 relative on the objective). 1e-9 relative leaves that margin and
still catches any change of the recursion (a wrong sample of delay moves the objective by
far more than 1e-6).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from _inner_loop_before import OldStepEvaluator, old_cost
from flexarm.control.inner_loop import (
    _objective,
    _scan,
    _StepEvaluator,
    design_inner_loop,
    motor_design_model,
)
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs import load_scenario

DT = 1e-3  # s, the rotary rig's sampling period


@pytest.fixture(scope="module")
def rotary():
    return SingleLinkModel.from_spec(load_scenario("rotary-flexible-link").arm)


def test_scan_is_the_first_order_recursion():
    """y_k = b y_{k−1} + x_k (y_0 the start) per column, by doubling, equals the recursion
    sample by sample to 1e-14 (rounding of 7 levels of sums of bounded terms, |b| < 1)."""
    rng = np.random.default_rng(3)
    b = np.array([-0.5, 0.0, 0.3, 0.99])
    for length in (1, 2, 5, 82):
        x = rng.normal(size=(length, b.size))
        want = x.copy()
        for k in range(1, length):
            want[k] = b * want[k - 1] + x[k]
        shifts = [1 << i for i in range(7)]
        got = x.copy()
        _scan(got, shifts, [b**s for s in shifts])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-14 * np.abs(want).max())


@pytest.mark.parametrize("delay", [0, 3, 40])
def test_objective_equals_the_old_evaluation(rotary, delay):
    """Candidates drawn over the search's box (stable and unstable loops alike), at three
    gains: the same objective to 1e-9 relative and, per candidate, the same step response
    (θm per unit step) and command to 1e-12 of the old one's scale where it is finite."""
    J, V, K = motor_design_model(rotary)
    horizon = max(0.3, 30 * delay * DT)
    n = math.ceil(horizon / DT)
    new, old = _StepEvaluator(J, V, K, DT, delay, n), OldStepEvaluator(J, V, K, DT, delay, n)
    rng = np.random.default_rng(7)
    p = rng.uniform(-0.5, 0.99, (4, 30))
    for gain in (0.5, 2.0, 5.0):
        c_new = _objective(new, p, gain, 0.02, horizon, 0.0)
        c_old = old_cost(old, p, gain, 0.02, horizon, 0.0)
        np.testing.assert_allclose(c_new, c_old, rtol=1e-9, atol=0.0)
        th_new, u_new = new.run(p, gain)
        th_old, u_old = old.run(p, gain)
        ok = np.all(np.abs(th_old) < 1e3, axis=0)  # the bounded responses
        assert ok.sum() >= 3
        scale = np.max(np.abs(th_old[:, ok]))
        np.testing.assert_allclose(th_new[:, ok], th_old[:, ok], rtol=0, atol=1e-12 * scale)
        uscale = np.max(np.abs(u_old[:, ok]))
        np.testing.assert_allclose(u_new[:, ok], u_old[:, ok], rtol=0, atol=1e-12 * uscale)
        # one candidate alone (the polish) is the same as in the batch, to rounding (BLAS
        # takes another kernel for one column)
        i = int(np.argmax(ok))
        t1, u1 = new.run(p[:, i], gain)
        np.testing.assert_allclose(t1, th_new[:, i], rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(u1, u_new[:, i], rtol=0, atol=1e-12 * uscale)


# The designs the search found before the change (commit 1ee883f), the rotary rig at 1 kHz:
# (delay, G_cm1(1), horizon s, max_overshoot) -> (a1, b1, a2, b2). Delay 2 runs the sample-by-sample
# recursion, 12 the blocks.
BEFORE = {
    (2, 5.0, 0.3, 0.0): [
        0.04039246138467811,
        0.04039250665989945,
        -0.4999926582899527,
        0.9140842961143139,
    ],
    (12, 2.0, 1.0, 0.01): [-0.5, 0.8432228219910629, -0.5, 0.9848783174719364],
}


@pytest.mark.parametrize("key", list(BEFORE))
def test_search_designs_the_same_compensators(rotary, key):
    """The same zeros and poles as before the change. Differential evolution with the same
    seed takes the same steps while every comparison of two costs comes out the same; the
    costs differ by rounding only (above), so they do unless two candidates tie to 1e-14.
    Measured: the same bits; asserted to Nelder–Mead's xatol 1e-7, the optimiser's own
    tolerance on the roots."""
    delay, gain, horizon, overshoot = key
    d = design_inner_loop(
        rotary,
        DT,
        delay,
        dc_gain=gain,
        current_limit=10.0,
        step=0.1,
        bending=0.05,
        coupling_gain=1.2 / 0.128,
        coulomb=0.03,
        horizon=horizon,
        min_root=-0.5,
        max_overshoot=overshoot,
    )
    np.testing.assert_allclose(d.params, BEFORE[key], rtol=0, atol=1e-7)
