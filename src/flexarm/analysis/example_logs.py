"""Example logs a user without a rig can run the README's chain on (issue #46).

:func:`write_example_logs` simulates rigs with a documented "true" parameter set
(:data:`ROTARY_FLEXIBLE`, :data:`ROTARY_RIGID`, :data:`MOTOR_BENCH`, the built-in
``quanser-two-link``) and writes what a lab's logger would have written:

* ``rotary-flexible`` and ``rotary-rigid``: a Quanser-type rotary servo rig (the lab data
  sheet's motor and gearbox: K_g = 48.4, K_m = 0.0107 V·s/rad, R_m = 3.29 Ω, efficiencies
  1, ±5 V amplifier) under the lab's state-feedback law at 1 kHz, square-wave reference
  ±0.4 rad, in the lab logger's own format (``examples/quanser-rotflex.toml`` reads it:
  tab-separated, CRLF, 13 fields, time in **ms** from an arbitrary clock under a header
  that says "(s)", every value rounded to 3 decimals, gains logged per sample, the rate
  columns the law's own backward differences). The rig is simulated in the very form
  the data-sheet fit writes its result (:func:`rotary_scenario`), so that the true values
  lie in the fitted model class. The hub angle is an encoder of 1 mrad per count, the tip
  deflection a noisy strain gauge with a calibration of 0.9; both are read late (sensor
  delays in samples, :data:`ROTARY_FLEXIBLE`), and the law acts on the late readings;
* ``two-link.csv``: the built-in ``quanser-two-link`` (current-driven two-link arm, the
  lab's LQR at 500 Hz, its sensors and filters) as it is, in flexarm's CSV exchange format
  (channels by the scenario's names, the references and the commands ``command_1``,
  ``command_2`` in A);
* ``motor-bench.mat``: a two-mass motor bench's odd-multisine record (2.5 kHz, 20 periods)
  in the lab's MATLAB layout (``examples/motor-bench.toml`` reads it for ``flexarm frf``;
  :func:`motor_bench_record`): a linear drive with noise on the measured current, a
  current loop, a delay and quantised encoders;
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
    "MOTOR_BENCH",
    "motor_bench_record",
    "write_motor_bench",
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
#: samples of 1 ms; the state-feedback gains K1..K4 in V/rad, V/m, V*s/rad, V*s/m). The
#: law's rates are backward differences and the encoder's step is 1 mrad (what the lab's
#: 3-decimal log can show), as in the scenario the data-sheet fit writes: the truth lies in
#: the fitted model class (:func:`rotary_scenario`).
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
    "encoder_step": 1.0e-3,  # rad per count
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
    "encoder_step": 1.0e-3,
}

#: The motor bench's true values (``motor-bench.mat``): the two-mass drive per ampere of
#: the measured current (:func:`flexarm.identification.frequency_domain.structures.
#: two_mass_response`'s parameters: A*s^2/rad, Hz, A*s/rad, s), the current loop
#: (reference -> current: gain / (1 + s / (2 pi bandwidth)), A/A, Hz), the logger's noise
#: and encoder step, and the record's design (2.5 kHz, 20 periods of 2500 samples, lines
#: 13, 17, ..., 249 Hz excited at 10 A rms: the lab's "type B" odd multisine).
MOTOR_BENCH: dict[str, Any] = {
    "total_inertia": 9.6e-3,  # A*s^2/rad (N*m*s^2/rad per N*m/A of torque constant)
    "inertia_ratio": 1.0,  # J_load / J_motor
    "resonance_hz": 76.0,  # Hz
    "shaft_damping": 0.01,  # the shaft's own damping ratio
    "motor_viscous": 0.03,  # A*s/rad
    "load_viscous": 0.02,  # A*s/rad
    "delay_s": 1.2e-4,  # s, current measurement -> encoders
    "current_loop_gain": 0.98,  # A/A
    "current_loop_hz": 600.0,  # Hz, first-order bandwidth of the current loop
    "current_noise": 0.05,  # A, standard deviation of the measured current
    "current_offset": 0.14,  # A, of the measured current
    "encoder_counts": 2**18,  # counts per revolution, both encoders
    "angle_noise": 1e-5,  # rad, standard deviation of each encoder's reading before its count
    "velocity_filter_hz": 200.0,  # Hz, first-order filter of the logged velocities
    "fs": 2500,  # Hz
    "period": 2500,  # samples
    "periods": 20,
    "lines": (13, 249, 4),  # first, last, step of the excited lines (DFT indices = Hz)
    "rms": 10.0,  # A, current reference
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
    """The rig with the data sheet (:data:`DATA_SHEET`) and the true values ``true``
    (:data:`ROTARY_FLEXIBLE` or :data:`ROTARY_RIGID`), in the very form the data-sheet fit
    writes its result (``flexarm fit LOG --drive voltage ... --scenario-out``:
    :func:`flexarm.identification.time_domain.report.scenario_from_fit`): a voltage-driven
    hub with Karnopp friction, a lumped link with one pinned tip mass m = J_l / L² and
    EI = ω_c² J_l L / 3 (or a rigid arm), the encoder as ``bits`` / ``range`` (13 bits over
    8.192 rad: a 1 mrad step), the sensor delays, no computation delay, 2 RK4 substeps and
    the bench law with backward-difference rates; plus the gauge's noise (not fitted). A
    square reference between −0.4 and 0.4 rad (period 3 s, first step at 0.5 s),
    ``duration`` s, the hub at rest at −0.4 rad."""
    from flexarm.specs.scenario import scenario_from_dict

    L = DATA_SHEET["link_length"]
    q = float(true["encoder_step"])
    bits = int(math.ceil(math.log2(2 * math.pi / q) - 1e-9))
    sensors: dict[str, Any] = {
        "motor_angle": {"delay": int(true["hub_delay"]), "bits": bits, "range": q * 2**bits}
    }
    if flexible:
        jl, wc = true["link_inertia"], true["link_frequency"]
        beam = {
            "model": "lumped",
            "length": L,
            "flexural_rigidity": jl * wc**2 * L / 3,
            "damping_ratio": true["link_damping"],
            "masses": [{"mass": jl / L**2, "joint": "pinned"}],
        }
        sensors["tip_deflection"] = {
            "gain": true["tip_gain"],
            "delay": int(true["tip_delay"]),
            "noise": true["tip_noise"],
        }
    else:
        beam = {"model": "rigid", "length": L}
    k1, k2, k3, k4 = true["gains"]
    d = {
        "name": "example-rotary-" + ("flexible" if flexible else "rigid"),
        "description": "flexarm example-logs: a simulated lab rotary servo rig (true values)",
        "arm": {
            "motor": {
                "drive": "voltage",
                "motor_constant": DATA_SHEET["motor_constant"],
                "armature_resistance": DATA_SHEET["armature_resistance"],
                "gear_ratio": DATA_SHEET["gear_ratio"],
                "gear_efficiency": 1.0,
                "motor_efficiency": 1.0,
                "voltage_limit": DATA_SHEET["voltage_limit"],
                "inertia": true["hub_inertia"],
                "viscous": true["viscous"],
            },
            "friction": {
                "model": "coulomb",
                "coulomb": true["coulomb"],
                "static": true["coulomb"] + true["static_excess"],
                "bias": true["bias"],
            },
            "beam": beam,
        },
        "sampling": {"period": 1e-3, "delay": 0},
        "sensors": sensors,
        "actuator": {"limit": DATA_SHEET["voltage_limit"]},
        "simulation": {"duration": float(duration), "substeps": 2},
        "initial": {"motor_angle": -0.4, "tip_deflection": 0.0},
        "reference": {"type": "step", "offset": -0.4, "amplitude": 0.8, "start": 0.5},
        "controller": {
            "type": "state_feedback",
            "k1": k1,
            "k2": k2,
            "k3": k3,
            "k4": k4,
            "rate": "backward",
        },
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
    ẋ_k = (τ ẋ_{k−1} + x_k − x_{k−1}) / (τ + T), ẋ_0 = 0 (τ = 0: the backward difference
    the examples' law uses); units of x per s."""
    out = np.zeros_like(x)
    for k in range(1, x.size):
        out[k] = (tau * out[k - 1] + x[k] - x[k - 1]) / (tau + dt)
    return out


