"""The signal names a log may carry and their SI units (:data:`KNOWN`, :data:`OTHER`,
:data:`PER_JOINT`; :func:`signal_unit`): read by the log readers (:mod:`flexarm.io.logs`,
:mod:`flexarm.io.matfile`) and their checks (:mod:`flexarm.io.checks`), which import it
and not each other's modules."""

from __future__ import annotations

__all__ = ["REQUIRED", "OPTIONAL", "KNOWN", "OTHER", "PER_JOINT", "signal_unit", "known_names"]

#: Required columns and their SI units.
REQUIRED: dict[str, str] = {
    "time": "s",
    "reference": "rad",
    "current": "A",
    "motor_angle": "rad",
    "tip_angle": "rad",
}
#: Optional columns the format knows, with their SI units.
OPTIONAL: dict[str, str] = {
    "voltage": "V",
    "tip_deflection": "m",
    "motor_velocity": "rad/s",
    "tip_velocity": "m/s",
}
KNOWN: dict[str, str] = {**REQUIRED, **OPTIONAL}
#: Further named signals a log-format file may map, with their SI units.
OTHER: dict[str, str] = {
    "sample_counter": "",  # a logger's sample counter (dropped after the check)
    "load_angle": "rad",
    "load_velocity": "rad/s",
    "tip_x": "m",
    "tip_y": "m",
}
#: Per-joint signals of a multi-link arm, named ``<base>_<joint>`` (``theta_1``,
#: ``alpha_f_2``, ...), with their SI units: joint angle θ, setpoint, rates, the link's
#: deflection angle α (raw, or ``_f`` filtered as a controller logs it) and its rate, the
#: drive's command (current, voltage, torque) and the measured current.
PER_JOINT: dict[str, str] = {
    "theta": "rad",
    "theta_ref": "rad",
    "theta_dot": "rad/s",
    "theta_dot_f": "rad/s",
    "alpha": "rad",
    "alpha_f": "rad",
    "alpha_dot": "rad/s",
    "alpha_dot_f": "rad/s",
    "deflection": "m",
    "deflection_angle": "rad",
    "current": "A",
    "current_measured": "A",
    "voltage": "V",
    "torque": "N*m",
}


def signal_unit(name: str) -> str | None:
    """The SI unit of a flexarm signal name (:data:`KNOWN`, :data:`OTHER`, or a per-joint
    name ``<base>_<j>`` of :data:`PER_JOINT`); ``None`` for a name flexarm does not know."""
    if name in KNOWN:
        return KNOWN[name]
    if name in OTHER:
        return OTHER[name]
    base, sep, j = name.rpartition("_")
    if sep and j.isdigit() and int(j) >= 1 and base in PER_JOINT:
        return PER_JOINT[base]
    return None


def known_names() -> str:
    """The signal names a log may map, for messages."""
    return ", ".join([*KNOWN, *OTHER]) + "; per joint j: " + ", ".join(f"{b}_j" for b in PER_JOINT)
