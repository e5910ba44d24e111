"""Feliu's Coulomb friction compensation (FRB Sec. III-B) on any feedback controller:
the sign rule, and a scenario's ``[controller.friction_compensation]``."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import flexarm
from flexarm.control import discrete
from flexarm.control.friction_compensation import friction_compensated, friction_sign
from flexarm.specs.scenario import scenario_from_dict


def test_sign_rule():
    # moving: the velocity's sign; at rest: the feedback's sign beyond the deadband; else 0
    v = jnp.array([2.0, -2.0, 0.05, 0.05, -0.05])
    u = jnp.array([-1.0, 1.0, -0.3, 0.01, 0.3])
    s = friction_sign(v, u, 0.1, 0.02)
    np.testing.assert_array_equal(np.asarray(s), [1.0, -1.0, -1.0, 0.0, 1.0])


def test_wrapper_adds_level_times_sign():
    # a static gain 2 on e = r − θ; level 0.5; θ steps by 0.01 rad per 1 ms sample (10 rad/s)
    fb = discrete.pd(2.0, 0.0, 1e-3)
    c = friction_compensated(fb, 0.5, dt=1e-3, quantum=1e-3)
    st = c.init()
    us = []
    for _k, th in enumerate([0.0, 0.01, 0.02, 0.02]):
        st, u = c.step(st, {"motor_angle": jnp.asarray(th)}, {"reference": jnp.asarray(1.0)})
        us.append(float(u[0]))
    fb_u = [2.0 * (1.0 - th) for th in (0.0, 0.01, 0.02, 0.02)]
    # first sample at rest (no kick): σ = sgn u_fb = +1; then moving +; then at rest, u_fb > 0
    np.testing.assert_allclose(us, [f + 0.5 for f in fb_u], rtol=0, atol=1e-15)
    assert float(c.velocity_deadband[0]) == pytest.approx(0.5)  # half a count per sample


def _rotary(compensate: bool):
    sc = flexarm.load_scenario("rotary-flexible-link")
    d = sc.model_dump(mode="json", exclude_none=True)
    d["simulation"]["duration"] = 3.0
    d["reference"] = {"type": "step", "amplitude": 0.3, "start": 0.1}
    m = d["arm"]["motor"]
    k_u = (
        m["gear_efficiency"]
        * m["motor_efficiency"]
        * m["gear_ratio"]
        * m["motor_constant"]
        / m["armature_resistance"]
    )  # N·m per V at stall
    if compensate:
        d["controller"]["friction_compensation"] = {"level": d["arm"]["friction"]["coulomb"] / k_u}
    return flexarm.simulate(scenario_from_dict(d)), d, k_u


def test_scenario_friction_compensation_removes_the_stiction_offset():
    (r0, d, k_u), (r1, _, _) = _rotary(False), _rotary(True)
    q = 2 * np.pi / 4096
    e0 = 0.3 - float(np.asarray(r0.outputs)[0, -1])
    e1 = 0.3 - float(np.asarray(r1.outputs)[0, -1])
    # without compensation the hub sticks where the feedback torque k1 k_u |e| (the link at
    # rest) no longer exceeds the static friction F_s: |e| <= F_s / (k1 k_u) + one count
    band = d["arm"]["friction"]["static"] / (d["controller"]["k1"] * k_u)
    assert 2 * q < abs(e0) <= band + q, (e0 / q, band / q)
    # with the compensation the feedback needs only to exceed F_s − C_f: the band shrinks
    # by C_f / F_s (= 0.75 here) and the compensation pushes the last counts
    assert (
        abs(e1)
        <= (d["arm"]["friction"]["static"] - d["arm"]["friction"]["coulomb"])
        / (d["controller"]["k1"] * k_u)
        + q
    ), e1 / q
