"""Issue #45: a log's time read in the wrong unit is refused (``io.checks.check_rate``).

Before: a ``.mat`` time in s where the log format says ``us`` was read as a 1 GHz clock
and ``flexarm frf`` wrote FRF lines at MHz, exit 0.  Now, where the time's unit is stated
([units] time, --unit time=) and where it is not (seconds assumed, see
test_io_checks__unstated_time_unit.py), a sampling rate outside ``RATE_RANGE`` (2 Hz to
200 kHz: no rig's controller logs faster than every 5 µs or slower than every 0.5 s) is one
``LogError`` line naming the rate, the stated unit and the unit that fits (exit 2)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io as sio
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.io.checks import RATE_RANGE
from flexarm.io.logformat import load_log, sample_rate
from flexarm.io.logs import LogError

FMT = '[columns]\ntime = "t"\ncurrent = "i"\nmotor_angle = "th"\n'


def _mat(tmp_path, t):
    n = len(t)
    rng = np.random.default_rng(0)
    sio.savemat(tmp_path / "rec.mat", {"t": t, "i": rng.normal(size=n), "th": rng.normal(size=n)})
    return tmp_path / "rec.mat"


@pytest.mark.parametrize(
    "numbers, stated, rate, fits, fits_rate",
    [
        (1e-3, "us", 1e9, "s", 1000),  # the case: seconds read as µs
        (1e-3, "ms", 1e6, "s", 1000),
        (1.0, "s", 1.0, "ms", 1000),  # a ms clock read as s
        (1000.0, "ms", 1.0, "us", 1000),  # a µs clock read as ms
    ],
)
def test_a_time_in_the_wrong_unit_is_refused_with_the_unit_that_fits(
    tmp_path, numbers, stated, rate, fits, fits_rate
):
    p = _mat(tmp_path, np.arange(100) * numbers)
    (tmp_path / "f.toml").write_text(FMT + f'[units]\ntime = "{stated}"\n')
    with pytest.raises(LogError) as e:
        load_log(p, tmp_path / "f.toml")
    msg = str(e.value)
    assert f"a sampling rate of {rate:.6g} Hz" in msg and f"[units] time = {stated!r}" in msg
    assert f"set [units] time = '{fits}' (--unit time={fits}): {fits_rate:.6g} Hz" in msg
    assert "\n" not in msg


@pytest.mark.parametrize(
    "numbers, stated", [(1000.0, "us"), (1.0, "ms"), (1e-3, "s"), (200.0, "us")]
)
def test_a_time_in_its_stated_unit_is_read(tmp_path, numbers, stated):
    p = _mat(tmp_path, np.arange(100) * numbers)
    (tmp_path / "f.toml").write_text(FMT + f'[units]\ntime = "{stated}"\n')
    from flexarm.units import ureg

    want = 1 / (numbers * ureg.Quantity(1.0, stated).to("s").magnitude)
    assert RATE_RANGE[0] <= want <= RATE_RANGE[1]
    assert sample_rate(load_log(p, tmp_path / "f.toml")) == pytest.approx(want, rel=1e-9)


def test_a_text_log_with_a_unit_on_the_command_line_is_checked_too(tmp_path):
    t = np.arange(50) * 1e-3
    rows = "\n".join(f"{a:.4f},{np.sin(a)},{np.cos(a)}" for a in t)
    (tmp_path / "r.csv").write_text("time,current,motor_angle\n" + rows + "\n")
    with pytest.raises(LogError, match=r"r.csv: time.*1e\+06 Hz.*\[units\] time = 'ms'"):
        load_log(tmp_path / "r.csv", units={"time": "ms"})


def test_frf_on_a_mat_time_in_s_said_us_is_exit_2_not_mhz_lines(tmp_path):
    p = _mat(tmp_path, np.arange(2000) * 1e-3)
    (tmp_path / "f.toml").write_text(FMT + '[units]\ntime = "us"\n')
    out = tmp_path / "f.json"
    r = CliRunner().invoke(
        app, ["frf", str(p), "--log-format", str(tmp_path / "f.toml"), "--json", str(out)]
    )
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "1e+09 Hz" in lines[0]
    assert not out.exists()
