"""Example logs a user without a rig can run the README's chain on (issue #46).

:func:`write_example_logs` simulates the built-in rig scenarios with a documented "true"
parameter set (:data:`ROTARY_FLEXIBLE`, :data:`ROTARY_RIGID`) and writes what a lab's
logger would have written:

* ``rotary-flexible`` and ``rotary-rigid``: a Quanser-type rotary servo rig (the lab data
  sheet's motor and gearbox: K_g = 48.4, K_m = 0.0107 V·s/rad, R_m = 3.29 Ω, efficiencies
  1, ±5 V amplifier) under the lab's state-feedback law at 1 kHz, square-wave reference
  ±0.4 rad, in the lab logger's own format (``examples/quanser-rotflex.toml`` reads it:
  tab-separated, CRLF, 13 fields, time in **ms** from an arbitrary clock under a header
  that says "(s)", every value rounded to 3 decimals, gains logged per sample, the rate
  columns the law's own filtered derivatives). The hub angle is a 4096-count encoder,
  the tip deflection a noisy strain gauge with a calibration of 0.9; both are read
  late (sensor delays in samples, :data:`ROTARY_FLEXIBLE`), and the law acts on the late
  readings;
* ``two-link.csv``: the built-in ``quanser-two-link`` (current-driven two-link arm, the
  lab's LQR at 500 Hz, its sensors and filters) as it is, in flexarm's CSV exchange format
  (channels by the scenario's names, the references and the commands ``command_1``,
  ``command_2`` in A);
* ``true-parameters.toml``: the true values of every log, by the rotary fit's parameter
  names (SI: :mod:`flexarm.identification.time_domain.params`) and as scenario paths;
* ``README.md``: what the folder holds and the data sheet to fit it with.

The noise is seeded: the same call writes the same files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from flexarm.errors import FlexarmError

__all__ = [
    "ROTARY_FLEXIBLE",
    "ROTARY_RIGID",
    "DATA_SHEET",
    "ExampleLogs",
    "ExampleLogsError",
    "rotary_scenario",
    "reference",
    "simulate",
    "write_lab_log",
    "write_example_logs",
]

#: The rig's data sheet (what a user gives ``flexarm fit``): SI.
DATA_SHEET: dict[str, float] = {
    "gear_ratio": 48.4,
    "motor_constant": 0.0107,  # V*s/rad (= N*m/A)
    "armature_resistance": 3.29,  # ohm
    "link_length": 0.45,  # m
    "voltage_limit": 5.0,  # V
}

#: The flexible unit's true values, by the rotary fit's parameter names (SI; delays in
#: samples of 1 ms; the state-feedback gains K1..K4 in V/rad, V/m, V*s/rad, V*s/m).
ROTARY_FLEXIBLE: dict[str, Any] = {
    "hub_inertia": 3.0e-3,  # kg*m^2, J at the output shaft
    "viscous": 1.0e-2,  # N*m*s/rad, B
    "coulomb": 3.0e-2,  # N*m, F_c
    "static_excess": 1.5e-2,  # N*m, F_s - F_c
    "bias": 4.0e-3,  # N*m
    "link_frequency": 2 * math.pi * 1.8,  # rad/s, hub clamped
    "link_inertia": 1.5e-3,  # kg*m^2, J_l = m L^2
    "link_damping": 0.05,  # damping ratio
    "tip_gain": 0.9,  # m per m, the gauge's calibration with its sign
    "hub_delay": 10,  # samples
    "tip_delay": 30,  # samples
    "gains": (6.0, -10.0, 0.3, 0.5),
    "rate_time_constant": 0.01,  # s, the logger's filtered derivative
    "encoder_counts": 4096,
    "tip_noise": 2.0e-4,  # m, standard deviation of the gauge
}

#: The rigid unit's true values (no link, no tip channel: its column is logged as 0).
ROTARY_RIGID: dict[str, Any] = {
    "hub_inertia": 3.5e-3,
    "viscous": 8.0e-3,
    "coulomb": 2.5e-2,
    "static_excess": 1.0e-2,
    "bias": -3.0e-3,
    "hub_delay": 15,
    "gains": (10.0, 0.0, 0.43, 0.0),
    "rate_time_constant": 0.01,
    "encoder_counts": 4096,
}

#: The logger's header (as the lab's rigs write it, "(s)" although the column is in ms).
LAB_HEADER = (
    "%Time (s)\tHubangle(Theta in rad)\tTip Deflection(m)\tHub Angular Velocity (rads/s)"
    "\tTip Velocity (m/s)\tPosition Reference (rad)\tOutput Voltage (V)\tK1 (Hub Prop)"
    "\tK2 (Tip Prop)\tK3 (Hub Deriv)\tK4 (Tip Deriv)\t%1/1/20269:00 AM"
)

#: Where the logger's millisecond clock stands at the first sample (arbitrary).
LAB_CLOCK0_MS = 412_870.0


def rotary_scenario(true: dict[str, Any], *, duration: float = 6.0, flexible: bool = True):
    """The built-in ``rotary-flexible-link`` with the data sheet (:data:`DATA_SHEET`) and
    the true values ``true`` (:data:`ROTARY_FLEXIBLE` or :data:`ROTARY_RIGID`): a square
    reference between −0.4 and 0.4 rad (period 3 s, first step at 0.5 s), ``duration`` s,
    the hub at rest at −0.4 rad."""
    from flexarm.specs.scenario import load_scenario, scenario_from_dict

    d = load_scenario("rotary-flexible-link").model_dump()
    L = DATA_SHEET["link_length"]
    d["name"] = "example-rotary-" + ("flexible" if flexible else "rigid")
    d["description"] = "flexarm example-logs: a simulated lab rotary servo rig (true values)"
    d["arm"]["motor"].update(
        inertia=true["hub_inertia"],
        viscous=true["viscous"],
        motor_constant=DATA_SHEET["motor_constant"],
        armature_resistance=DATA_SHEET["armature_resistance"],
        gear_ratio=DATA_SHEET["gear_ratio"],
        gear_efficiency=1.0,
        motor_efficiency=1.0,
        voltage_limit=DATA_SHEET["voltage_limit"],
    )
    d["arm"]["friction"].update(
        coulomb=true["coulomb"],
        static=true["coulomb"] + true["static_excess"],
        bias=true["bias"],
    )
    count = 2 * math.pi / true["encoder_counts"]
    d["sensors"]["motor_angle"].update(
        bits=0, quantum=count, range=2 * math.pi, delay=true["hub_delay"]
    )
    if flexible:
        jl, wc = true["link_inertia"], true["link_frequency"]
        d["arm"]["beam"].update(
            length=L, flexural_rigidity=jl * wc**2 * L / 3, damping_ratio=true["link_damping"]
        )
        d["arm"]["beam"]["masses"][0]["mass"] = jl / L**2
        d["sensors"]["tip_deflection"].update(
            gain=true["tip_gain"], noise=true["tip_noise"], delay=true["tip_delay"]
        )
    else:
        d["arm"]["beam"] = {"model": "rigid", "length": L}
        del d["sensors"]["tip_deflection"]
    d["actuator"]["limit"] = DATA_SHEET["voltage_limit"]
    d["simulation"]["duration"] = float(duration)
    d["initial"] = {"motor_angle": -0.4, "tip_deflection": 0.0}
    d["reference"] = {"type": "step", "offset": -0.4, "amplitude": 0.8, "start": 0.5}
    k1, k2, k3, k4 = true["gains"]
    d["controller"] = {
        "type": "state_feedback",
        "k1": k1,
        "k2": k2,
        "k3": k3,
        "k4": k4,
        "rate": "filtered",
        "rate_time_constant": true["rate_time_constant"],
    }
    return scenario_from_dict(d, source=d["name"])


def reference(time: np.ndarray) -> np.ndarray:
    """The runs' hub reference (rad) at ``time`` (s): −0.4 rad, then ±0.4 rad alternating
    every 1.5 s from 0.5 s (steps at 0.5, 2, 3.5, 5 s, ...)."""
    t = np.asarray(time, float)
    k = np.floor((t - 0.5) / 1.5)
    return np.where((t >= 0.5) & (k % 2 == 0), 0.4, -0.4)


def simulate(true: dict[str, Any], *, duration: float = 6.0, flexible: bool = True, seed=0):
    """The simulated run (a :class:`flexarm.io.logs.Log`: measured channels, ``reference``,
    ``command``) of :func:`rotary_scenario` under :func:`reference`."""
    from flexarm.identification.time_domain.synthetic import scenario_log

    sc = rotary_scenario(true, duration=duration, flexible=flexible)
    T = 1e-3  # s, the rig's 1 kHz loop (rotary_scenario's [sampling])
    t = np.arange(int(round(duration / T)) + 1) * T
    name = "rotary-" + ("flexible" if flexible else "rigid")
    return scenario_log(sc, {"reference": reference(t)}, seed=seed, name=name)


def _filtered_rate(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """The law's filtered derivative (:mod:`flexarm.control.state_feedback`):
    ẋ_k = (τ ẋ_{k−1} + x_k − x_{k−1}) / (τ + T), ẋ_0 = 0; units of x per s."""
    out = np.zeros_like(x)
    for k in range(1, x.size):
        out[k] = (tau * out[k - 1] + x[k] - x[k - 1]) / (tau + dt)
    return out


def write_lab_log(
    path: str | Path, log, true: dict[str, Any], *, overwrite: bool = False, decimals: int = 3
):
    """Write a simulated rotary log (:func:`flexarm.identification.time_domain.synthetic.
    scenario_log` of :func:`rotary_scenario`) as the lab's logger writes it (see the module
    docstring); the rate columns are the law's filtered derivatives of the logged-late
    readings (rad/s, m/s), so the logged law reproduces the logged voltage (V).
    ``decimals``: the logger's rounding (3, as the lab's; more for a study of its effect)."""
    from flexarm.io.write import write_text

    t = np.asarray(log.time, float)
    dt = float(t[1] - t[0])
    c = log.columns
    th = np.asarray(c["motor_angle"], float)
    d = np.asarray(c["tip_deflection"], float) if "tip_deflection" in c else np.zeros_like(th)
    tau = float(true["rate_time_constant"])
    k1, k2, k3, k4 = true["gains"]
    n = t.size
    cols = [
        LAB_CLOCK0_MS + np.round(t * 1000.0),
        th,
        d,
        _filtered_rate(th, dt, tau),
        _filtered_rate(d, dt, tau),
        np.asarray(c["reference"], float),
        np.asarray(c["command"], float),
        np.full(n, k1),
        np.full(n, k2),
        np.full(n, k3),
        np.full(n, k4),
        np.zeros(n),
        np.zeros(n),
    ]
    table = np.round(np.column_stack(cols), decimals) + 0.0  # no "-0.000"
    rows = ["\t".join(f"{v:.{decimals}f}" for v in row) for row in table]
    return write_text(path, "\r\n".join([LAB_HEADER, *rows]) + "\r\n", overwrite=overwrite)


class ExampleLogsError(FlexarmError, ValueError):
    """A bad argument of :func:`write_example_logs` (the message names it and the fix)."""


@dataclass
class ExampleLogs:
    """What :func:`write_example_logs` wrote: the folder and its files by role."""

    directory: Path
    files: dict[str, Path] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "directory": str(self.directory),
            "files": {k: str(v) for k, v in self.files.items()},
        }


def _true_document(duration: float, two_link_seconds: float) -> dict:
    def fit_names(true: dict) -> dict:
        keys = [k for k in true if k not in ("gains", "rate_time_constant", "encoder_counts")]
        return {k: true[k] for k in keys}

    flex, rigid = ROTARY_FLEXIBLE, ROTARY_RIGID
    L = DATA_SHEET["link_length"]
    c = flex["link_inertia"] * flex["link_frequency"] ** 2
    return {
        "note": "true values of flexarm example-logs (SI; delays in samples of 1 ms); "
        "the fit's parameter names are flexarm.identification.time_domain.params'",
        "data_sheet": dict(DATA_SHEET, gear_efficiency=1.0, motor_efficiency=1.0),
        "rotary-flexible": {
            "file": "rotary-flexible",
            "seconds": duration,
            "fit": fit_names(flex),
            "gains": list(flex["gains"]),
            "derived": {
                "link_stiffness": c,
                "flexural_rigidity": c * L / 3,
                "tip_mass": flex["link_inertia"] / L**2,
                "encoder_count": 2 * math.pi / flex["encoder_counts"],
                "rate_time_constant": flex["rate_time_constant"],
            },
        },
        "rotary-rigid": {
            "file": "rotary-rigid",
            "seconds": duration,
            "fit": fit_names(rigid),
            "gains": list(rigid["gains"]),
        },
        "two-link": {
            "file": "two-link.csv",
            "seconds": two_link_seconds,
            "scenario": "quanser-two-link (the built-in, unchanged: its numbers are the truth)",
        },
    }


_README = """\
# Example logs (simulated; written by `flexarm example-logs`)

