"""The scenario: one arm, one experiment, one controller, read from TOML.

:func:`load_scenario` turns every validation problem into a :class:`ScenarioError`
whose lines name the field, the value given and what is expected.
"""

# Field types built by calls (Q("rad", gt=0), Count(...), Coefficients(...)) are what
# pydantic reads at runtime; a static checker cannot take a call as a type, so pyright's
# invalid-type-form check is off for this module (flexarm.specs.quantity).
# pyright: reportInvalidTypeForm=false

from __future__ import annotations

import re
import tomllib
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError, model_validator

from flexarm.errors import FlexarmError
from flexarm.specs.arm import SingleLinkArm, prismatic_values
from flexarm.specs.experiment import (
    Actuator,
    ControllerSpec,
    Disturbance,
    Initial,
    Reference,
    Sampling,
    Sensor,
    Simulation,
)
from flexarm.specs.multilink import JointPDController, MultiLinkArm
from flexarm.specs.quantity import Q, Spec

KNOWN_SENSORS = ("motor_angle", "tip_angle", "tip_deflection", "motor_velocity")
#: the drive's command as a measured channel (:class:`flexarm.sim.sampled.Sensors`): the
#: controller's command after saturation and D/A (``current``, ``voltage``; ``torque_j``,
#: ``current_j``, ``voltage_j`` on several joints), and with ``_applied`` the command the
#: drive receives, the ``into = "command"`` disturbances added
COMMAND_SIGNALS = ("current", "voltage", "current_applied", "voltage_applied")
#: plant signals of a multi-link arm (:func:`flexarm.models.multilink.signal_names`)
_MULTI_SIGNAL = re.compile(
    r"(theta|theta_dot|deflection|deflection_angle|delta|"
    r"friction_torque)_\d+(_\d+)?|tip_x|tip_y|(torque|current|voltage)_\d+(_applied)?"
)


class ScenarioError(FlexarmError, ValueError):
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
    def _sizes(self) -> RegulationSpec:
        n = len(self.target)
        for name in ("initial", "kp", "kd"):
            if len(getattr(self, name)) != n:
                raise ValueError(
                    f"{name} has {len(getattr(self, name))} entries; target has {n} (one per joint)"
                )
        return self


Arm = Annotated[SingleLinkArm | MultiLinkArm, Field(discriminator="kind")]


