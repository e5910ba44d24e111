"""A linear axis (issue #44 item 1): a prismatic joint, positions in m, forces in N,
masses in kg, viscous N s/m, through specs, models, simulation, ``flexarm info`` and
log-format units (``m``, ``mm``, ``um``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexarm.analysis.model_info import single_link_info
from flexarm.io.logformat import LogFormatError, log_format_from_dict
from flexarm.models.single_link import SingleLinkModel
from flexarm.sim.build import simulate
from flexarm.specs.scenario import ScenarioError, scenario_from_dict

M, KF, V = 2.5, 30.0, 20.0  # kg, N/A, N s/m


def axis(**extra):
    data = {
        "name": "axis",
        "arm": {
            "joint": "prismatic",
            "motor": {
                "drive": "current",
                "inertia": f"{M} kg",
                "torque_constant": f"{KF} N/A",
                "current_limit": 10.0,
                "viscous": f"{V} N*s/m",
            },
            "friction": {"model": "coulomb", "coulomb": "5 N", "bias": "-2 N"},
            "beam": {"model": "rigid", "length": 1.0, "masses": [{"mass": 0.5}]},
        },
        "sampling": {"period": 0.001},
        "simulation": {"duration": 0.2},
        "sensors": {"motor_angle": {}, "current": {}},
        "initial": {"motor_angle": "12 mm"},
        "reference": {"type": "step", "amplitude": "50 mm"},
    }
    data.update(extra)
    return scenario_from_dict(data)


def test_a_prismatic_axis_reads_linear_units():
    sc = axis()
    assert sc.prismatic
    assert sc.arm.motor.inertia == M and sc.arm.motor.torque_constant == KF
    assert sc.arm.motor.viscous == V
    assert sc.arm.friction.coulomb == 5.0 and sc.arm.friction.bias == -2.0
    assert sc.initial.motor_angle == pytest.approx(0.012, rel=1e-15)
    assert sc.reference.amplitude == pytest.approx(0.05, rel=1e-15)
    model = SingleLinkModel.from_spec(sc.arm)
    assert model.J == M + 0.5  # the carriage's masses move with it (kg), not m r²


def test_info_on_a_linear_axis():
    info = single_link_info(SingleLinkModel.from_spec(axis().arm))
    assert info["joint"] == "prismatic"
    assert info["axis"]["mass_kg"] == M + 0.5
    assert info["friction"]["offset_force_N"] == -2.0
    g = info["transfer_functions"]["motor"]
    # G_m = K_f / (m s² + V s): the integrator's gain K_f / V m/(A s), the pole V / m
    assert g["static_gain"] == pytest.approx(KF / V, rel=1e-12)
    assert g["natural_frequencies_rad_s"][0]["wn_rad_s"] == pytest.approx(V / (M + 0.5))
    json.dumps(info)


def test_a_force_pulse_moves_the_carriage_by_the_analytic_amount():
    """No friction, no viscous: a 2 A pulse for 10 samples adds K_f·2 A·10T/m m/s."""
    sc = axis(
        arm={
            "joint": "prismatic",
            "motor": {
                "drive": "current",
                "inertia": f"{M} kg",
                "torque_constant": f"{KF} N/A",
                "current_limit": 10.0,
            },
            "friction": {"model": "none"},
        },
        disturbances=[{"name": "pulse", "into": "command"}],
        initial={},
    )
    pulse = np.zeros(201)
    pulse[:10] = 2.0
    res = simulate(sc, references={"pulse": pulse})
    assert res.signals["motor_velocity"][-1] == pytest.approx(KF * 2.0 * 10 * 1e-3 / M, rel=1e-12)


def test_units_of_another_kind_and_a_flexible_carriage_are_refused():
    with pytest.raises(ScenarioError, match="prismatic joint's inertia is in kg"):
        axis(
            arm={
                "joint": "prismatic",
                "motor": {
                    "drive": "current",
                    "inertia": "2 kg*m**2",
                    "torque_constant": 1.0,
                    "current_limit": 1.0,
                },
            }
        )
    with pytest.raises(ScenarioError, match="rigid carriage"):
        axis(
            arm={
                "joint": "prismatic",
                "motor": {
                    "drive": "current",
                    "inertia": 1,
                    "torque_constant": 1.0,
                    "current_limit": 1.0,
                },
                "beam": {
                    "model": "lumped",
                    "length": 0.5,
                    "flexural_rigidity": 1.0,
                    "masses": [{"mass": 0.1}],
                },
            }
        )


@pytest.mark.parametrize("unit, factor", [("m", 1.0), ("mm", 1e-3), ("um", 1e-6)])
def test_a_log_format_reads_positions_in_m_mm_um(tmp_path, unit, factor):
    p = tmp_path / "axis.csv"
    t = np.arange(20) * 1e-3
    p.write_text("t,x,v,F\n" + "\n".join(f"{a},{1000 * a},{2.0},{3.0}" for a in t))
    fmt = log_format_from_dict(
        {
            "columns": {"time": "t", "motor_angle": "x", "motor_velocity": "v", "torque_1": "F"},
            "units": {"motor_angle": unit, "motor_velocity": f"{unit}/s", "torque_1": "N"},
        }
    )
    log = fmt.read(p)
    assert np.allclose(log["motor_angle"], 1000 * t * factor, rtol=1e-14, atol=0)
    assert np.all(log["motor_velocity"] == 2.0 * factor)
    assert np.all(log["torque_1"] == 3.0)
    with pytest.raises(LogFormatError, match="does not convert to rad.*linear axis, m"):
        log_format_from_dict({"columns": {"motor_angle": 1}, "units": {"motor_angle": "kg"}})
