"""flexarm example-logs (issue #46 item 1): simulated lab logs with known true parameters,
in the lab logger's own format, that the README's data-sheet fit recovers; the motor
bench's multisine record, whose FRF and two-mass fit recover the true plant."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import flexarm
from flexarm.analysis.example_logs import (
    DATA_SHEET,
    MOTOR_BENCH,
    ROTARY_FLEXIBLE,
    ROTARY_RIGID,
    ExampleLogsError,
    rotary_scenario,
    write_example_logs,
)
from flexarm.errors import OutputExistsError

ROOT = Path(__file__).resolve().parents[1]
FORMAT = ROOT / "examples" / "quanser-rotflex.toml"


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("example-logs")
    return write_example_logs(d, duration=6.0, two_link_seconds=2.0)


def test_the_rotary_logs_are_the_lab_loggers_format(logs):
    """Tab-separated, CRLF, 13 fields, a '%' header saying (s) over a ms column, 3
    decimals; the lab's format file reads them back to the simulated reference and gains."""
    raw = logs.files["rotary-flexible"].read_bytes()
    lines = raw.split(b"\r\n")
    assert lines[0].startswith(b"%Time (s)") and lines[-1] == b""
    rows = [ln.split(b"\t") for ln in lines[1:-1]]
    assert len(rows) == 6001 and {len(r) for r in rows} == {13}
    assert all(len(f.split(b".")[1]) == 3 for f in rows[10])
    t_ms = np.array([float(r[0]) for r in rows[:3]])
    assert np.allclose(np.diff(t_ms), 1.0) and t_ms[0] > 1000  # ms on the logger's clock
    log = flexarm.load_log(logs.files["rotary-flexible"], FORMAT)
    assert log.time[0] == pytest.approx(412.87) and log.time[-1] - log.time[0] == pytest.approx(6.0)
    r = log.columns["reference"]
    assert r[0] == -0.4 and r[600] == 0.4 and r[2100] == -0.4  # steps at 0.5, 2 s
    assert log.controller.k1 == ROTARY_FLEXIBLE["gains"][0]
    rigid = flexarm.load_log(logs.files["rotary-rigid"], FORMAT)
    assert np.all(rigid.columns["tip_deflection"] == 0.0)


def test_the_true_parameters_are_written_beside_the_logs(logs):
    import tomllib

    doc = tomllib.loads(logs.files["true-parameters"].read_text())
    assert doc["rotary-flexible"]["fit"]["hub_inertia"] == ROTARY_FLEXIBLE["hub_inertia"]
    assert doc["rotary-rigid"]["fit"]["coulomb"] == ROTARY_RIGID["coulomb"]
    assert doc["data_sheet"]["gear_ratio"] == DATA_SHEET["gear_ratio"]
    two = flexarm.load_log(logs.files["two-link"])
    assert two.time[-1] == pytest.approx(2.0) and "command_1" in two.columns


def test_nothing_is_overwritten_without_overwrite(logs):
    before = logs.files["rotary-flexible"].read_bytes()
    with pytest.raises(OutputExistsError, match="overwrite"):
        write_example_logs(logs.directory, which=("rotary-rigid",))
    assert logs.files["rotary-flexible"].read_bytes() == before
    with pytest.raises(ExampleLogsError, match="rotary-flexible, rotary-rigid, two-link"):
        write_example_logs(logs.directory, which=("motor",), overwrite=True)


