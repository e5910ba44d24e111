"""Validated specs of arms and experiments (SI inside); TOML scenario files."""

from flexarm.specs.arm import (
    CurrentMotor,
    Friction,
    LumpedBeam,
    PointMass,
    RigidBeam,
    SingleLinkArm,
    TransferFunctionBeam,
    VoltageMotor,
)
from flexarm.specs.experiment import Actuator, Initial, Reference, Sampling, Sensor, Simulation
from flexarm.specs.scenario import (
    Scenario,
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    scenario_from_dict,
)

__all__ = [
    "Actuator",
    "CurrentMotor",
    "Friction",
    "Initial",
    "LumpedBeam",
    "PointMass",
    "Reference",
    "RigidBeam",
    "Sampling",
    "Scenario",
    "ScenarioError",
    "Sensor",
    "Simulation",
    "SingleLinkArm",
    "TransferFunctionBeam",
    "VoltageMotor",
    "builtin_scenarios",
    "load_scenario",
    "scenario_from_dict",
]
