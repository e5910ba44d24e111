"""Scenario files: units, SI storage, and errors that name field, value and fix."""

import copy
import tomllib

import pytest

from flexarm.specs import ScenarioError, builtin_scenarios, load_scenario, scenario_from_dict
from flexarm.units import LBF_IN, UnitError, to_si


def base() -> dict:
    path = builtin_scenarios()["feliu-single-mass"]
    return tomllib.loads(path.read_text())


def test_paper_units_convert_to_si():
    assert to_si("0.005529 lbf*in*s**2", "kg*m**2") == pytest.approx(0.005529 * LBF_IN, rel=1e-12)
    assert to_si("7 in", "m") == pytest.approx(0.1778, rel=1e-12)
    assert to_si("55 g", "kg") == pytest.approx(0.055)
    assert to_si("400 mrad", "rad") == pytest.approx(0.4)
    assert to_si("360 deg", "") == pytest.approx(6.283185307179586)
    assert to_si(3.5, "m") == 3.5  # bare numbers are SI


def test_builtin_scenario_is_stored_in_si():
    sc = load_scenario("feliu-single-mass")
    assert sc.arm.motor.inertia == pytest.approx(6.2469e-4, rel=1e-4)  # reference note
    assert sc.arm.motor.viscous == pytest.approx(1.3739e-3, rel=1e-4)
    assert sc.arm.motor.torque_constant == pytest.approx(0.24676, rel=1e-4)
    assert sc.arm.friction.coulomb / sc.arm.motor.torque_constant == pytest.approx(0.132, rel=1e-9)
    assert sc.sampling.period == pytest.approx(0.003)
    assert sc.arm.beam.length == pytest.approx(0.1778)


def _error(data) -> str:
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict(data, source="test.toml")
    return str(exc.value)


def test_missing_field_is_named():
    d = base()
    del d["arm"]["motor"]["inertia"]
    msg = _error(d)
    assert "arm.motor.inertia" in msg and "missing" in msg


@pytest.mark.parametrize("value", ["-1 kg*m**2", 0.0, "0 lbf*in*s**2"])
def test_non_positive_inertia(value):
    d = base()
    d["arm"]["motor"]["inertia"] = value
    msg = _error(d)
    assert "arm.motor.inertia" in msg and "must be > 0" in msg and str(value).split()[0] in msg


def test_non_positive_stiffness():
    d = base()
    d["arm"]["beam"] = {
        "model": "lumped",
        "length": "7 in",
        "flexural_rigidity": "-2 N*m**2",
        "masses": [{"mass": "55 g"}],
    }
    msg = _error(d)
    assert "arm.beam.lumped.flexural_rigidity" in msg or "flexural_rigidity" in msg
    assert "must be > 0" in msg


def test_unit_that_does_not_fit_the_field():
    d = base()
    d["arm"]["beam"]["length"] = "3 kg"
    msg = _error(d)
    assert "length" in msg and "'3 kg'" in msg and "expects m" in msg


def test_unknown_key_is_named():
    d = base()
    d["arm"]["motor"]["inertiaa"] = 1.0
    msg = _error(d)
    assert "inertiaa" in msg and "unknown key" in msg


@pytest.mark.parametrize("period", [0.0, "-3 ms"])
def test_sample_period_must_be_positive(period):
    d = base()
    d["sampling"]["period"] = period
    msg = _error(d)
    assert "sampling.period" in msg and "must be > 0" in msg


def test_unknown_sensor_and_garbage_quantity():
    d = base()
    d["sensors"]["elbow_angle"] = {"bits": 12}
    assert "elbow_angle" in _error(d)
    d = base()
    d["arm"]["motor"]["inertia"] = "fast"
    msg = _error(d)
    assert "arm.motor.inertia" in msg and "fast" in msg
    with pytest.raises(UnitError):
        to_si(float("nan"), "m")


def test_breakaway_below_coulomb_rejected():
    d = copy.deepcopy(base())
    d["arm"]["friction"]["static"] = "0.1 lbf*in"
    assert "breakaway must be >= coulomb" in _error(d)


def test_file_errors(tmp_path):
    with pytest.raises(ScenarioError, match="no such file"):
        load_scenario(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[arm\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(bad)
