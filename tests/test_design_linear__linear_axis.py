"""Issue #44: design and C export of a linear axis (``arm.joint = "prismatic"``), end to end
through the command line, in m, N, m/s and A.

The axis is the acceptance test's (tests/test_cli_fit__linear_axis.py): a current-driven
carriage, m = 2.5 kg, viscous 20 N s/m, Coulomb 5 N, offset force −2 N, K_f = 30 N/A, a 3 A
limit, 1 ms sampling with one sample of computation delay, a 1 µm linear scale; the
scenario as a fit writes it (SI numbers), its step 0.05 m.

What is checked against what:

* the lqr design's linear loop, run by flexarm's simulator (friction off, no noise, no
  quantisation), against python-control's own closed loop built here from the design's
  controller matrices and the ZOH-sampled carriage m ẍ = K_f i − c ẋ with the one-sample
  delay: both are exact discretisations of the same linear system (flexarm integrates the
  plant by RK4 on 0.1 ms substeps; its fastest pole is c/m = 8 1/s, local error
  ~ (8e-4)^5 / 120 ≈ 3e-18 of the state), so they agree to rounding: 1e-12 m asserted
  (measured 1.9e-15 m);
* the design's comparison (friction, the offset force, quantisation, noise) settles
  within 10 % of the linear loop's 2 % settling time (python-control's ``step_info``):
  the Coulomb feedforward cancels the 5 N and the observer's disturbance state the −2 N
  offset, so only the friction's switching near rest is left (measured 0.240 s against
  0.240 s);
* the exported C, compiled, against the Python controller stepped over the sequence the
  simulator fed it, and against the simulator's applied command one sample later: 1e-9 A
  (same operations in the same order: the C export's own tests find ≤ 1e-12 in command
  units).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import control
import jax
import numpy as np
import pytest

import flexarm
from _helpers import CC, run_c
from flexarm.identification.time_domain.result import drop_none
from flexarm.io.write import write_toml
from flexarm.sim.build import prepare
from flexarm.specs import load_scenario
from flexarm.specs.scenario import scenario_from_dict

CLI = [sys.executable, "-m", "flexarm"]
M, VISCOUS, KF, T = 2.5, 20.0, 30.0, 1e-3
STEP = 0.05  # m


def axis_dict(quantum: float | None = 1e-6) -> dict:
    """The linear axis as a fit's ``--scenario-out`` holds it (SI numbers)."""
    return {
        "name": "linear-axis",
        "arm": {
            "joint": "prismatic",
            "motor": {
                "drive": "current",
                "inertia": M,
                "torque_constant": KF,
                "current_limit": 3.0,
                "viscous": VISCOUS,
            },
            "friction": {"model": "coulomb", "coulomb": 5.0, "bias": -2.0},
            "beam": {"model": "rigid", "length": 1.0},
        },
        "sampling": {"period": T, "delay": 1},
        "simulation": {"duration": 1.5, "seed": 0},
        "sensors": {
            "motor_angle": {"noise": 2e-7, **({"quantum": quantum} if quantum else {})},
            "current": {"noise": 0.005},
        },
        "reference": {"type": "step", "amplitude": STEP},
        "controller": {"type": "pd", "kp": 50.0, "kd": 2.0},
        "disturbances": [{"name": "pulse", "into": "command"}],
    }


def _write(path: Path, d: dict) -> Path:
    write_toml(path, drop_none(scenario_from_dict(d).model_dump(mode="json")))
    return path


def _cli(*args, ok: bool = True) -> subprocess.CompletedProcess:
    r = subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True)
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, r.stderr[-3000:]
    if ok:
        assert r.returncode == 0, (r.stdout[-3000:], r.stderr[-3000:])
    return r


@pytest.fixture(scope="module")
def designed(tmp_path_factory) -> Path:
    """``flexarm design AXIS --method lqr`` (default weights), its folder."""
    tmp = tmp_path_factory.mktemp("axis")
    sc = _write(tmp / "axis.toml", axis_dict())
    r = _cli("design", sc, "--method", "lqr", "--out", tmp / "lqr")
    (tmp / "stdout.txt").write_text(r.stdout)
    return tmp / "lqr"


def _python_closed_loop(ctrl: dict, n: int) -> tuple[control.StateSpace, np.ndarray]:
    """python-control's closed loop r → x of the carriage (ZOH at T), the one-sample
    computation delay and the design's LTI block (e = [0 − x, r − x]); its step of STEP."""
    P = control.c2d(
        control.ss([[0, 1], [0, -VISCOUS / M]], [[0], [KF / M]], [[1, 0]], [[0]]), T, "zoh"
    )
    Ac, Bc, Cc, Dc = (np.array(ctrl[k], float) for k in "ABCD")
    assert ctrl["inputs"] == ["motor_angle", "motor_angle"]
    assert ctrl["setpoints"] == [0.0, "reference"]
    nc = Ac.shape[0]
    Ey, Er = -np.ones((2, 1)) @ P.C, np.array([[0.0], [1.0]])
    A, B = np.zeros((3 + nc, 3 + nc)), np.zeros((3 + nc, 1))
    A[0:2, 0:2], A[0:2, 2:3] = P.A, P.B  # the carriage, driven by the delayed command
    A[2:3, 0:2], A[2:3, 3:], B[2:3] = Dc @ Ey, Cc, Dc @ Er  # the delay register
    A[3:, 0:2], A[3:, 3:], B[3:] = Bc @ Ey, Ac, Bc @ Er  # the controller's state
    cl = control.ss(A, B, np.hstack([P.C, np.zeros((1, 1 + nc))]), [[0.0]], T)
    out = control.forced_response(cl, T=np.arange(n) * T, U=STEP * np.ones(n))
    return cl, np.asarray(out.outputs).ravel()