def _run(tmp_path, args):
    env = dict(os.environ)  # this checkout's flexarm, also where PYTHONPATH is relative
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    cmd = [sys.executable, "-m", "flexarm", *map(str, args)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=900, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


#: the README's data-sheet fit of the example log, with the profile delay search: the
#: default search ("neighbours") stops at a tip delay of 31 samples (truth 30) on this log,
#: in a local minimum whose cost is above the truth's (hub fit 99.734 % against the truth's
#: 99.855 %; J 4.3 % low); "both" reaches 99.926 / 99.248 %, below the truth's cost
README_FIT = [
    "--log-format", FORMAT, "--drive", "voltage", "--gear-ratio", "48.4",
    "--motor-constant", "0.0107", "--armature-resistance", "3.29", "--link-length", "0.45",
    "--window", "0:4", "--validate-window", "4:6",
]  # fmt: skip


def _fit(tmp_path, log):
    out = tmp_path / "fit.json"
    _run(tmp_path, ["fit", log, *README_FIT, "--delay-search", "both", "--json", out])
    return json.loads(out.read_text())


def _rig(fitted: dict) -> tuple[dict, dict]:
    """The servo rig's own parameters and std (hub_inertia, link_frequency, ...): the fit
    document's stages.servo_rig where it holds them (its top-level params may be named by
    scenario paths), else its top-level params."""
    rig = fitted["stages"]["servo_rig"]
    if "params" in rig:
        return rig["params"], rig["std"]
    return fitted["params"], fitted["std"]


@pytest.fixture(scope="module")
def fitted(logs, tmp_path_factory):
    return _fit(tmp_path_factory.mktemp("fit"), logs.files["rotary-flexible"])


def _truth_prediction(logs):
    from flexarm.identification.time_domain.options import PredictOptions
    from flexarm.identification.time_domain.predict import predict

    log = flexarm.load_log(logs.files["rotary-flexible"], FORMAT)
    sc = rotary_scenario(ROTARY_FLEXIBLE, duration=6.0)
    return predict(sc, [log], PredictOptions(windows=[(0.0, 4.0)])).fit_percent["rotary-flexible"]


def test_the_truth_lies_in_the_fitted_model_class(logs):
    """The true rig, in the form the data-sheet fit writes (backward-difference rates, the
    encoder's 1 mrad step, no computation delay, one pinned tip mass), predicts the fitted
    window 0-4 s as the fit's own prediction does (each window's start estimated): hub
    >= 99.8 %, tip >= 99.1 %. What is left is the noise: the gauge's 0.2 mm in the loop,
    the logger's rounding to 1 mm and 1 mrad (measured 2026-12-05: 99.855 / 99.187 %; the
    earlier logs, from the built-in beam scenario with filtered rates and a 4096-count
    encoder, were outside the class: the fit's J came out 20 % low)."""
    fp = _truth_prediction(logs)
    assert fp["motor_angle"] >= 99.8 and fp["tip_deflection"] >= 99.1, fp


@pytest.mark.slow
def test_the_fit_predicts_the_example_log_at_least_as_well_as_the_truth(fitted, logs):
    """The fit reaches the truth's fit % on the window it fits (its cost is at most the
    truth's: the search found the optimum, so what separates the fitted values from the
    true ones is the noise, not the search), and predicts the held-out 4-6 s (>= 98 %).
    Measured 2026-12-05: fit 99.926 / 99.248 %, truth 99.855 / 99.187 %, held out
    99.922 / 99.070 %."""
    fp = fitted["fit_percent"]["rotary-flexible"]
    truth = _truth_prediction(logs)
    for sig in ("motor_angle", "tip_deflection"):
        assert fp[sig] >= truth[sig] - 0.01, (sig, fp, truth)
    held = fitted["held_out"]
    assert held["window_s"] == [4.0, 6.0]
    hp = held["fit_percent"]["rotary-flexible"]
    assert hp["motor_angle"] >= 98 and hp["tip_deflection"] >= 98, hp


@pytest.mark.slow
def test_the_fit_recovers_the_link_the_gauge_and_the_delays(fitted):
    """The link's clamped frequency and inertia and the gauge's calibration within 3
    reported (HAC) std of the truth (3σ: a 0.3 % chance per parameter for a Gaussian
    error), the sensor delays exactly (10 / 30 samples). Measured 2026-12-05:
    ω_c 11.3099 ± 0.00043 rad/s (true 11.3097, +0.3σ), J_l 0.00150048 ± 7.7e-07 kg·m²
    (+0.6σ), gain 0.899753 ± 0.00011 (−2.3σ)."""
    p, s = _rig(fitted)
    for k in ("link_frequency", "link_inertia", "tip_gain"):
        z = (p[k] - ROTARY_FLEXIBLE[k]) / s[k]
        assert abs(z) <= 3, (k, p[k], s[k], ROTARY_FLEXIBLE[k])
    d = fitted["stages"]["servo_rig"]["delays_samples"]
    assert d == {"motor_angle": ROTARY_FLEXIBLE["hub_delay"], "tip_deflection": 30}, d


@pytest.mark.slow
def test_the_fit_recovers_the_hub_and_its_friction_to_a_few_percent(fitted):
    """The hub inertia, link damping, viscous and Coulomb friction within 1 % and the bias
    within 3 % of the truth (measured 2026-12-05: +0.10, +0.36, −0.23, +0.40, +1.9 %; on
    the noise seeds 1 and 2 the hub delay comes out 11 samples and the errors grow to
    0.9 % (J), 7 % (B), 5 % (bias)). The breakaway excess F_s − F_c is not asserted: the
    runs' restarts come at reference steps whose torque is far above it (fitted 0.0004
    against 0.015 N·m, ± 0.002; the fit warns)."""
    p, _ = _rig(fitted)
    tol = {"hub_inertia": 0.01, "link_damping": 0.01, "viscous": 0.01, "coulomb": 0.01}
    tol["bias"] = 0.03
    for k, rel in tol.items():
        assert p[k] == pytest.approx(ROTARY_FLEXIBLE[k], rel=rel), (k, p[k])


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="issue #46: with the truth in the model class and the fit's cost below the "
    "truth's, six of nine parameters still lie beyond 3 reported (HAC) std (2026-12-05, "
    "seed 0: J +3.9σ, ζ +5.2σ, B −3.6σ, F_c +8.3σ, bias +14.7σ, F_s−F_c −7.3σ; the "
    "link's three within 2.3σ): the HAC std (0.03-0.3 %) is 10-30x smaller than the "
    "errors over noise seeds 0-2. The gauge's noise feeds the loop (K4 on its backward "
    "difference: about 0.14 V rms on the command) and moves the stick-slip events, which "
    "the fit's noise-free simulation and its linearised std do not represent",
)
def test_the_fit_recovers_every_parameter_within_3_std(fitted):
    p, s = _rig(fitted)
    for k in ("hub_inertia", "link_inertia", "viscous", "coulomb", "link_damping", "bias"):
        assert abs(p[k] - ROTARY_FLEXIBLE[k]) <= 3 * s[k], (k, p[k], s[k], ROTARY_FLEXIBLE[k])
    k = "static_excess"
    assert abs(p[k] - ROTARY_FLEXIBLE[k]) <= 3 * s[k], (k, p[k], s[k])


