"""Generate the scenario-field reference (Markdown) from the pydantic specs.

    python tools/scenario_reference.py          # print it

The site's page docs/scenarios.md holds only the marker ``<!-- scenario-reference -->``:
docs/hooks.py replaces it with :func:`reference` at every docs build, so no copy of the
reference is kept in the repository to go stale (``--write``, which rewrote the README's
copy, now only says so).
"""

from __future__ import annotations

import inspect
import sys
import types
import typing

from pydantic import BaseModel

from flexarm.specs import arm, experiment, multilink, scenario
from flexarm.specs.controllers_bench import StateFeedbackController
from flexarm.specs.nested import NestedController
from flexarm.specs.quantity import Unit

#: the marker in a docs page that docs/hooks.py replaces with :func:`reference`
MARKER = "<!-- scenario-reference -->"

SECTIONS = [
    ("top level (single-link)", scenario.Scenario),
    ("[arm] (single-link)", arm.SingleLinkArm),
    ('[arm.motor] drive = "current"', arm.CurrentMotor),
    ('[arm.motor] drive = "voltage"', arm.VoltageMotor),
    ("[arm.friction]", arm.Friction),
    ('[arm.beam] model = "lumped"', arm.LumpedBeam),
    ("[[arm.beam.masses]]", arm.PointMass),
    ('[arm.beam] model = "transfer_function"', arm.TransferFunctionBeam),
    ('[arm.beam] model = "rigid"', arm.RigidBeam),
    ("[sampling]", experiment.Sampling),
    ("[sensors.<signal>]", experiment.Sensor),
    ("[sensors.<signal>.filter]", experiment.DigitalFilterSpec),
    ("[actuator]", experiment.Actuator),
    ("[simulation]", experiment.Simulation),
    ("[initial]", experiment.Initial),
    ("[reference]", experiment.Reference),
    ("[[disturbances]]", experiment.Disturbance),
    ('[controller] type = "pd"', experiment.PDController),
    ('[controller] type = "pid"', experiment.PIDController),
    ('[controller] type = "lead"', experiment.LeadController),
    ('[controller] type = "tf"', experiment.TFController),
    ('[controller] type = "state_feedback"', StateFeedbackController),
    ('[controller] type = "lti"', experiment.LTIControllerSpec),
    ('[controller] type = "nested"', NestedController),
    ('top level (multi-link, arm.kind = "multi_link")', scenario.MultiLinkScenario),
    ("[arm] (multi-link)", multilink.MultiLinkArm),
    ("[[arm.links]]", multilink.Link),
    ("[[arm.hubs]]", multilink.Hub),
    ("[arm.payload]", multilink.Payload),
    ("[regulation]", scenario.RegulationSpec),
]


def _type_text(ann) -> str:
    origin = typing.get_origin(ann)
    if origin is typing.Literal:
        return " \\| ".join(f'"{a}"' for a in typing.get_args(ann))
    if origin in (typing.Union, types.UnionType):
        parts = [_type_text(a) for a in typing.get_args(ann) if a is not type(None)]
        return " or ".join(dict.fromkeys(parts))
    if origin is typing.Annotated:
        return _type_text(typing.get_args(ann)[0])
    if origin in (list, tuple):
        args = [a for a in typing.get_args(ann) if a is not Ellipsis]
        return f"list of {_type_text(args[0])}" if args else "list"
    if origin is dict:
        return "table"
    if inspect.isclass(ann) and issubclass(ann, BaseModel):
        return "section"
    return getattr(ann, "__name__", str(ann))


def _unit(field) -> Unit | None:
    for m in field.metadata:
        if isinstance(m, Unit):
            return m
    ann = field.annotation
    for a in typing.get_args(ann) or ():
        for m in getattr(a, "__metadata__", ()):
            if isinstance(m, Unit):
                return m
        for b in typing.get_args(a) or ():
            for m in getattr(b, "__metadata__", ()):
                if isinstance(m, Unit):
                    return m
    return None


def _default(field) -> str:
    if field.is_required():
        return "**required**"
    d = field.get_default(call_default_factory=True)
    if isinstance(d, BaseModel):
        return "(defaults)"
    return f"`{d!r}`" if d not in (None, [], {}) else ("none" if d is None else f"`{d!r}`")


def reference() -> str:
    out = [
        'Quantities accept a bare number (SI) or a string with units, e.g. `"7 in"`, '
        '`"0.005529 lbf*in*s**2"`, `"55 g"`, `"400 mrad"`; the unit column is '
        "the SI unit stored (`1`: dimensionless, angles in rad).",
        "",
    ]
    for title, model in SECTIONS:
        doc = inspect.cleandoc(model.__doc__ or "").split("\n\n")[0].replace("\n", " ")
        out += [
            f"#### {title}",
            "",
            doc,
            "",
            "| field | type | unit | bounds | default |",
            "|---|---|---|---|---|",
        ]
        for name, f in model.model_fields.items():
            u = _unit(f)
            typ = "quantity" if u is not None and u.unit != "count" else _type_text(f.annotation)
            if u is not None and u.unit == "count":
                typ = "integer"
            unit = "" if u is None or u.unit == "count" else f"`{u.unit}`"
            bounds = "" if u is None else u.bounds
            out.append(f"| `{name}` | {typ} | {unit} | {bounds} | {_default(f)} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


if __name__ == "__main__":
    if "--write" in sys.argv:
        print(
            "nothing to write: the scenario reference is generated at docs build time "
            f"(docs/hooks.py replaces {MARKER} in docs/scenarios.md); `make docs` builds it",
            file=sys.stderr,
        )
    else:
        print(reference())