class Scenario(Spec):
    """A full scenario: one arm (``arm.kind = "single_link"`` or ``"multi_link"``), the
    experiment and the controller.

    Sections: ``arm``; for the sampled-data loop ``sampling``, ``sensors``, ``actuator``,
    ``simulation``, ``initial``, ``reference`` (the channel ``reference``) and
    ``references`` (more named channels, e.g. ``theta_ref_1``), ``controller`` (one block)
    or ``controllers`` (``[[controllers]]``: several ``type = "lti"`` blocks, each at its own
    period, a multiple of the sampling period, driving its own outputs); for a
    multi-link arm under a continuous-time law, ``regulation`` (DLS eqs. 8, 30). Sensor
    channels are named after the arm's signals (:attr:`flexarm.models.plant.Plant.signal_names`;
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
    controller: (
        Annotated[ControllerSpec | JointPDController, Field(discriminator="type")] | None
    ) = None
    controllers: (
        list[Annotated[ControllerSpec | JointPDController, Field(discriminator="type")]] | None
    ) = None
    regulation: RegulationSpec | None = None
    disturbances: list[Disturbance] = Field(default_factory=list)

    @property
    def n_joints(self) -> int:
        return 1 if self.arm.kind == "single_link" else len(self.arm.links)

    @property
    def prismatic(self) -> bool:
        """Whether the arm is one linear axis (``arm.joint = "prismatic"``: m, N, kg)."""
        return getattr(self.arm, "joint", "revolute") == "prismatic"

    @model_validator(mode="before")
    @classmethod
    def _linear_units(cls, data: Any) -> Any:
        """A prismatic axis's ``[initial]`` and references in m (:data:`PRISMATIC_UNITS`)."""
        arm = data.get("arm") if isinstance(data, dict) else None
        joint = arm.get("joint") if isinstance(arm, dict) else getattr(arm, "joint", None)
        if joint != "prismatic":
            return data
        data = dict(data)
        if "initial" in data:
            data["initial"] = prismatic_values(data["initial"], "initial")
        if "reference" in data:
            data["reference"] = prismatic_values(data["reference"], "reference")
        if isinstance(data.get("references"), dict):
            data["references"] = {
                k: prismatic_values(v, "reference") for k, v in data["references"].items()
            }
        return data

    def controller_specs(self) -> list:
        """The controller blocks: ``[[controllers]]`` in order, or ``[controller]``, or none."""
        if self.controllers is not None:
            return list(self.controllers)
        return [] if self.controller is None else [self.controller]

    def reference_channels(self) -> set[str]:
        """The reference channels the scenario defines: ``reference`` and ``[references]``."""
        return {"reference", *self.references}

    def controller_references(self) -> set[str]:
        """The reference channels the controllers read (their setpoints, and the entries
        of a ``signals`` vector that name a reference channel)."""
        refs, out = self.reference_channels(), set()
        for spec in self.controller_specs():
            out.update(s for s in getattr(spec, "setpoints", None) or [] if isinstance(s, str))
            out.update(
                s for s in getattr(spec, "signals", None) or [] if isinstance(s, str) and s in refs
            )
        return out

    def with_controllers(
        self, tables: ControllerFile | dict[str, Any], source: str | None = None
    ) -> Scenario:
        """This scenario with its controllers replaced by ``tables`` (a
        :class:`ControllerFile` from :func:`load_controllers`, or a dict with a
        ``controller`` table or a ``controllers`` list as in a scenario TOML); validated
        again, so a period or output that does not fit this scenario is a
        :class:`ScenarioError` naming ``source`` (default the controller file)."""
        if isinstance(tables, ControllerFile):
            source = source or tables.source
            tables = tables.model_dump(mode="json", exclude_none=True, exclude={"source"})
        given = {k: v for k, v in tables.items() if k in ("controller", "controllers")}
        if len(given) != 1 or set(tables) - {"controller", "controllers"}:
            raise ScenarioError(
                f"{source or 'controllers'}: give [controller] (one block) or "
                "[[controllers]] (several), nothing else; got "
                f"{', '.join(sorted(tables)) or 'nothing'}"
            )
        data = self.model_dump(mode="json", exclude_none=True)
        data.pop("controller", None)
        data.pop("controllers", None)
        data.update(given)
        return scenario_from_dict(
            data, source=f"{source or 'controllers'} (with scenario {self.name!r})"
        )

    @model_validator(mode="after")
    def _check_controllers(self) -> Scenario:
        if self.controller is not None and self.controllers is not None:
            raise ValueError("give [controller] (one block) or [[controllers]] (several), not both")
        if self.controllers is None:
            blocks = [("controller", self.controller)] if self.controller is not None else []
        else:
            if not self.controllers:
                raise ValueError("[[controllers]] is empty; give at least one block, or drop it")
            blocks = [(f"controllers[{i}]", c) for i, c in enumerate(self.controllers)]
            for where, c in blocks:
                if c.type != "lti" or c.friction_compensation is not None:
                    raise ValueError(
                        f"{where}: type = {c.type!r}"
                        + (" with friction_compensation" if c.type == "lti" else "")
                        + " cannot run as one of several [[controllers]]: each block "
                        'needs its own outputs and period, which type = "lti" has (write '
                        "the law as A, B, C, D, or use [controller] for a single one)"
                    )
        base = self.sampling.period if self.sampling is not None else None
        driven: dict[object, str] = {}
        known = (
            set(self.sensors)
            | self.reference_channels()
            | (set(KNOWN_SENSORS) if self.arm.kind == "single_link" else set())
        )
        for where, c in blocks:
            dt = getattr(c, "dt", None)
            if dt is not None and base is not None:
                r = dt / base
                if round(r) < 1 or abs(r - round(r)) > 1e-9 * max(1.0, round(r)):
                    raise ValueError(
                        f"{where}.dt = {dt:g} s is not a whole multiple of the sampling "
                        f"period {base:g} s (ratio {r:.9g}); give dt = k·{base:g} s, e.g. "
                        f"{max(1, round(r)) * base:g} s (the block runs every k samples)"
                    )
            for j, s in enumerate(getattr(c, "signals", None) or []):
                if (
                    isinstance(s, str)
                    and s not in known
                    and not (self.arm.kind == "multi_link" and _MULTI_SIGNAL.fullmatch(s))
                ):
                    raise ValueError(
                        f"{where}.signals[{j}] = {s!r} is neither a channel nor a number: "
                        f"give a sensor channel ({', '.join(sorted(self.sensors)) or 'none'}), "
                        f"a reference channel ({', '.join(sorted(self.reference_channels()))}"
                        "), a plant signal, or a number (a constant input)"
                    )
            for o in getattr(c, "outputs", None) or []:
                m = re.fullmatch(r".*_(\d+)", o) if isinstance(o, str) else None
                key = int(o) if not isinstance(o, str) else int(m.group(1)) if m else o
                if key in driven and driven[key] != where:
                    raise ValueError(
                        f"{where}.outputs: {o!r} is driven by {driven[key]} "
                        "already; two controllers cannot drive one output (sum "
                        "them in one block, or give each its own outputs)"
                    )
                driven[key] = where
        return self

    @model_validator(mode="after")
    def _check_names(self) -> Scenario:
        if self.arm.kind == "single_link":
            for name in ("sampling", "simulation"):
                if getattr(self, name) is None:
                    raise ValueError(
                        f"[{name}] is missing; a single-link scenario needs "
                        "[sampling] (period) and [simulation] (duration)"
                    )
            if self.regulation is not None:
                raise ValueError(
                    "[regulation] is the multi-link continuous-time law; a "
                    "single-link arm takes a [controller]"
                )
            for name, sensor in self.sensors.items():
                if (sensor.signal or name) not in KNOWN_SENSORS + COMMAND_SIGNALS:
                    raise ValueError(
                        f"unknown sensor channel {name!r}"
                        + (f" (signal {sensor.signal!r})" if sensor.signal else "")
                        + f"; known signals: {', '.join(KNOWN_SENSORS + COMMAND_SIGNALS)}"
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
            raise ValueError(
                f"regulation.target has {len(self.regulation.target)} joints; the arm has {n} links"
            )
        if (self.sampling is None) != (self.simulation is None):
            raise ValueError("give [sampling] and [simulation] together (the sampled-data loop)")
        if self.sampling is None and (self.controller is not None or self.controllers):
            raise ValueError(
                "a [controller] runs in the sampled-data loop: give [sampling] "
                "(period) and [simulation] (duration)"
            )
        for name in ("joint_angles", "joint_velocities"):
            v = getattr(self.initial, name)
            if v is not None and len(v) != n:
                raise ValueError(f"initial.{name} has {len(v)} values; the arm has {n} joints")
        return self

    @model_validator(mode="after")
    def _check_disturbances(self) -> Scenario:
        n = self.n_joints
        taken = self.reference_channels() | set(self.sensors)
        seen: set[str] = set()
        for i, d in enumerate(self.disturbances):
            where = f"disturbances[{i}] ({d.name})"
            if d.name in seen:
                raise ValueError(f"{where}: name {d.name!r} is given twice; give each its own")
            seen.add(d.name)
            if d.name in taken:
                raise ValueError(
                    f"{where}: name {d.name!r} is already a reference or sensor channel; "
                    "give the disturbance its own name"
                )
            if d.joint is not None and d.joint > n:
                raise ValueError(
                    f"{where}: joint = {d.joint}, but the arm has {n} joint(s); give 1..{n}"
                )
            if d.joint is None and n > 1:
                raise ValueError(f"{where}: the arm has {n} joints; say which with joint = 1..{n}")
            if self.sampling is None:
                raise ValueError(
                    f"{where}: a disturbance enters the sampled-data loop; give [sampling] "
                    "and [simulation]"
                )
        return self

    def disturbance_names(self) -> list[str]:
        """The names of the ``[[disturbances]]``, in order (the log columns they need)."""
        return [d.name for d in self.disturbances]

    def __repr__(self) -> str:
        """A short table (name, arm, drive, beam, sampling, controller); the full
        specification is ``model_dump()``."""
        return _scenario_table(self).text()

    def _repr_html_(self) -> str:
        return _scenario_table(self).html()


def _scenario_table(sc: Scenario):
    """The rows of :meth:`Scenario.__repr__` (:class:`flexarm.display.Table`)."""
    from flexarm.display import Table

    arm = sc.arm
    rows: list[tuple[str, object]] = [("description", sc.description or None)]
    if arm.kind == "single_link":
        motor = arm.motor
        rows += [
            ("arm", "single link"),
            ("drive", f"{motor.drive}, J = {motor.inertia:.4g} kg*m**2"),
            ("beam", getattr(arm.beam, "model", None)),
            (
                "friction",
                f"Coulomb {arm.friction.coulomb:.4g} N*m"
                if getattr(arm.friction, "coulomb", None) is not None
                else None,
            ),
        ]
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
            lines.append(f"  {loc}: {msg}" if loc else f"  {msg}")
    return "\n".join(lines)


class ControllerFile(Spec):
    """A controller file (``--controller FILE.toml``): ``[controller]`` or
    ``[[controllers]]`` tables exactly as in a scenario (:func:`load_controllers`)."""

    source: str = "controllers"
    controller: (
        Annotated[ControllerSpec | JointPDController, Field(discriminator="type")] | None
    ) = None
    controllers: (
        list[Annotated[ControllerSpec | JointPDController, Field(discriminator="type")]] | None
    ) = None

    @model_validator(mode="after")
    def _one(self) -> ControllerFile:
        if (self.controller is None) == (self.controllers is None):
            raise ValueError(
                "give [controller] (one block) or [[controllers]] (several): "
                + ("both given" if self.controller is not None else "the file has neither")
            )
        return self


def _resolve_files(data: Any, folder: Path) -> Any:
    """``data`` with every controller table's relative ``file`` made absolute against
    ``folder`` (the folder of the TOML that names it)."""
    if not isinstance(data, dict):
        return data
    out = dict(data)
    tables = []
    if isinstance(out.get("controller"), dict):
        out["controller"] = dict(out["controller"])
        tables.append(out["controller"])
    if isinstance(out.get("controllers"), list):
        out["controllers"] = [dict(t) if isinstance(t, dict) else t for t in out["controllers"]]
        tables += [t for t in out["controllers"] if isinstance(t, dict)]
    for t in tables:
        f = t.get("file")
        if isinstance(f, str) and f and not Path(f).expanduser().is_absolute():
            t["file"] = str((folder / Path(f).expanduser()).resolve())
    return out


def _read_toml(path: Path, what: str) -> dict[str, Any]:
    if path.is_dir():
        raise ScenarioError(f"{path}: is a folder; give a {what} TOML file")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:  # issue #45: arrays or tables nested thousands deep
        raise ScenarioError(
            f"{path}: nested too deeply to read (arrays or tables inside each other beyond "
            f"Python's recursion limit); a {what} is a few flat tables"
        ) from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(
            f"{path}: not a text file in UTF-8 (byte {exc.start}: "
            f"{exc.object[exc.start : exc.start + 1]!r}); a {what} is a TOML "
            "text file"
        ) from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read the file ({exc.strerror or exc})") from None


def load_controllers(path: str | Path) -> ControllerFile:
    """Read a controller file: a TOML with ``[controller]`` or ``[[controllers]]`` tables
    exactly as in a scenario (relative ``file`` entries resolved against the file's
    folder). Pass the result to :meth:`Scenario.with_controllers` (what ``--controller
    FILE.toml`` does). Problems are a :class:`ScenarioError` naming the file and field."""
    path = Path(path)
    if not path.exists():
        raise ScenarioError(
            f"{path}: no such controller file (a TOML with [controller] or [[controllers]])"
        )
    data = _resolve_files(_read_toml(path, "controller file"), path.parent)
    try:
        return ControllerFile.model_validate({**data, "source": str(path)})
    except ValidationError as err:
        raise ScenarioError(_format_errors(err, str(path), "controller file")) from None


def _is_union_tag(p: object) -> bool:
    return isinstance(p, str) and p in {
        "current",
        "voltage",
        "torque",
        "lumped",
        "transfer_function",
        "rigid",
        "pd",
        "pid",
        "lead",
        "tf",
        "state_feedback",
        "joint_pd",
        "lti",
        "nested",
        "single_link",
        "multi_link",
    }


def scenario_from_dict(
    data: dict[str, Any], source: str = "scenario"
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
    return {
        p.name.removesuffix(".toml"): Path(str(p))
        for p in folder.iterdir()
        if p.name.endswith(".toml")
    }


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
    """Read and validate a scenario TOML file (or a built-in scenario by name). A relative
    controller ``file`` is read from the scenario's folder, not the working directory."""
    path = resolve_scenario_path(name_or_path)
    if path.is_dir():
        raise ScenarioError(
            f"{path}: is a folder; give a scenario TOML file or a built-in "
            "name (flexarm scenarios lists them)"
        )
    data = _resolve_files(_read_toml(path, "scenario"), path.parent)
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
