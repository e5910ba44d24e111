"""Logged disturbances (issue #44 item 2): a scenario's ``[[disturbances]]`` enter the one
sampled loop from a reference-like input array: into the command after the saturation,
or as a force on a joint; a log and a scenario that disagree are refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.io.logformat import log_format_from_dict
from flexarm.io.logs import Log
from flexarm.sim.build import DisturbanceError, disturbance_inputs, simulate
from flexarm.specs.scenario import ScenarioError, scenario_from_dict

J = 0.01  # kg m^2, the rigid hub
KT = 0.5  # N m / A
T = 0.001  # s


def rigid(disturbances, sensors=None, limit=10.0, duration=0.1, controller=None):
    data = {
        "name": "rigid",
        "arm": {
            "motor": {
                "drive": "current",
                "inertia": J,
                "torque_constant": KT,
                "current_limit": limit,
                "viscous": 0.0,
            },
            "friction": {"model": "none"},
            "beam": {"model": "rigid", "length": 0.3},
        },
        "sampling": {"period": T},
        "simulation": {"duration": duration},
        "sensors": sensors or {"motor_angle": {}},
        "disturbances": disturbances,
    }
    if controller is not None:
        data["controller"] = controller
    return scenario_from_dict(data)


def test_pulse_into_the_command_moves_a_rigid_inertia_by_pulse_gain_T_over_J():
    sc = rigid([{"name": "pulse", "into": "command"}])
    n = 101
    pulse = np.zeros(n)
    pulse[10:20] = 2.0  # A, ten samples
    res = simulate(sc, references={"pulse": pulse})
    v = res.signals["motor_velocity"]
    # no controller: Δv = pulse·K_t·(10 T)/J exactly (ZOH, RK4 exact on a constant torque)
    assert v[-1] == pytest.approx(2.0 * KT * 10 * T / J, rel=1e-12)
    # the angle: v ramps over the pulse, then coasts (ZOH integral, exact)
    a = 2.0 * KT / J
    theta_end = 0.5 * a * (10 * T) ** 2 + a * 10 * T * (100 - 20) * T
    assert res.signals["motor_angle"][-1] == pytest.approx(theta_end, rel=1e-12)
    # without the array the disturbance is 0: nothing moves
    assert np.all(simulate(sc).signals["motor_velocity"] == 0.0)


def test_a_command_pulse_enters_after_the_saturation():
    # a P controller on a far setpoint saturates at 1 A; a +0.5 A pulse still adds
    ctrl = {"type": "pd", "kp": 1e6, "kd": 0.0}
    sc = rigid(
        [{"name": "pulse", "into": "command"}],
        sensors={"motor_angle": {}, "current": {}, "current_applied": {}},
        limit=1.0,
        controller=ctrl,
    )
    sc = sc.model_copy(update={"reference": sc.reference.model_copy(update={"amplitude": 100.0})})
    n = 101
    pulse = np.zeros(n)
    pulse[:50] = 0.5
    res = simulate(sc, references={"pulse": pulse})
    v = res.signals["motor_velocity"]
    # 50 samples at 1.5 A, 50 at 1 A (the first sample's command is the controller's too)
    assert v[-1] == pytest.approx(KT * (1.5 * 50 + 1.0 * 50) * T / J, rel=1e-12)
    # the command as a channel: the controller's (saturated) and the applied one
    assert np.all(res.measured["current"] == 1.0)
    assert np.allclose(res.measured["current_applied"], 1.0 + pulse)
    assert np.allclose(res.command[:, 0], 1.0 + pulse)


def test_a_force_disturbance_on_the_joint():
    sc = rigid([{"name": "push", "into": "force"}])
    push = np.zeros(101)
    push[5:25] = -0.3  # N m, twenty samples
    res = simulate(sc, references={"push": push})
    assert res.signals["motor_velocity"][-1] == pytest.approx(-0.3 * 20 * T / J, rel=1e-12)
    assert np.all(res.command == 0.0)  # a force is not a command


def _log(tmp_path, with_pulse: bool, mapped: bool):
    t = np.arange(101) * T
    cols = "t,theta" + (",P" if with_pulse else "")
    rows = [
        f"{a:.6f},0" + (f",{1000.0 * (10 <= k < 20)}" if with_pulse else "")
        for k, a in enumerate(t)
    ]
    p = tmp_path / "run.csv"
    p.write_text(cols + "\n" + "\n".join(rows) + "\n")
    fmt = {"columns": {"time": "t", "motor_angle": "theta"}}
    if mapped:
        fmt["disturbances"] = {"pulse": "P"}
        fmt["units"] = {"pulse": "mA"}
    return log_format_from_dict(fmt, "fmt.toml").read(p)


def test_disturbance_inputs_from_a_log_drive_the_loop(tmp_path):
    log = _log(tmp_path, with_pulse=True, mapped=True)
    assert log.disturbances == ("pulse",)
    sc = rigid([{"name": "pulse", "into": "command"}])
    inputs = disturbance_inputs(sc, log)
    assert np.allclose(inputs["pulse"][10:20], 1.0) and inputs["pulse"].sum() == 10.0
    res = simulate(sc, references=inputs)
    assert res.signals["motor_velocity"][-1] == pytest.approx(1.0 * KT * 10 * T / J, rel=1e-12)


def test_a_log_without_the_declared_column_is_refused_in_one_line(tmp_path):
    log = _log(tmp_path, with_pulse=False, mapped=False)
    sc = rigid([{"name": "pulse", "into": "command"}])
    with pytest.raises(DisturbanceError) as e:
        disturbance_inputs(sc, log)
    msg = str(e.value)
    assert "\n" not in msg
    assert "run.csv" in msg and "'pulse'" in msg and "[disturbances]" in msg


def test_a_log_with_a_disturbance_the_scenario_does_not_declare_is_refused(tmp_path):
    log = _log(tmp_path, with_pulse=True, mapped=True)
    sc = rigid([])
    with pytest.raises(DisturbanceError) as e:
        disturbance_inputs(sc, log)
    msg = str(e.value)
    assert "\n" not in msg
    assert "'pulse'" in msg and "does not declare" in msg and "rigid" in msg


def test_a_disturbance_log_unit_and_a_plain_log_without_any():
    assert disturbance_inputs(rigid([]), Log(None, np.arange(3.0), {"x": np.zeros(3)})) == {}


def test_scenario_checks_on_disturbances():
    with pytest.raises(ScenarioError, match="twice"):
        rigid([{"name": "p", "into": "command"}, {"name": "p", "into": "force"}])
    with pytest.raises(ScenarioError, match="already a reference or sensor channel"):
        rigid([{"name": "reference", "into": "command"}])
    with pytest.raises(ScenarioError, match="joint = 2"):
        rigid([{"name": "p", "into": "force", "joint": 2}])
    with pytest.raises(ScenarioError, match="into"):
        rigid([{"name": "p", "into": "torque"}])
