"""The stiffer clamp of a gear train pushed stuck (flexarm.models.assembly.SingleLinkBody,
``pushed``): a link on a stuck hub rings at ω_c while the drive torque is below the
threshold, at ω_c √(1 + s) above the full push and at ω_c √(1 + s φ) between, φ the
linear fraction (the undamped clamped link, analytic); with the option off the loop is the
one it was."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from flexarm.sim.integrate import integrate_hold, solver_for
from flexarm.sim.rig_loop import single_link_arm

jax.config.update("jax_enable_x64", True)

WC = 2 * np.pi * 1.8
M = dict(J=0.002, B=0.0, wc2=WC**2, c2z=0.0, JlL=0.015 / 0.45, Fc=0.08, Fs=0.5, bias=0.0)
CONST = dict(
    length=0.45,
    k_u=0.157,
    k_omega=0.0,
    limit=10.0,
    vel_tol=1e-3,
    push_s=0.13,
    push_T=0.03,
    push_T1=0.03,
)


def _ring_hz(u_volt: float, pushed: bool, ramp=None) -> tuple[float, float]:
    """(ringing frequency Hz of the tip deflection, largest |hub angle|) over 5 s from a
    10 mm deflection, the hub at rest, constant command u."""
    arm = single_link_arm(
        {k: jnp.asarray(v) for k, v in M.items()},
        {k: jnp.asarray(v) for k, v in {**CONST, **(ramp or {})}.items()},
        pushed,
    )
    L, h, n = CONST["length"], 5e-4, 10000
    x = jnp.array([0.0, 0.0, 0.01, 0.0])  # theta, omega, y = L theta + w, ydot

    def step(x, _):
        x = integrate_hold(arm, x, jnp.array([u_volt]), h, 1, solver_for("rk4"))
        return x, x

    _, xs = jax.lax.scan(step, x, None, length=n)
    xs = np.asarray(xs)
    w = xs[:, 2] - L * xs[:, 0]
    k = np.nonzero((w[:-1] < 0) & (w[1:] >= 0))[0]
    tc = (k + w[k] / (w[k] - w[k + 1])) * h  # crossings, linearly interpolated
    return (len(tc) - 1) / (tc[-1] - tc[0]), float(np.max(np.abs(xs[:, 0])))


#: a ramp from 0.02 to 0.06 N*m: at 0.3 V (0.0471 N*m) the fraction is 0.6775
RAMP = {"push_T": 0.02, "push_T1": 0.06}


@pytest.mark.parametrize(
    "u, pushed, ramp, factor",
    [
        (0.1, True, None, 1.0),  # 0.0157 N*m < 0.03: light
        (0.3, True, None, np.sqrt(1.13)),  # 0.047 N*m > 0.03: pushed (a step)
        (0.3, False, None, 1.0),  # the option off
        (0.3, True, RAMP, np.sqrt(1 + 0.13 * (0.3 * 0.157 - 0.02) / 0.04)),
        (0.1, True, RAMP, 1.0),  # below the ramp
    ],
)
def test_clamped_link_rings_faster_while_pushed(u, pushed, ramp, factor):
    f, hub = _ring_hz(u, pushed, ramp)
    assert hub == 0.0  # stuck throughout (|tau_a| << F_s)
    # RK4 at h = 0.5 ms on a 1.9 Hz oscillator: phase error ~ (w h)^4 / 120, far below
    # the 1e-4 that interpolated zero crossings over 9 periods resolve
    assert f == pytest.approx(WC / (2 * np.pi) * factor, rel=2e-4), (f, factor)


def test_pushed_stiffening_refused_where_it_cannot_act():
    """One line naming the field, the value and the fix: a joint that cannot stick (LuGre),
    and a multi-link arm (the stiffening is modelled for a single link)."""
    from pydantic import ValidationError

    from flexarm.sim.build import prepare
    from flexarm.specs import load_scenario
    from flexarm.specs.arm import Friction

    with pytest.raises(ValidationError, match="pushed_stiffening 0.1 needs a joint that sticks"):
        Friction(model="lugre", coulomb=0.01, pushed_stiffening=0.1)
    sc = load_scenario("quanser-two-link")
    joints = list(sc.arm.joints)
    fr = joints[0].friction.model_copy(update={"pushed_stiffening": 0.1, "model": "coulomb"})
    joints[0] = joints[0].model_copy(update={"friction": fr})
    sc = sc.model_copy(update={"arm": sc.arm.model_copy(update={"joints": joints})})
    with pytest.raises(ValueError, match="joint 1: friction.pushed_stiffening = 0.1.*single"):
        prepare(sc)
