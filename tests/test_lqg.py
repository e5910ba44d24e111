"""Linear models of assembled arms (flexarm.models.linearize) and the discrete LQG design on
them (flexarm.control.lqg)."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from flexarm.control.lqg import closed_loop_poles, lqg
from flexarm.models.assembly import multi_link_arm
from flexarm.models.linearize import frictionless, linearize
from flexarm.specs.multilink import Hub, Joint, Link, MultiLinkArm


def _torsional_two_link(friction=None) -> MultiLinkArm:
    """A horizontal two-link arm of torsional links with current drives (the kind of the
    two-link rig), numbers of that order."""
    fr = friction or {"model": "coulomb", "coulomb": 0.2, "static": 0.3}
    j = [Joint.model_validate({"drive": {"drive": "current", "torque_constant": k,
                                         "current_limit": lim},
                               "viscous": v, "friction": fr})
         for k, lim, v in ((8.9, 0.94, 4.0), (0.87, 1.2, 1.5))]
    links = [Link(model="torsional", length=0.2, mass=0.6, inertia=0.05,
                  torsional_stiffness=40.0, damping_ratio=0.01),
             Link(model="torsional", length=0.2, mass=0.3, inertia=0.006,
                  torsional_stiffness=6.9, damping_ratio=0.01)]
    return MultiLinkArm(links=links, hubs=[Hub(inertia=0.06), Hub(mass=0.5, inertia=0.003)],
                        gravity=0.0, joints=j)


def test_linearize_is_the_jacobian_of_the_arm():
    """A, B against central finite differences of the frictionless right-hand side
    (step 1e-6: truncation O(h²) ~ 1e-12 relative, round-off ~ 1e-10 of the entries);
    outputs by name; friction left out; the θ columns of A vanish (no stiffness to
    ground in a horizontal plane)."""
    arm, _ = multi_link_arm(_torsional_two_link())
    sys = linearize(arm, outputs=["theta_1", "deflection_angle_1", "theta_2",
                                  "deflection_angle_2"])
    lin = frictionless(arm)
    x0, u0, h = np.zeros(lin.n_states), np.zeros(2), 1e-6
    f = lambda x, u: np.asarray(lin.rhs(jnp.asarray(x), jnp.asarray(u)))  # noqa: E731
    A = np.stack([(f(x0 + h * e, u0) - f(x0 - h * e, u0)) / (2 * h)
                  for e in np.eye(lin.n_states)], 1)
    B = np.stack([(f(x0, u0 + h * e) - f(x0, u0 - h * e)) / (2 * h) for e in np.eye(2)], 1)
    np.testing.assert_allclose(sys.A, A, rtol=1e-6, atol=1e-8 * np.abs(A).max())
    np.testing.assert_allclose(sys.B, B, rtol=1e-6, atol=1e-8 * np.abs(B).max())
    assert list(sys.output_labels) == ["theta_1", "deflection_angle_1", "theta_2",
                                       "deflection_angle_2"]
    assert list(sys.input_labels) == ["current_1", "current_2"]
    np.testing.assert_array_equal(sys.A[:, :2], 0.0)
    # C picks θ and α exactly (they are states of the torsional links)
    np.testing.assert_allclose(sys.C[:, :4], np.eye(4)[[0, 2, 1, 3]], atol=1e-15)
    with pytest.raises(ValueError, match="'tip_z' is not a signal"):
        linearize(arm, outputs=["tip_z"])


def test_one_torsional_link_frequencies():
    """One joint with hub J_h on a torsional link (J_0, K), free hub: the linear model's
    oscillation is ω² = K (J_h + J_0)/(J_h J_0), an integrator pair for the rigid motion."""
    J_h, J0, K = 0.06, 0.05, 40.0
    arm, _ = multi_link_arm(MultiLinkArm(
        links=[Link(model="torsional", length=0.2, mass=0.6, inertia=J0,
                    torsional_stiffness=K)], hubs=[Hub(inertia=J_h)], gravity=0.0,
        joints=[Joint.model_validate({"drive": {"drive": "current", "torque_constant": 1.0}})]))
    ev = np.linalg.eigvals(linearize(arm).A)
    assert np.abs(ev.imag).max() == pytest.approx(math.sqrt(K * (J_h + J0) / (J_h * J0)),
                                                 rel=1e-12)
    assert np.sum(np.abs(ev) < 1e-9) == 2


def test_lqg_separation_and_stability():
    """The closed loop of the sampled design model with the LQG controller has exactly the
    regulator's and the estimator's eigenvalues (separation principle; to 1e-9 of the
    unit circle's scale, the eigenvalue solver's accuracy for a 16 × 16 non-normal matrix),
    all inside the unit circle; the controller is discrete at the period, e → u."""
    arm, _ = multi_link_arm(_torsional_two_link())
    outs = ["theta_1", "deflection_angle_1", "theta_2", "deflection_angle_2"]
    plant = linearize(arm, outputs=outs)
    d = lqg(plant, 0.01, Q=[2500, 2500, 1, 1, 1, 1, 1, 1], R=[10, 10], W=1e-4,
            V=[(1.5e-5) ** 2 / 12, 1e-8, (3e-5) ** 2 / 12, 1e-8])
    assert d.controller.dt == 0.01
    assert list(d.controller.input_labels) == [f"e_{k}" for k in outs]
    assert list(d.controller.output_labels) == ["current_1", "current_2"]
    cl = closed_loop_poles(d)
    want = np.concatenate([d.regulator_poles, d.estimator_poles])
    # pair them one to one (an assignment, not a sort: near-equal real parts reorder)
    rows, cols = linear_sum_assignment(np.abs(cl[:, None] - want[None, :]))
    assert len(cl) == len(want) == 16
    assert np.abs(cl[rows] - want[cols]).max() < 1e-9
    assert np.abs(cl).max() < 1.0
    with pytest.raises(ValueError, match="Q has shape"):
        lqg(plant, 0.01, Q=np.eye(3), R=1, W=1, V=1)