def test_lqr_design_of_a_linear_axis_is_its_linear_loop_in_metres(designed):
    out = (designed.parent / "stdout.txt").read_text()
    assert f"a {STEP:g} m step" in out and " rad" not in out, out
    assert "peak command [A]" in out and "position ss error [counts]" in out, out
    doc = json.loads((designed / "design.json").read_text())
    assert doc["verdict"] == "stable", doc["verdict"]
    cmp = json.loads((designed / "compare.json").read_text())
    assert cmp["settings"]["units"] == {"position": "m", "command": "A"}
    assert cmp["settings"]["step"] == STEP and cmp["settings"]["count_rad"] == 1e-6

    # the designed loop, linear: flexarm's simulator against python-control's closed loop
    d = load_scenario(designed / "design.toml").model_dump(mode="json", exclude_none=True)
    assert d["arm"]["joint"] == "prismatic" and d["reference"]["amplitude"] == STEP
    d["arm"]["friction"] = {"model": "none"}
    d["controller"].pop("friction_compensation")
    d.pop("disturbances")
    for s in d["sensors"].values():
        s.update(noise=0.0, quantum=0.0)
    d["reference"].update(start=0.0)
    d["simulation"]["duration"] = 1.0
    res = flexarm.simulate(scenario_from_dict(d))
    x = np.asarray(res["motor_angle"])
    cl, x_pc = _python_closed_loop(d["controller"], x.size)
    print(f"flexarm vs python-control closed loop: max |dx| = {np.abs(x - x_pc).max():.3g} m")
    assert np.abs(x - x_pc).max() <= 1e-12
    assert np.max(np.abs(cl.poles())) < 1.0
    info = control.step_info(cl, T=np.arange(x.size) * T, SettlingTimeThreshold=0.02)
    ts_lin = info["SettlingTime"]

    # the comparison's run, with friction, the offset force, the 1 µm scale and noise
    lqr = cmp["rows"]["lqr"]["nominal"]
    print(f"settling: linear {ts_lin:.3f} s, with friction {lqr['tip_settling_s']:.3f} s")
    print(f"position error at the end: {lqr['hub_error_counts']:.3g} counts of 1 µm")
    assert abs(lqr["tip_settling_s"] - ts_lin) <= 0.1 * ts_lin
    assert lqr["hub_error_counts"] * 1e-6 < 0.02 * STEP  # inside the settling band
    assert lqr["peak_command_V"] < 3.0 and lqr["time_at_limit_s"] == 0.0  # A


@pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on PATH")
def test_exported_c_of_the_linear_axis_design_steps_as_the_python_loop(designed, tmp_path):
    r = _cli("export-c", designed, "--out", tmp_path, "--name", "ctl")
    head = json.loads(r.stdout)
    assert head["measured"] == ["motor_angle (m)"] and head["reference"] == ["reference (m)"]
    assert head["u"] == ["current (A)"]
    h = (tmp_path / "ctl.h").read_text()
    assert "motor_angle  (m)" in h and "(rad)" not in h

    # the sequence the simulator fed the controller: a run of the design with friction,
    # the offset force, the 1 µm scale and noise (the friction feedforward switches)
    sc = load_scenario(designed / "design.toml")
    n = int(round(sc.simulation.duration / T)) + 1
    res = flexarm.simulate(sc, references={"pulse": np.zeros(n)})
    meas = np.asarray(res.measured["motor_angle"])
    ref = np.asarray(res.references["reference"])
    ctrl = prepare(sc, None, {"pulse": np.zeros(n)}).loop.controller

    def body(state, inp):
        new, u = ctrl.step(state, {"motor_angle": inp[0]}, {"reference": inp[1]})
        return new, u

    _, y = jax.jit(lambda c: jax.lax.scan(body, c, (meas, ref)))(ctrl.init())
    u_py = np.clip(np.asarray(y).ravel(), -3.0, 3.0)

    u_c = run_c(tmp_path, {"motor_angle": meas}, {"reference": ref}).ravel()
    applied = np.asarray(res.command).ravel()
    print(
        f"C vs Python step: max |du| = {np.abs(u_c - u_py).max():.3g} A; C vs the simulator's "
        f"applied command (one sample later): {np.abs(u_c[:-1] - applied[1:]).max():.3g} A; "
        f"peak {np.abs(u_c).max():.3g} A"
    )
    assert np.abs(u_c - u_py).max() <= 1e-9
    assert np.abs(u_c[:-1] - applied[1:]).max() <= 1e-9  # delay = 1 sample
    assert np.ptp(u_c) > 1.0  # the step moved the command (not a trivial sequence)


def test_linear_axis_design_errors_name_metres(tmp_path):
    """One line each, exit 2: a scale unknown (m per count), --encoder-counts (per turn)
    on a linear axis, Feliu's nested loops on a rigid carriage."""
    bare = _write(tmp_path / "bare.toml", axis_dict(quantum=None))
    r = _cli("design", bare, "--out", tmp_path / "a", ok=False)
    assert r.returncode == 2 and "m per count" in r.stderr, r.stderr
    sc = _write(tmp_path / "axis.toml", axis_dict())
    r = _cli("design", sc, "--encoder-counts", "4096", "--out", tmp_path / "b", ok=False)
    assert r.returncode == 2 and "linear axis" in r.stderr and "quantum" in r.stderr, r.stderr
    r = _cli("design", sc, "--method", "nested", "--out", tmp_path / "c", ok=False)
    assert r.returncode == 2 and "linear axis" in r.stderr and "'lqr'" in r.stderr, r.stderr
