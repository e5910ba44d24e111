"""The scenario: one arm, one experiment, one controller, read from TOML.

:func:`load_scenario` turns every validation problem into a :class:`ScenarioError`
whose lines name the field, the value given and what is expected.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError, model_validator

from flexarm.specs.arm import SingleLinkArm
from flexarm.specs.experiment import (
    Actuator,
    ControllerSpec,
    Initial,
    Reference,
    Sampling,
    Sensor,
    Simulation,
)
from flexarm.specs.multilink import JointPDController, MultiLinkArm
from flexarm.specs.quantity import Q, Spec

KNOWN_SENSORS = ("motor_angle", "tip_angle", "tip_deflection", "motor_velocity")


class ScenarioError(ValueError):
    """A scenario that cannot be used, with one line per problem."""


class RegulationSpec(Spec):
    """Regulation of a multi-link arm (De Luca & Siciliano) by a continuous-time law.

    ``law``: ``constant`` (eq. 8, g_θ at the target), ``online`` (eq. 30, g_θ at the
    measured θ, δ) or ``quasistatic`` (eq. 30, g_θ at θ and the quasi-static δ̄(θ)).
    ``interpolation_time`` > 0 moves the reference from ``initial`` to ``target`` along a
    quintic in that time (the paper's remedy for large gains and large initial errors)."""

    target: list[Q("rad")]
    initial: list[Q("rad")]
    kp: list[Q("N*m/rad", gt=0)]
    kd: list[Q("N*m*s/rad", ge=0)]
    law: Literal["constant", "online", "quasistatic"] = "constant"
    duration: Q("s", gt=0) = 3.0
    step: Q("s", gt=0) = 1e-4
    output_period: Q("s", gt=0) = 1e-3
    interpolation_time: Q("s", ge=0) = 0.0

    @model_validator(mode="after")
    def _sizes(self) -> "RegulationSpec":
        n = len(self.target)
        for name in ("initial", "kp", "kd"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"{name} has {len(getattr(self, name))} entries; target has {n} "
                                 "(one per joint)")
        return self


Arm = Annotated[SingleLinkArm | MultiLinkArm, Field(discriminator="kind")]


class Scenario(Spec):
    """A full scenario: one arm (``arm.kind = "single_link"`` or ``"multi_link"``), the
    experiment and the controller.

    Sections: ``arm``; for the sampled-data loop ``sampling``, ``sensors``, ``actuator``,
    ``simulation``, ``initial``, ``reference`` (the channel ``reference``) and
    ``references`` (more named channels, e.g. ``theta_ref_1``), ``controller``; for a
    multi-link arm under a continuous-time law, ``regulation`` (DLS eqs. 8, 30). Sensor
    channels are named after the arm's signals (:attr:`flexarm.sim.plant.Plant.signal_names`;
    a single link: ``motor_angle``, ``tip_angle``, ``tip_deflection``, ``motor_velocity``;
    several links: ``theta_i``, ``theta_dot_i``, ``deflection_i``, ``deflection_angle_i``,
    ``tip_x``, ``tip_y``, ...)."""

    name: str = "scenario"
    description: str = ""
    notes: dict[str, Any] = Field(default_factory=dict)
    arm: Arm
    sampling: Sampling | None = None
    sensors: dict[str, Sensor] = Field(default_factory=dict)
    actuator: Actuator = Actuator()
    simulation: Simulation | None = None
    initial: Initial = Initial()
    reference: Reference = Reference()
    references: dict[str, Reference] = Field(default_factory=dict)
    controller: Annotated[ControllerSpec | JointPDController, Field(discriminator="type")] | None = None
    regulation: RegulationSpec | None = None

    @property
    def n_joints(self) -> int:
        return 1 if self.arm.kind == "single_link" else len(self.arm.links)

    @model_validator(mode="after")
    def _check_names(self) -> "Scenario":
        if self.arm.kind == "single_link":
            for name in ("sampling", "simulation"):
                if getattr(self, name) is None:
                    raise ValueError(f"[{name}] is missing; a single-link scenario needs "
                                     "[sampling] (period) and [simulation] (duration)")
            if self.regulation is not None:
                raise ValueError("[regulation] is the multi-link continuous-time law; a "
                                 "single-link arm takes a [controller]")
            for name, sensor in self.sensors.items():
                if (sensor.signal or name) not in KNOWN_SENSORS:
                    raise ValueError(
                        f"unknown sensor channel {name!r}"
                        + (f" (signal {sensor.signal!r})" if sensor.signal else "")
                        + f"; known signals: {', '.join(KNOWN_SENSORS)}"
                    )
            m = getattr(self.controller, "measured", None)
            if isinstance(m, str) and m not in KNOWN_SENSORS:
                raise ValueError(
                    f"controller.measured = {m!r} is not a signal; "
                    f"choose one of {', '.join(KNOWN_SENSORS)}"
                )
            return self
        n = len(self.arm.links)
        if self.regulation is not None and len(self.regulation.target) != n:
            raise ValueError(f"regulation.target has {len(self.regulation.target)} joints; the arm "
                             f"has {n} links")
        if (self.sampling is None) != (self.simulation is None):
            raise ValueError("give [sampling] and [simulation] together (the sampled-data loop)")
        if self.sampling is None and self.controller is not None:
            raise ValueError("a [controller] runs in the sampled-data loop: give [sampling] "
                             "(period) and [simulation] (duration)")
        for name in ("joint_angles", "joint_velocities"):
            v = getattr(self.initial, name)
            if v is not None and len(v) != n:
                raise ValueError(f"initial.{name} has {len(v)} values; the arm has {n} joints")
        return self

    def __repr__(self) -> str:
        """A short table (name, arm, drive, beam, sampling, controller); the full
        specification is ``model_dump()``."""
        return _scenario_table(self).text()

    def _repr_html_(self) -> str:
        return _scenario_table(self).html()


def _scenario_table(sc: "Scenario"):
    """The rows of :meth:`Scenario.__repr__` (:class:`flexarm.display.Table`)."""
    from flexarm.display import Table

    arm = sc.arm
    rows: list[tuple[str, object]] = [("description", sc.description or None)]
    if arm.kind == "single_link":
        motor = arm.motor
        rows += [("arm", "single link"),
                 ("drive", f"{motor.drive}, J = {motor.inertia:.4g} kg*m**2"),
                 ("beam", getattr(arm.beam, "model", None)),
                 ("friction", f"Coulomb {arm.friction.coulomb:.4g} N*m"
                  if getattr(arm.friction, "coulomb", None) is not None else None)]
    else:
        rows.append(("arm", f"{len(arm.links)} links"))
    if sc.sampling is not None:
        rows.append(("sampling", f"period {sc.sampling.period:.4g} s"))
    if sc.simulation is not None:
        rows.append(("duration", f"{sc.simulation.duration:.4g} s"))
    rows.append(("controller", None if sc.controller is None else sc.controller.type))
    if sc.regulation is not None:
        rows.append(("regulation", f"{sc.regulation.law}, {sc.regulation.duration:.4g} s"))
    return Table(f"Scenario {sc.name!r}", rows)


#: The multi-link scenario is the same class (kept for code written against it).
MultiLinkScenario = Scenario


def _format_errors(err: ValidationError, source: str, what: str = "scenario") -> str:
    lines = [f"{source}: {err.error_count()} problem(s) in the {what}"]
    for e in err.errors():
        loc = ".".join(str(p) for p in e["loc"] if not _is_union_tag(p))
        kind = e["type"]
        if kind == "missing":
            lines.append(f"  {loc}: missing; this field is required")
        elif kind == "extra_forbidden":
            lines.append(
                f"  {loc}: unknown key (value {e.get('input')!r}); "
                "check its spelling against the documented fields"
            )
        elif kind == "union_tag_invalid":
            ctx = e.get("ctx", {})
            lines.append(
                f"  {loc}: {ctx.get('discriminator', 'type')} = {ctx.get('tag')!r} is not "
                f"known; expected one of {ctx.get('expected_tags')}"
            )
        else:
            msg = e["msg"].removeprefix("Value error, ")
            given = e.get("input")
            if isinstance(given, (str, int, float)) and repr(given) not in msg:
                msg = f"got {given!r}: {msg}"
            lines.append(f"  {loc}: {msg}")
    return "\n".join(lines)


def _is_union_tag(p: object) -> bool:
    return isinstance(p, str) and p in {"current", "voltage", "torque", "lumped",
                                        "transfer_function", "rigid", "pd", "pid", "lead", "tf",
                                        "state_feedback", "joint_pd", "lti", "nested", "single_link",
                                        "multi_link"}


def scenario_from_dict(data: dict[str, Any], source: str = "scenario"
                       ) -> Scenario | MultiLinkScenario:
    """Validate a scenario given as a dict (as parsed from TOML); ``arm.kind`` picks a
    single-link :class:`Scenario` or a :class:`MultiLinkScenario`."""
    if isinstance(data, dict) and isinstance(data.get("arm"), dict) and "kind" not in data["arm"]:
        # an arm with links is a multi-link arm; otherwise the single link (motor + beam)
        kind = "multi_link" if "links" in data["arm"] else "single_link"
        data = {**data, "arm": {**data["arm"], "kind": kind}}
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(_format_errors(err, source)) from None


def builtin_scenarios() -> dict[str, Path]:
    """Names and paths of the scenarios shipped with flexarm."""
    folder = resources.files("flexarm") / "scenarios"
    return {p.name.removesuffix(".toml"): Path(str(p)) for p in folder.iterdir()
            if p.name.endswith(".toml")}


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A file path, or the name of a built-in scenario."""
    p = Path(name_or_path)
    if p.exists():
        return p
    builtin = builtin_scenarios()
    if str(name_or_path) in builtin:
        return builtin[str(name_or_path)]
    raise ScenarioError(
        f"{name_or_path}: no such file, and not a built-in scenario "
        f"(built-in: {', '.join(sorted(builtin))})"
    )


def load_scenario(name_or_path: str | Path) -> Scenario | MultiLinkScenario:
    """Read and validate a scenario TOML file (or a built-in scenario by name)."""
    path = resolve_scenario_path(name_or_path)
    if path.is_dir():
        raise ScenarioError(f"{path}: is a folder; give a scenario TOML file or a built-in "
                            "name (flexarm scenarios lists them)")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{path}: not a text file in UTF-8 (byte {exc.start}: "
                            f"{exc.object[exc.start:exc.start + 1]!r}); a scenario is a TOML "
                            "text file") from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    return scenario_from_dict(data, source=str(path))


def names_a_scenario(x: Any) -> bool:
    """Whether ``x`` is a scenario or names one (a ``.toml`` path or a built-in name), as
    the first argument of ``fit`` / ``validate`` and of ``flexarm fit`` (where logs are the
    alternative)."""
    if isinstance(x, Scenario):
        return True
    if isinstance(x, (str, Path)):
        return str(x).endswith(".toml") or str(x) in builtin_scenarios()
    return False