Simulated closed-loop runs of the built-in rigs with known "true" parameters
(`true-parameters.toml`), written as the labs' loggers write them, so that the README's
chain runs without a rig. Real lab logs go where these are used (e.g.
`../shared/data/rotary-rig/...` beside a clone that has the project's data).

* `rotary-flexible`: rotary servo with a flexible link, {duration:g} s at 1 kHz, read with
  `--log-format examples/quanser-rotflex.toml`;
* `rotary-rigid`: the same servo with a rigid arm, {duration:g} s, the same format;
* `two-link.csv`: the built-in `quanser-two-link` (current drives, LQR, 500 Hz), {two:g} s,
  in the CSV exchange format.

Data sheet of both rotary units: `--drive voltage --gear-ratio 48.4 --motor-constant 0.0107
--armature-resistance 3.29 --link-length 0.45` (the rigid arm's too; its tip column is 0);
the amplifier saturates at 5 V. As on the real rigs: time in ms under a header that says "(s)",
values rounded to 3 decimals, a 4096-count encoder, a noisy strain gauge whose
calibration is not 1, both read late (hub 10, tip 30 samples on the flexible unit).
"""


def write_example_logs(
    directory: str | Path,
    *,
    overwrite: bool = False,
    seed: int = 0,
    duration: float = 6.0,
    two_link_seconds: float = 6.0,
    which: tuple[str, ...] = ("rotary-flexible", "rotary-rigid", "two-link"),
) -> ExampleLogs:
    """Write the example logs into ``directory`` (created; an existing file is refused
    unless ``overwrite``): see the module docstring. ``duration`` / ``two_link_seconds``:
    the runs' lengths (s); ``seed``: the noise's seed; ``which``: a subset of the logs."""
    from flexarm.errors import OutputExistsError
    from flexarm.identification.time_domain.synthetic import scenario_log
    from flexarm.io.logs import write_log
    from flexarm.io.write import output_folder, write_text, write_toml
    from flexarm.specs.scenario import load_scenario, scenario_from_dict

    unknown = sorted(set(which) - {"rotary-flexible", "rotary-rigid", "two-link"})
    if unknown:
        raise ExampleLogsError(
            "example log(s) not known",
            field="which",
            value=", ".join(unknown),
            fix="choose among rotary-flexible, rotary-rigid, two-link",
        )
    if not duration >= 3.0:
        raise ExampleLogsError(
            "the rotary runs need >= 3 s (steps at 0.5 and 2 s)",
            field="duration",
            value=duration,
            fix="give 3 s or more (on the command line --seconds)",
        )
    if not two_link_seconds > 0:
        raise ExampleLogsError(
            "must be > 0 s", field="two_link_seconds", value=two_link_seconds, fix="give e.g. 6"
        )
    names = {"rotary-flexible": "rotary-flexible", "rotary-rigid": "rotary-rigid"}
    names["two-link"] = "two-link.csv"
    targets = [Path(directory) / names[w] for w in which]
    targets += [Path(directory) / "true-parameters.toml", Path(directory) / "README.md"]
    there = [str(p) for p in targets if p.exists()]
    if there and not overwrite:
        raise OutputExistsError(
            f"{there[0]}: exists ({len(there)} of the example files are there already); "
            "nothing written (pass overwrite=True, on the command line --overwrite)",
            file=Path(there[0]),
        )
    out = output_folder(directory, overwrite=True)
    res = ExampleLogs(out)
    if "rotary-flexible" in which:
        log = simulate(ROTARY_FLEXIBLE, duration=duration, seed=seed)
        res.files["rotary-flexible"] = write_lab_log(
            out / "rotary-flexible", log, ROTARY_FLEXIBLE, overwrite=overwrite
        )
    if "rotary-rigid" in which:
        log = simulate(ROTARY_RIGID, duration=duration, flexible=False, seed=seed + 1)
        res.files["rotary-rigid"] = write_lab_log(
            out / "rotary-rigid", log, ROTARY_RIGID, overwrite=overwrite
        )
    if "two-link" in which:
        d2 = load_scenario("quanser-two-link").model_dump()
        d2["simulation"]["duration"] = float(two_link_seconds)
        sc = scenario_from_dict(d2, source="quanser-two-link")
        log = scenario_log(sc, seed=seed + 2, name="two-link")
        res.files["two-link"] = write_log(
            out / "two-link.csv",
            np.asarray(log.time, float),
            log.columns,
            comments=[
                "source: flexarm example-logs, the built-in scenario quanser-two-link",
                f"seed: {seed + 2}",
            ],
            overwrite=overwrite,
            required=("time",),
        )
    res.files["true-parameters"] = write_toml(
        out / "true-parameters.toml",
        _true_document(duration, two_link_seconds),
        overwrite=overwrite,
    )
    res.files["readme"] = write_text(
        out / "README.md",
        _README.format(duration=duration, two=two_link_seconds),
        overwrite=overwrite,
    )
    return res
