"""Logs as loggers write them: log-format files, the bench-log reader on the rotary-rig
logs, and the errors for malformed logs and formats (issue #11 item 1)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from flexarm.identification.time_domain.logs import FitInputError, load_rig_log
from flexarm.io.logformat import LogFormatError, load_log_format, log_format_from_dict
from flexarm.io.logs import LogError, read_log

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "examples" / "quanser-rotflex.toml"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
RIG_FILES = sorted(p for p in DATA.iterdir() if p.name != "README.md") if DATA.is_dir() else []
#: The gains K1..K4 the README's table lists per file (K2 logged negative).
README_GAINS = {
    "4PM_Group37_FlexArm_Unit6": (8, -8.5, 1.5, 1.5),
    "Unit7_Flex_trial1.csv": (10, -1, 1, 1),
    "4PM_Group37_RigidArm_Unit1": (10, 0, 0.43, 0),
    "Unit5_Rigid_trial1.csv": (10, 0, 0.3, 0),
    **{f"rigidarm_K1_{k}": (k, 0, 0, 0) for k in (6, 7, 8, 9)},
    **{
        f"rigidarm_k1k3_{k}": (k, 0, k3, 0)
        for k, k3 in ((6, 0.212), (7, 0.271), (8, 0.326), (9, 0.377))
    },
    "flexarm_K1_6": (6, 0, 0, 0),
    "flexarm_K1K2_6_-5": (6, -5, 0, 0),  # the 4/27 session
    # the 5/2 session (README: K4 0.2 until 0.915 s, then 0.4: the first sample's law)
    "flexarm_K1K2K3_6_-3_213": (6, -3, 0.213, 0),
    "flexarm_K1K2K3k4_6_-3_213_4": (6, -3, 0.213, 0.2),
}
needs_data = pytest.mark.skipif(
    not RIG_FILES,
    reason=f"real logs not found in {DATA} (the shared data folder beside the repository)",
)

# A small log in the rig logger's style: tab-separated, CRLF, a '%' header with fewer names
# than fields ending in a date, time in ms from a clock value, gains in columns 8-11.
HEAD = (
    "%Time (s)\tHubangle(Theta in rad)\tTip Deflection(m)\tHub Angular Velocity (rads/s)"
    "\tTip Velocity (m/s)\tPosition Reference (rad)\tOutput Voltage (V)\tK1 (Hub Prop)"
    "\tK2 (Tip Prop)\tK3 (Hub Deriv)\tK4 (Tip Deriv)\t%4/18/20175:40 PM"
)


def _rig_rows(n=200, t0=718578, k1=8.0, switch=None):
    rows = []
    for k in range(n):
        th = 0.1 * np.sin(0.05 * k)
        g1 = k1 if switch is None or k < switch else k1 + 1
        rows.append(
            [
                t0 + k,
                th,
                0.001 * np.cos(0.05 * k),
                0.005 * np.cos(0.05 * k),
                -5e-5 * np.sin(0.05 * k),
                0.1,
                0.3 * np.sin(0.05 * k),
                g1,
                -8.5,
                1.5,
                1.5,
                0,
                0,
            ]
        )
    return np.array(rows)


def _write_rig(path, rows=None, *, head=HEAD, edit=None):
    rows = _rig_rows() if rows is None else rows
    lines = [head] + ["\t".join(f"{v:.3f}" for v in r) for r in rows]
    if edit is not None:
        edit(lines)
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


def _sha(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_example_format_reads_a_rig_style_log_exactly(tmp_path):
    """Every column lands where the format says, in SI; values are exact to the file's 3
    decimals (the file is written with %.3f, so compare with atol 5e-4 in the file's unit)."""
    rows = _rig_rows()
    p = _write_rig(tmp_path / "rig", rows)
    before = _sha(p)
    log = load_rig_log(p, EXAMPLE)
    assert _sha(p) == before
    r = np.round(rows, 3)
    np.testing.assert_allclose(log.time, r[:, 0] * 1e-3, rtol=0, atol=1e-12)  # ms -> s, offset kept
    for name, j in (
        ("motor_angle", 1),
        ("tip_deflection", 2),
        ("motor_velocity", 3),
        ("tip_velocity", 4),
        ("reference", 5),
        ("voltage", 6),
    ):
        np.testing.assert_allclose(log.columns[name], r[:, j], rtol=0, atol=1e-12)
    np.testing.assert_allclose(log.gains, r[:, 7:11], rtol=0, atol=0)
    assert log.controller.k2 == -8.5 and log.voltage_limit == 5.0 and log.rate == "logged"
    assert abs(log.dt - 1e-3) < 1e-12


def test_gains_changing_inside_a_log_are_kept_per_sample(tmp_path):
    log = load_rig_log(_write_rig(tmp_path / "switch", _rig_rows(switch=120)), EXAMPLE)
    assert log.gain_segments == [(0, 120), (120, 200)]
    assert log.controller.k1 == 8 and log.gains[119, 0] == 8 and log.gains[120, 0] == 9
    w = log.window(0.1, 0.2)  # samples 100..199, relative time
    assert len(w) == 100 and w.controller.k1 == 8 and w.gains[-1, 0] == 9
    w2 = log.window(0.13, 0.2)
    assert w2.controller.k1 == 9 and w2.time[0] == pytest.approx(log.time[130])


def test_window_outside_or_too_short_names_log_window_and_span(tmp_path):
    log = load_rig_log(_write_rig(tmp_path / "w"), EXAMPLE)
    with pytest.raises(
        LogError,
        match=r"w: window \[5, 6\) s lies outside the log; "
        r"the log spans \[0, 0\.2\) s",
    ):
        log.window(5, 6)
    with pytest.raises(LogError, match=r"holds only 10 sample\(s\), fewer than 64"):
        log.window(0.0, 0.01, min_samples=64)


def test_fixed_gains_and_sign_flip_in_the_format(tmp_path):
    p = _write_rig(tmp_path / "fixed")
    fmt = load_log_format(EXAMPLE).model_dump()
    fmt["controller"] = {
        "kind": "state_feedback",
        "gains": {"K1": "8 V/rad", "K2": 8.5, "K3": 1.5, "K4": 1.5},
    }
    fmt["columns"]["tip_deflection"] = -3
    fmt["columns"]["motor_angle"] = "-Hubangle(Theta in rad)"
    log = load_rig_log(p, log_format_from_dict(fmt, "f.toml"))
    r = np.round(_rig_rows(), 3)
    np.testing.assert_array_equal(log.columns["tip_deflection"], -r[:, 2])
    np.testing.assert_array_equal(log.columns["motor_angle"], -r[:, 1])
    np.testing.assert_array_equal(log.gains, np.tile([8, 8.5, 1.5, 1.5], (200, 1)))
    assert "col8" in log.columns  # unmapped gain column kept, not used


@needs_data
@pytest.mark.parametrize("path", RIG_FILES, ids=lambda p: p.name)
def test_every_rig_log_loads_unedited_with_the_example_format(path):
    before = _sha(path)
    log = load_rig_log(path, EXAMPLE)
    assert _sha(path) == before
    assert len(log) == 10_000  # README: 10 000 rows at 1 kHz
    assert log.dt == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_allclose(log.gains[0], README_GAINS[path.name], rtol=0, atol=1e-12)
    assert "motor_angle" in log.outputs
    assert ("tip_deflection" in log.outputs) == ("flex" in path.name.lower())


@pytest.mark.parametrize(
    "sep, nl", [(",", "\n"), (";", "\r\n"), ("\t", "\r\n"), (" ", "\n"), ("   ", "\n")]
)
def test_delimiter_and_line_ends_are_sniffed(tmp_path, sep, nl):
    t = np.arange(40) * 0.01
    lines = ["# controller: pd KP=3 KD=0.1", sep.join(["time", "reference", "motor_angle"])]
    lines += [sep.join(f"{v:.6g}" for v in (ti, 0.1, 0.05 * ti)) for ti in t]
    p = tmp_path / "d.txt"
    p.write_bytes((nl.join(lines) + nl).encode())
    log = load_rig_log(p, min_samples=16)
    np.testing.assert_allclose(log.columns["motor_angle"], 0.05 * t, rtol=1e-6)
    assert log.controller.k1 == 3


def test_headerless_log_read_by_column_numbers(tmp_path):
    p = tmp_path / "bare.dat"
    p.write_text("".join(f"{k} 0.1 {0.01 * k}\n" for k in range(30)))
    log = read_log(
        p,
        {"time": 1, "reference": "2", "motor_angle": 3},
        {"time": "ms"},
        required=("time", "reference"),
    )
    np.testing.assert_allclose(log["motor_angle"], 0.01 * np.arange(30))
    with pytest.raises(
        LogError,
        match=r"bare\.dat: missing column\(s\) 'time'.*\n.*found:"
        r"    \(no header; 3 field\(s\) per data row\)",
    ):
        read_log(p, required=("time",))


# --- errors: each names the file, the line and the column --------------------------------


def test_cut_mid_line_names_file_line_and_column(tmp_path):
    p = _write_rig(tmp_path / "cut", edit=lambda ls: ls.__setitem__(-1, ls[-1][:20]))
    with pytest.raises(FitInputError) as e:
        load_rig_log(p, EXAMPLE)
    msg = str(e.value)
    assert f"{p}: data row 200 (line 201) has 3 field(s); most rows have 13" in msg
    assert "column 'tip_deflection' (file column 3" not in msg  # the 3rd field is there
    assert "'tip_velocity' (file column 4" not in msg
    assert (
        "column 'motor_velocity' (file column 4, 'Hub Angular Velocity (rads/s)') onwards "
        "is missing (is the file cut mid-line?)" in msg
    )


def test_text_in_a_number_column_names_file_line_and_column(tmp_path):
    def edit(ls):
        f = ls[51].split("\t")
        f[6] = "1.2V"
        ls[51] = "\t".join(f)

    p = _write_rig(tmp_path / "text", edit=edit)
    with pytest.raises(
        FitInputError,
        match=r"text: column 'voltage' \(file column 7, 'Output "
        r"Voltage \(V\)'\), data row 51 \(line 52\): '1\.2V' "
        r"is not a number",
    ):
        load_rig_log(p, EXAMPLE)


def test_duplicated_time_stamp_names_file_line_and_column(tmp_path):
    rows = _rig_rows()
    rows[80, 0] = rows[79, 0]
    p = _write_rig(tmp_path / "dup", rows)
    with pytest.raises(
        FitInputError,
        match=r"dup: time repeats at data row 81 \(line 82, column "
        r"'time' \(file column 1, 'Time \(s\)'\)\): "
        r"t = 718\.657 s after t = 718\.657 s \(line 81\)",
    ):
        load_rig_log(p, EXAMPLE)


def test_gains_that_cannot_be_found(tmp_path):
    p = _write_rig(tmp_path / "nogains")
    fmt = load_log_format(EXAMPLE).model_dump()
    fmt["controller"] = {"kind": "state_feedback"}
    with pytest.raises(
        FitInputError,
        match=r"nogains: the gains of the state_feedback law "
        r"cannot be found: log format g\.toml \[controller\]",
    ):
        load_rig_log(p, log_format_from_dict(fmt, "g.toml"))
    fmt["controller"] = {"kind": "state_feedback", "gain_columns": {"K1": 8, "K2": 9, "K3": 10}}
    with pytest.raises(
        LogFormatError,
        match=r"h\.toml: 1 problem.*\n  controller: gain\(s\) K4 "
        r"of 'state_feedback' not found",
    ):
        log_format_from_dict(fmt, "h.toml")
    fmt["controller"] = {
        "kind": "state_feedback",
        "gain_columns": {"K1": "K1 (Hub P)", "K2": 9, "K3": 10, "K4": 11},
    }
    with pytest.raises(
        FitInputError,
        match=r"nogains: log format i\.toml: column 'K1' = "
        r"'K1 \(Hub P\)': no such column in the file; the "
        r"file has 13 field\(s\) per data row; header \(line "
        r"1\): Time \(s\) \| Hubangle",
    ):
        load_rig_log(p, log_format_from_dict(fmt, "i.toml"))


def test_format_naming_a_column_that_is_not_there(tmp_path):
    p = _write_rig(tmp_path / "cols")
    fmt = load_log_format(EXAMPLE).model_dump()
    fmt["columns"]["voltage"] = 14
    with pytest.raises(
        FitInputError,
        match=r"cols: log format j\.toml: column 'voltage' = 14: "
        r"no column 14; the file has 13 field\(s\) per data "
        r"row; header \(line 1\): Time",
    ):
        load_rig_log(p, log_format_from_dict(fmt, "j.toml"))
    fmt["columns"]["voltage"] = "Voltage"
    with pytest.raises(FitInputError, match=r"column 'voltage' = 'Voltage': no such column"):
        load_rig_log(p, log_format_from_dict(fmt, "j.toml"))


def test_unit_that_does_not_fit_names_field_and_unit(tmp_path):
    fmt = load_log_format(EXAMPLE).model_dump()
    fmt["units"] = {"time": "V", "motor_angle": "furlong"}
    with pytest.raises(LogFormatError) as e:
        log_format_from_dict(fmt, "u.toml")
    msg = str(e.value)
    assert msg.startswith("u.toml: 1 problem(s) in the log format")
    assert "units: time = 'V' does not convert to s" in msg and 'e.g. time = "ms"' in msg
    # (issue #44: "mm" is a linear axis's position, read in m; a mass is neither)
    fmt["units"] = {"motor_angle": "kg"}
    with pytest.raises(LogFormatError, match=r"units: motor_angle = 'kg' does not convert to rad"):
        log_format_from_dict(fmt, "u.toml")
    fmt["units"] = {}
    fmt["controller"]["gains"] = {"K4": "3 V/m"}
    fmt["controller"]["gain_columns"] = {"K1": 8, "K2": 9, "K3": 10}
    with pytest.raises(
        LogFormatError,
        match=r"gains\.K4: '3 V/m' has units of V / m .*expects "
        r"V\*s/m",
    ):
        log_format_from_dict(fmt, "u.toml")


def test_format_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[columns]\ntime = 0\nmotr_angle = 2\n")
    with pytest.raises(LogFormatError) as e:
        load_log_format(bad)
    assert str(bad) in str(e.value) and "'motr_angle' is not one of flexarm's column names" in str(
        e.value
    )
    bad.write_text("[columns\n")
    with pytest.raises(LogFormatError, match=r"bad\.toml: not valid TOML"):
        load_log_format(bad)
    with pytest.raises(LogFormatError, match=r"nope\.toml: no such log-format file"):
        load_log_format(tmp_path / "nope.toml")
    bad.write_text("[columns]\ntime = 0\n")
    with pytest.raises(LogFormatError, match=r"columns: time = 0: column numbers start at 1"):
        load_log_format(bad)