def write_lab_log(
    path: str | Path, log, true: dict[str, Any], *, overwrite: bool = False, decimals: int = 3
):
    """Write a simulated rotary log (:func:`flexarm.identification.time_domain.synthetic.
    scenario_log` of :func:`rotary_scenario`) as the lab's logger writes it (see the module
    docstring); the rate columns are the law's backward differences of the logged-late
    readings (rad/s, m/s; ``true["rate_time_constant"]`` > 0 s: filtered, as some lab
    loggers), so the logged law reproduces the logged voltage (V).
    ``decimals``: the logger's rounding (3, as the lab's; more for a study of its effect)."""
    from flexarm.io.write import write_text

    t = np.asarray(log.time, float)
    dt = float(t[1] - t[0])
    c = log.columns
    th = np.asarray(c["motor_angle"], float)
    d = np.asarray(c["tip_deflection"], float) if "tip_deflection" in c else np.zeros_like(th)
    tau = float(true.get("rate_time_constant", 0.0))
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


def motor_bench_record(true: dict[str, Any] | None = None, *, seed: int = 0) -> dict:
    """The motor bench's multisine record as the lab's logger stores it (the variables of
    ``../shared/data/motor-bench/MultisineTypeB.mat``, see its README), from the linear
    two-mass drive ``true`` (default :data:`MOTOR_BENCH`) in periodic steady state: the
    current reference ``iq_refx`` (A) a random-phase odd multisine; the flowing current the
    reference through the current loop; the measured ``iq_adx`` (A) that plus noise and an
    offset (errors in variables); the motor angle ``theta_mx`` and the load angle
    ``theta_my`` (rad; the load encoder counts the other way round) the drive's response to
    the flowing current, late by ``delay_s``, with white noise, quantised by the encoders;
    the velocities (rad/s) the angles' rates through a first-order filter; ``time`` in µs
    (int32), the sample counter ``msr`` (uint16, its last row repeated, as the lab's) and the design
    (``ref``, ``fs``, ``df``, ``fl``, ``fh``, ``nroft``, ``nrofs``, ``itp``, ``ctp``,
    ``stp``, ``xf``). The lab's MATLAB ``tf`` object (``BA``) is not written."""
    from flexarm.identification.frequency_domain.structures import two_mass_response

    t = dict(MOTOR_BENCH if true is None else true)
    fs, P, nper = int(t["fs"]), int(t["period"]), int(t["periods"])
    n = P * nper
    rng = np.random.default_rng(seed)
    k0, k1, dk = t["lines"]
    lines = np.arange(k0, k1 + 1, dk)
    X = np.zeros(P // 2 + 1, complex)
    X[lines] = np.exp(1j * rng.uniform(0, 2 * np.pi, lines.size))
    ref = np.fft.irfft(X, P)
    ref = ref / np.sqrt(np.mean(ref**2))  # one period, rms 1 (the lab's normalised ``ref``)
    w = 2 * np.pi * np.fft.rfftfreq(P, 1.0 / fs)  # rad/s
    R = np.fft.rfft(t["rms"] * ref)
    gc = t["current_loop_gain"] / (1 + 1j * w / (2 * np.pi * t["current_loop_hz"]))
    Cur = R * gc  # the flowing current's spectrum
    p = {k: t[k] for k in ("total_inertia", "inertia_ratio", "resonance_hz")}
    p.update({k: t[k] for k in ("shaft_damping", "motor_viscous", "load_viscous", "delay_s")})
    Gm, Gl = two_mass_response(p, np.where(w > 0, w, 1.0))
    Gm[0] = Gl[0] = 0.0  # no DC line is excited
    vf = 1 / (1 + 1j * w / (2 * np.pi * t["velocity_filter_hz"]))

    def periodic(S):
        return np.tile(np.fft.irfft(S, P), nper)

    q = 2 * np.pi / t["encoder_counts"]
    sa = t["angle_noise"]
    th_m = np.round((3.571 + periodic(Gm * Cur) + sa * rng.standard_normal(n)) / q) * q
    th_l = np.round((4.138 + periodic(Gl * Cur) + sa * rng.standard_normal(n)) / q) * q
    cur = periodic(Cur) + t["current_offset"] + t["current_noise"] * rng.standard_normal(n)

    def col(a, dt="float64"):
        return np.asarray(a, dt).reshape(-1, 1)

    msr = np.arange(2, n + 2)
    msr[-1] = msr[-2]  # the logger's irregular last row: its counter repeats
    return {
        "time": col(np.arange(n) * (1_000_000 // fs), "int32"),
        "msr": col(msr, "uint16"),
        "iq_refx": col(np.roll(np.tile(t["rms"] * ref, nper), -1)),
        "iq_adx": col(cur),
        "vdc_adx": col(283.7 + 0.2 * rng.standard_normal(n)),
        "theta_mx": col(th_m),
        "omega_max": col(periodic(1j * w * Gm * Cur * vf)),
        "theta_my": col(-th_l),
        "omega_may": col(-periodic(1j * w * Gl * Cur * vf)),
        "nroft": np.array([[n]], "uint16"),
        "fs": np.array([[fs]], "uint16"),
        "ref": col(ref),
        "nrofs": np.array([[P]], "uint16"),
        "df": np.array([[fs // P]], "uint8"),
        "fl": np.array([[11]], "uint8"),
        "fh": np.array([[250]], "uint8"),
        "itp": np.array(["r"]),
        "ctp": np.array(["c"]),
        "stp": np.array(["O"]),
        "xf": col(ref),
    }


def write_motor_bench(path: str | Path, *, seed: int = 0, overwrite: bool = False) -> Path:
    """Write :func:`motor_bench_record` as a MATLAB v5 file (``scipy.io.savemat``), read by
    ``flexarm frf PATH --log-format examples/motor-bench.toml``."""
    import scipy.io

    from flexarm.io.write import atomic_path

    rec = motor_bench_record(seed=seed)
    with atomic_path(path, overwrite=overwrite) as tmp:
        with open(tmp, "wb") as f:
            scipy.io.savemat(f, rec, format="5", oned_as="column")
    return Path(path)


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
        keys = [k for k in true if k not in ("gains", "encoder_step")]
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
                "encoder_step": flex["encoder_step"],
                "rate": "backward difference",
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
        "motor-bench": {
            "file": "motor-bench.mat",
            "note": "the two-mass drive per ampere of the measured current (tfest --structure "
            "two-mass names), the current loop, noise, encoders and the record's design",
            **{k: (list(v) if isinstance(v, tuple) else v) for k, v in MOTOR_BENCH.items()},
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
  in the CSV exchange format;
* `motor-bench.mat`: a two-mass motor bench's odd multisine (2.5 kHz, 20 periods of 1 s,
  10 A rms on the current reference) in the lab's MATLAB layout, read with
  `flexarm frf motor-bench.mat --log-format examples/motor-bench.toml --input current
  --output motor_angle,load_angle`; a linear drive (no friction), so `flexarm tfest
  --structure two-mass` recovers its true values per ampere.

Data sheet of both rotary units: `--drive voltage --gear-ratio 48.4 --motor-constant 0.0107
--armature-resistance 3.29 --link-length 0.45` (the rigid arm's too; its tip column is 0);
the amplifier saturates at 5 V. As on the real rigs: time in ms under a header that says "(s)",
values rounded to 3 decimals, an encoder of 1 mrad per count, a noisy strain gauge whose
calibration is not 1, both read late (hub 10, tip 30 samples on the flexible unit). The
rigs are simulated in the form the data-sheet fit writes (`--scenario-out`): the law's rates
are backward differences and there is no computation delay, so the true values lie in the
fitted model class.
"""


def write_example_logs(
    directory: str | Path,
    *,
    overwrite: bool = False,
    seed: int = 0,
    duration: float = 6.0,
    two_link_seconds: float = 6.0,
    which: tuple[str, ...] = ("rotary-flexible", "rotary-rigid", "two-link", "motor-bench"),
) -> ExampleLogs:
    """Write the example logs into ``directory`` (created; an existing file is refused
    unless ``overwrite``): see the module docstring. ``duration`` / ``two_link_seconds``:
    the runs' lengths (s); ``seed``: the noise's seed (the motor bench's: ``seed`` + 3);
    ``which``: a subset of the logs."""
    from flexarm.errors import OutputExistsError
    from flexarm.identification.time_domain.synthetic import scenario_log
    from flexarm.io.logs import write_log
    from flexarm.io.write import output_folder, write_text, write_toml
    from flexarm.specs.scenario import load_scenario, scenario_from_dict

    unknown = sorted(set(which) - {"rotary-flexible", "rotary-rigid", "two-link", "motor-bench"})
    if unknown:
        raise ExampleLogsError(
            "example log(s) not known",
            field="which",
            value=", ".join(unknown),
            fix="choose among rotary-flexible, rotary-rigid, two-link, motor-bench",
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
    names.update({"two-link": "two-link.csv", "motor-bench": "motor-bench.mat"})
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
    if "motor-bench" in which:
        res.files["motor-bench"] = write_motor_bench(
            out / "motor-bench.mat", seed=seed + 3, overwrite=overwrite
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
