"""flexarm example-logs (issue #46 item 1): simulated lab logs with known true parameters,
in the lab logger's own format, that the README's data-sheet fit recovers."""

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
    ROTARY_FLEXIBLE,
    ROTARY_RIGID,
    ExampleLogsError,
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


def _fit(tmp_path, log):
    out = tmp_path / "fit.json"
    cmd = [
        sys.executable, "-m", "flexarm", "fit", str(log), "--log-format", str(FORMAT),
        "--drive", "voltage", "--gear-ratio", "48.4", "--motor-constant", "0.0107",
        "--armature-resistance", "3.29", "--link-length", "0.45",
        "--window", "0:4", "--validate-window", "4:6", "--json", str(out),
    ]  # fmt: skip
    env = dict(os.environ)  # this checkout's flexarm, also where PYTHONPATH is relative
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")])
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, timeout=900, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
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


@pytest.mark.slow
def test_the_readme_fit_predicts_the_example_log(fitted):
    """The README's data-sheet fit on 0-4 s follows the log (>= 95 % on both signals) and
    predicts the held-out 4-6 s (>= 90 %): the simulated rig is one the fit's model can
    represent. Measured 2026-12-05: 97.9 / 97.9 %, held out 97.2 / 96.7 %."""
    fp = fitted["fit_percent"]["rotary-flexible"]
    assert fp["motor_angle"] >= 95 and fp["tip_deflection"] >= 95, fp
    held = fitted["held_out"]
    assert held["window_s"] == [4.0, 6.0]
    hp = held["fit_percent"]["rotary-flexible"]
    assert hp["motor_angle"] >= 90 and hp["tip_deflection"] >= 90, hp


@pytest.mark.slow
def test_the_readme_fit_recovers_what_the_log_determines(fitted):
    """The link's clamped frequency within 3 reported std, the gauge's calibration within 2 %
    and the sensor delays within one sample of the truth (10 / 30 samples). Measured
    2026-12-05: 11.325 ± 0.0068 rad/s (true 11.310), gain 0.912 ± 0.0036 (true 0.9),
    delays 9 / 31."""
    p, s = _rig(fitted)
    z = (p["link_frequency"] - ROTARY_FLEXIBLE["link_frequency"]) / s["link_frequency"]
    assert abs(z) <= 3, (p["link_frequency"], s["link_frequency"])
    assert p["tip_gain"] == pytest.approx(ROTARY_FLEXIBLE["tip_gain"], rel=0.02)
    d = fitted["stages"]["servo_rig"]["delays_samples"]
    assert abs(d["motor_angle"] - ROTARY_FLEXIBLE["hub_delay"]) <= 1, d
    assert abs(d["tip_deflection"] - ROTARY_FLEXIBLE["tip_delay"]) <= 1, d


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="issue #46: the fit's hub and link inertias come out 10-20 % off the simulated "
    "truth with std of 1-5 % (2026-12-05: J 0.00240 +- 2.5e-05 vs 0.003, J_l 0.00115 +- "
    "2.2e-05 vs 0.0015, F_c 0.0157 +- 0.0008 vs 0.03), also on a run without delays, "
    "friction, quantisation or noise (J 0.00266, J_l 0.00117, delays 2 / 2 samples where "
    "the truth is 0 / 0): flexarm.sim's sampled loop and the servo-rig fit's model differ "
    "in a convention, not in the data",
)
def test_the_readme_fit_recovers_the_inertias_and_friction_within_3_std(fitted):
    p, s = _rig(fitted)
    for k in ("hub_inertia", "link_inertia", "viscous", "coulomb", "link_damping"):
        assert abs(p[k] - ROTARY_FLEXIBLE[k]) <= 3 * s[k], (k, p[k], s[k], ROTARY_FLEXIBLE[k])