def test_the_motor_bench_record_is_the_labs_layout(logs):
    """The .mat holds the lab's variables (time in µs as int32, the uint16 counter whose
    last row repeats, the design) and examples/motor-bench.toml reads it: 50 000 samples at
    2.5 kHz less the irregular last row, the load angle's sign flipped back."""
    import scipy.io

    raw = scipy.io.loadmat(logs.files["motor-bench"])
    assert raw["time"].dtype == np.int32 and raw["msr"].dtype == np.uint16
    assert raw["time"].shape == (50_000, 1) and raw["msr"][-1, 0] == raw["msr"][-2, 0]
    assert int(raw["fs"][0, 0]) == 2500 and int(raw["nrofs"][0, 0]) == 2500
    log = flexarm.load_log(logs.files["motor-bench"], ROOT / "examples" / "motor-bench.toml")
    assert len(log.time) == 49_999 and log.time[1] - log.time[0] == pytest.approx(4e-4)
    assert np.allclose(log.columns["load_angle"], -raw["theta_my"][:-1, 0])


@pytest.fixture(scope="module")
def two_mass(logs, tmp_path_factory):
    d = tmp_path_factory.mktemp("bench")
    mb = logs.files["motor-bench"]
    fmt = ROOT / "examples" / "motor-bench.toml"
    _run(d, ["frf", mb, "--log-format", fmt, "--input", "current"]
         + ["--output", "motor_angle,load_angle", "--json", d / "frf.json"])  # fmt: skip
    _run(d, ["tfest", d / "frf.json", "--structure", "two-mass", "--json", d / "tm.json"])
    return json.loads((d / "frf.json").read_text()), json.loads((d / "tm.json").read_text())


@pytest.mark.slow
def test_the_motor_bench_frf_and_two_mass_fit_recover_the_true_plant(two_mass):
    """The task page's frf -> tfest --structure two-mass on the example record: the fit
    passes its own noise check, and each of the seven parameters lies within 3.5 std of
    the truth (the std from the FRF's noise variances; 3.5σ: a 0.3 % chance that any of
    seven Gaussian errors exceeds it) and within 0.5 % (the delay 0.5 µs). Measured
    2026-12-05 (the record's seed 3): +1.3, −0.5, +0.3, −1.7, +0.8, +1.5, +0.05σ for J,
    J_l/J_m, f_r, ζ_c, d_m, d_l, τ; χ² accepted (cost 106.7 against 116.5 ± 10.8)."""
    frf, tm = two_mass
    assert tm["verdict"].startswith("accepted"), tm["verdict"]
    p = {k: v["value"] for k, v in tm["parameters"].items()}
    s = {k: v["std"] for k, v in tm["parameters"].items()}
    for k in ("total_inertia", "inertia_ratio", "resonance_hz", "shaft_damping"):
        assert abs(p[k] - MOTOR_BENCH[k]) <= 3.5 * s[k], (k, p[k], s[k], MOTOR_BENCH[k])
        assert p[k] == pytest.approx(MOTOR_BENCH[k], rel=0.005), k
    for k in ("motor_viscous", "load_viscous"):
        assert abs(p[k] - MOTOR_BENCH[k]) <= 3.5 * s[k], (k, p[k], s[k], MOTOR_BENCH[k])
        assert p[k] == pytest.approx(MOTOR_BENCH[k], rel=0.005), k
    assert abs(p["delay_s"] - MOTOR_BENCH["delay_s"]) <= max(3.5 * s["delay_s"], 5e-7)
