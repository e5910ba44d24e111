"""Presets: what is special about a rig kind, for the one fit (:func:`flexarm.fit`).

A preset is a function that builds the rig's model and returns it with its default free
list, priors, bounds and options (and, for the rotary servo, the cheap start estimates'
engine) as one :class:`Preset`:

* :func:`two_link` — the current-driven two-link arm (``quanser-two-link``): the split's
  free list (15 parameters: joint friction, link stiffness and damping, gauge gains,
  torque constants, elbow inertia), data-sheet priors, bounds, segments of 3 s
  (:mod:`flexarm.identification.time_domain.two_link`);
* :func:`servo_rig` — the voltage-driven rotary servo from its data sheet (flexible, or
  rigid with ``link_length`` None ... see there): its engine is the servo-rig pipeline
  (:func:`flexarm.identification.time_domain.fit.fit`: hub → tip estimates, delay search,
  global stage, continuation), called through its keyword interface;
* :func:`for_scenario` — a built-in or user scenario: its ``[notes.fit]`` table, the
  preset registered under its name (:data:`BUILTIN`), or the joints' friction
  (:func:`~flexarm.identification.time_domain.general.friction_paths`) with the joints'
  cable springs that the logs' rests show (:func:`cable_spring_starts`).

A preset's ``starts`` are its cheap estimates from the fitted logs: start values that the
one fit sets and frees before the search (the two-link arm's and the fallback's: the
joints' cable springs).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from flexarm.identification.time_domain.options import FitOptions, Priors

__all__ = [
    "Preset",
    "DataSheet",
    "two_link",
    "servo_rig",
    "servo_bounds",
    "for_scenario",
    "BUILTIN",
    "SERVO_PATHS",
]


@dataclass
class Preset:
    """A rig kind's model and defaults. ``engine``: ``"scenario"`` (the general engine on
    ``scenario``) or ``"servo_rig"`` (the rotary servo pipeline on ``sheet``); ``options``:
    the preset's :class:`~flexarm.identification.time_domain.options.FitOptions` (priors,
    bounds, ties, segments, channels), under the options a fit is given
    (:meth:`~flexarm.identification.time_domain.options.FitOptions.resolved`).
    ``starts``: the cheap estimates that start the search, ``starts(scenario, logs)`` on the
    fitted logs (their windows applied) → (path → start value in SI, a report): the paths
    are set to those values and added to the free list, the report goes to the result's
    ``stages["estimates"]`` (run only with the preset's own free list)."""

    name: str
    scenario: Any
    free: list[str]
    options: FitOptions | None = None
    engine: str = "scenario"
    sheet: dict[str, Any] = field(default_factory=dict)
    starts: Callable[[Any, list], tuple[dict[str, float], dict]] | None = None


def cable_spring_starts(scenario: Any, logs: list) -> tuple[dict[str, float], dict]:
    """Start values of the joints' cable springs where the logs' rests show one
    (:func:`~flexarm.identification.time_domain.estimates.cable_springs`): path → k_c
    (N·m/rad), and the estimates per joint (``cable_springs``)."""
    from flexarm.identification.time_domain.estimates import cable_springs

    est = cable_springs(scenario, logs)
    values = {
        f"arm.joints[{e.joint}].cable_stiffness": e.stiffness
        for e in est
        if e.stiffness is not None
    }
    return values, {"cable_springs": [e.to_dict() for e in est]}


@dataclass
class DataSheet:
    """A voltage- (or current-) driven rotary servo's data sheet (SI): K_g, K_m (V·s/rad or
    N·m/A), R (Ω), link length (m; None: a rigid arm without a tip sensor), efficiencies,
    amplifier limit (V)."""

    drive: str = "voltage"
    gear_ratio: float = 1.0
    motor_constant: float | None = None
    armature_resistance: float | None = None
    link_length: float | None = None
    gear_efficiency: float = 1.0
    motor_efficiency: float = 1.0
    voltage_limit: float | None = None
    current_limit: float | None = None

    def keywords(self) -> dict:
        return dict(vars(self))


def two_link(friction: bool = True) -> Preset:
    """The current-driven two-link arm: ``quanser-two-link`` with link 1's damping started
    at 0.1 N·m·s/rad, the split's free list, priors, bounds and ties
    (:func:`~flexarm.identification.time_domain.two_link.default_options`), and the joints'
    cable springs started where the logs' rests show one (:func:`cable_spring_starts`)."""
    from flexarm.identification.time_domain import two_link as tl

    opts = tl.default_options()
    free = list(tl.FREE) if friction else [p for p in tl.FREE if "friction" not in p]
    if not friction:
        pri = opts.priors or Priors()
        opts.priors = dataclasses.replace(
            pri,
            priors={k: v for k, v in pri.priors.items() if "friction" not in k},
            bounds={k: v for k, v in pri.bounds.items() if "friction" not in k},
        )
    return Preset("quanser-two-link", tl.template(friction), free, opts, starts=cable_spring_starts)


def servo_rig(sheet: DataSheet) -> Preset:
    """The rotary servo from its data sheet; flexible with a ``link_length``. Its free list
    is the pipeline's physical parameters (hub inertia, viscous and Coulomb friction,
    breakaway excess, bias torque; for a flexible link its frequency, damping, inertia and
    the gauge gain), its start estimates the pipeline's (hub → tip model, hub delay, link
    frequency)."""
    from flexarm.identification.time_domain.fit import FRICTION

    free = ["hub_inertia", "viscous", *FRICTION]
    if sheet.link_length is not None:
        free += ["link_frequency", "link_damping", "link_inertia", "tip_gain"]
    return Preset(
        "rotary-servo", None, list(dict.fromkeys(free)), None, "servo_rig", sheet.keywords()
    )


#: the rotary servo pipeline's parameters → the scenario paths they set (one each; the link's
#: frequency and inertia set the lumped beam's EI and mass together: :func:`servo_bounds`)
SERVO_PATHS = {
    "hub_inertia": "arm.motor.inertia",
    "viscous": "arm.motor.viscous",
    "coulomb": "arm.friction.coulomb",
    "static_excess": "arm.friction.static",
    "bias": "arm.friction.bias",
    "link_damping": "arm.beam.damping_ratio",
    "tip_gain": "sensors.tip_deflection.gain",
}
#: a bound at 0 of the pipeline's (its friction levels' log-linear coordinates) becomes
#: this fraction of the upper bound: the general engine fits them in log space
SERVO_FLOOR = 1e-3


def servo_bounds(space: Any, scenario: Any) -> dict[str, tuple[float, float]]:
    """The rotary servo pipeline's data-derived search box (its
    :class:`~flexarm.identification.time_domain.params.ParamSpace`, session 0's parameters)
    as the general engine's ``Priors.bounds`` over the paths of ``scenario`` (the pipeline's
    written scenario, whose values each box holds): :data:`SERVO_PATHS`; the breakaway up to
    the sum of the Coulomb level's and the excess's upper bounds; the lumped link's mass J_l
    / L² and rigidity EI = ω² J_l L / 3 over the boxes of the link inertia J_l and frequency
    ω; the gauge gain with the scenario's sign. A bound at 0 is raised to
    :data:`SERVO_FLOOR` of the upper one. The free list is the keys (a rigid arm: the hub
    and friction paths)."""
    from flexarm.specs.paths import expand_paths, get

    defs = {d.name: d for d in space.defs if not d.session}
    dump = scenario.model_dump()
    out: dict[str, tuple[float, float]] = {}
    for name, path in SERVO_PATHS.items():
        if name not in defs:
            continue
        d = defs[name]
        lo, hi = float(d.lo), float(d.hi)
        if name == "static_excess":  # the breakaway: the Coulomb level's box and the excess
            lo, hi = float(defs["coulomb"].lo), float(defs["coulomb"].hi) + hi
        if name != "bias":
            lo = max(lo, SERVO_FLOOR * hi)
        if name == "tip_gain" and get(dump, path) < 0:
            lo, hi = -hi, -lo
        out[path] = (lo, hi)
    if "link_frequency" in defs and "link_inertia" in defs:
        length = float(get(dump, "arm.beam.length"))
        (w_lo, w_hi), (j_lo, j_hi) = (
            (float(defs[k].lo), float(defs[k].hi)) for k in ("link_frequency", "link_inertia")
        )
        (mass,) = expand_paths(dump, ["arm.beam.masses[0].mass"])
        out[mass] = (j_lo / length**2, j_hi / length**2)
        out["arm.beam.flexural_rigidity"] = (
            w_lo**2 * j_lo * length / 3,
            w_hi**2 * j_hi * length / 3,
        )
    for path, (lo, hi) in list(out.items()):  # each box holds the start (its rounding)
        v = float(get(dump, path))
        out[path] = (min(lo, v), max(hi, v))
    return out


#: Built-in scenario name → its preset.
BUILTIN: dict[str, Callable[[], Preset]] = {"quanser-two-link": two_link}


def for_scenario(scenario) -> Preset:
    """The preset of a scenario: its ``[notes.fit]`` (free, priors), else the one registered
    under its name, else its joints' friction levels (Coulomb, breakaway, viscous) and the
    joints' cable springs where the logs' rests show one (:func:`cable_spring_starts`)."""
    from flexarm.identification.time_domain.general import friction_paths, scenario_fit_notes

    notes = scenario_fit_notes(scenario)
    if notes.get("free"):
        return Preset(
            scenario.name,
            scenario,
            list(notes["free"]),
            FitOptions(priors=Priors(priors=dict(notes.get("priors", {})))),
        )
    if scenario.name in BUILTIN:
        p = BUILTIN[scenario.name]()
        # the registered preset's template is the built-in; a changed copy keeps its numbers,
        # except free parameters it leaves at 0, which start at the preset's value (a fit in
        # log space needs a non-zero start, e.g. link 1's damping)
        from flexarm.specs.paths import expand_paths, get, scenario_with

        mine, theirs = scenario.model_dump(), p.scenario.model_dump()
        starts = {}
        for path in expand_paths(mine, p.free):
            try:
                if get(mine, path) == 0 and get(theirs, path) != 0:
                    starts[path] = get(theirs, path)
            except Exception:  # a path the changed copy lacks: fitted as given
                continue
        sc = scenario_with(scenario, starts) if starts else scenario
        return Preset(p.name, sc, p.free, p.options, p.engine, p.sheet, p.starts)
    if scenario.sampling is None:
        raise ValueError(
            f"scenario {scenario.name!r} has no [sampling]: a continuous-time "
            "[regulation] law is simulated (flexarm.simulate), not fitted to "
            "logs; give a scenario with a sampled loop"
        )
    return Preset(
        scenario.name,
        scenario,
        friction_paths(scenario),
        FitOptions(),
        starts=cable_spring_starts,
    )
