"""Issues #45 / #46: a log whose time unit is NOT stated (no log format's ``[units] time``,
no ``--unit time=``: the numbers are taken as seconds) is checked against
``io.checks.RATE_RANGE`` too.

Before: the lab logger's ms column (its header says "Time (s)") read without the format's
``[units] time = "ms"`` gave a 1 Hz loop, exit 0, and the error came much later as "the
logged command disagrees with the declared law".  Now the reader refuses it in one line
naming the file, the column, the step, the rate it implies read as s, and the field that
states the unit."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io as sio
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.io.checks import RATE_RANGE, check_rate
from flexarm.io.logformat import load_log, sample_rate
from flexarm.io.logs import LogError, read_log

FMT = '[columns]\ntime = "t"\ncurrent = "i"\nmotor_angle = "th"\n'


def _csv(path, t, header="time,current,motor_angle"):
    rows = "\n".join(f"{a:.6f},{np.sin(a):.6f},{np.cos(a):.6f}" for a in t)
    path.write_text(header + "\n" + rows + "\n")
    return path


def test_a_ms_clock_without_a_unit_is_refused_naming_file_column_step_rate_and_fix(tmp_path):
    p = _csv(tmp_path / "run.csv", 343393.0 + np.arange(200))  # the lab logger: 1 ms steps
    with pytest.raises(LogError) as e:
        read_log(p, required=("time", "current", "motor_angle"))
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}: time, column 'time'")
    assert "the median step is 1 s, a sampling rate of 1 Hz" in msg
    assert "no time unit stated" in msg
    assert "[units] time = 'ms' (--unit time=ms): 1000 Hz" in msg
    # what the message proposes loads, at the logger's rate
    log = read_log(p, units={"time": "ms"}, required=("time", "current", "motor_angle"))
    assert sample_rate(log) == pytest.approx(1000.0, rel=1e-9)


def test_a_us_clock_without_a_unit_proposes_us(tmp_path):
    sio.savemat(
        tmp_path / "rec.mat",
        {"t": np.arange(100) * 400.0, "i": np.zeros(100), "th": np.zeros(100)},
    )
    (tmp_path / "f.toml").write_text(FMT)
    with pytest.raises(LogError) as e:
        load_log(tmp_path / "rec.mat", tmp_path / "f.toml")
    msg = str(e.value)
    assert "rec.mat: time" in msg and "the median step is 400 s" in msg
    assert "[units] time = 'us' (--unit time=us): 2500 Hz" in msg


@pytest.mark.parametrize("step", [1e-3, 2e-3, 4e-4, 0.1])
def test_seconds_at_a_rigs_rate_without_a_unit_are_read(tmp_path, step):
    p = _csv(tmp_path / "run.csv", np.arange(200) * step)
    log = read_log(p, required=("time", "current", "motor_angle"))
    assert sample_rate(log) == pytest.approx(1 / step, rel=1e-6)  # 6 printed decimals


@pytest.mark.parametrize("fs", [RATE_RANGE[0], 0.999 * RATE_RANGE[1]])
def test_rates_at_the_ranges_edges_pass_where_no_unit_is_stated(fs):
    check_rate(np.arange(10) / fs, file="x.csv")  # 2 Hz: a step of 0.5 s, exact


@pytest.mark.parametrize("fs", [0.999 * RATE_RANGE[0], 1.001 * RATE_RANGE[1]])
def test_rates_just_beyond_the_range_are_refused_where_no_unit_is_stated(fs):
    with pytest.raises(LogError, match="no time unit stated"):
        check_rate(np.arange(10) / fs, file="x.csv")


def test_far_too_fast_seconds_without_a_fitting_unit_say_map_the_time_column():
    with pytest.raises(LogError, match=r"1e\+09 Hz.*map the column that holds the time"):
        check_rate(np.arange(10) * 1e-9, file="x.csv", column="time")


def test_cli_frf_on_a_ms_clock_without_a_unit_is_exit_2_one_line_and_no_output(tmp_path):
    p = _csv(tmp_path / "run.csv", 343393.0 + np.arange(200))
    r = CliRunner().invoke(app, ["frf", str(p), "--json", str(tmp_path / "f.json")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert "[units] time = 'ms'" in lines[0] and "a sampling rate of 1 Hz" in lines[0]
    assert not (tmp_path / "f.json").exists()
