"""Clocks that drift (issue #44 item 5): a log whose time stamps are off the scenario's
period by at most a tolerance (default 1e-4 relative) is read on the scenario's sample grid
with a note saying by how much; beyond it, one line names the figure and the option
(:func:`flexarm.io.logs.on_sample_grid`)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from flexarm.io.logs import PERIOD_TOLERANCE, ClockError, Log, on_sample_grid

T = 1e-3
N = 24_841  # 24.84 s at 1 kHz


def _drifting(ppm: float, jitter: float = 0.0) -> Log:
    """A log whose clock runs ``ppm`` fast (each step (1 − ppm·1e-6) T) from 12.5 s, its
    stamps rounded to 1e-9 s, with optional uniform jitter (s) on each stamp."""
    rng = np.random.default_rng(4)
    t = 12.5 + np.arange(N) * T * (1 - ppm * 1e-6) + rng.uniform(-jitter, jitter, N)
    return Log(Path("drift.csv"), np.round(t, 9), {"motor_angle": np.sin(np.arange(N) * T)})


def test_a_16_ppm_clock_is_read_on_the_grid_with_a_note():
    log = _drifting(16.0)
    assert abs(log.dt - T) / T == pytest.approx(16e-6, rel=0.01)
    got, note = on_sample_grid(log, T)
    assert PERIOD_TOLERANCE == 1e-4
    # re-stamped on the grid from the first sample; the samples untouched
    assert np.array_equal(got.time, 12.5 + np.arange(N) * T)
    assert got.signals["motor_angle"] is log.signals["motor_angle"]
    assert note is not None and note in got.notes and "\n" not in note
    assert "drift.csv" in note and "16 ppm" in note
    # the last stamp lies 16e-6 · 24.84 s = 0.397 ms before the grid
    assert "-0.000397 s from the grid" in note
    assert log.time[0] == 12.5 and log.notes == []  # the given log unchanged


def test_a_jittering_clock_within_the_tolerance():
    """Stamps that jitter by ±20 µs on a clock 8 ppm slow: the stamps' slope is 8 ppm off
    to 0.05 ppm (7.99 measured: least squares over 24,841 stamps; their median step was
    121 ppm off, the jitter's spread over √N), within 1e-4."""
    got, note = on_sample_grid(_drifting(-8.0, jitter=2e-5), T)
    assert note is not None
    ppm = float(re.search(r"is ([0-9.]+) ppm off", note).group(1))
    assert ppm == pytest.approx(8.0, abs=0.05)
    assert np.allclose(np.diff(got.time), T, rtol=0, atol=1e-12)


def test_beyond_the_tolerance_the_error_names_the_figure_and_the_option():
    log = _drifting(250.0)  # 2.5e-4 relative
    with pytest.raises(ClockError) as e:
        on_sample_grid(log, T)
    msg = str(e.value)
    assert "\n" not in msg
    assert "drift.csv" in msg and "250 ppm" in msg and "period_tolerance = 0.0001" in msg
    assert "period_tolerance >= 0.00025" in msg
    assert isinstance(e.value, ValueError)
    # with the tolerance widened as the message says, it is read
    got, note = on_sample_grid(log, T, 2.5e-4)
    assert note is not None and "250 ppm" in note
    # a tighter tolerance refuses the 16 ppm clock; 0 refuses any drift beyond round-off
    with pytest.raises(ClockError, match="16 ppm"):
        on_sample_grid(_drifting(16.0), T, 1e-5)


def test_a_log_on_the_period_is_used_as_it_is():
    log = _drifting(0.0)
    got, note = on_sample_grid(log, T)
    assert got is log and note is None
