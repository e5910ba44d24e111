"""Issue #46 (small items): the summaries of ``flexarm simulate`` / ``demo`` read as a
person reads them: numbers to 4 significant digits (not 0.28800000000000003), no
``[None, None]`` (a joint without an encoder says so), and a step run's summary reports
the tip its figure shows (the demo's first figure: a tip swinging 0 to 780 mrad while the
summary named only the motor)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from rich.console import Console

from flexarm.analysis.summary import demo_line, rounded, write_multilink, write_simulation
from flexarm.io.logs import read_log
from flexarm.specs import load_scenario


def _floats(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _floats(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _floats(v)
    elif isinstance(obj, float):
        yield obj


def _significant(x: float) -> int:
    """Significant digits of x as JSON writes it (repr)."""
    m = re.sub(r"e.*$", "", repr(abs(x))).replace(".", "").lstrip("0").rstrip("0")
    return len(m)


def test_rounded_keeps_4_significant_digits_and_no_nan():
    d = rounded(
        {
            "t": 0.28800000000000003,
            "c": [153.38674875720403, -19.665191250811088],
            "small": np.float64(3.1961527614532415e-05),
            "n": np.int64(667),
            "ok": np.bool_(True),
            "r": float("nan"),
            "name": "rig",
            "a": np.array([1.23456, 2.0]),
        }
    )
    assert d == {
        "t": 0.288,
        "c": [153.4, -19.67],
        "small": 3.196e-05,
        "n": 667,
        "ok": True,
        "r": None,  # JSON has no NaN
        "name": "rig",
        "a": [1.235, 2.0],
    }
    assert type(d["n"]) is int and type(d["ok"]) is bool


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    out = tmp_path_factory.mktemp("single")
    s = write_simulation(load_scenario("feliu-single-mass"), out)
    return out, s


def test_a_step_runs_summary_reports_the_tip_its_figure_shows(single):
    out, s = single
    assert json.loads((out / "feliu-single-mass.summary.json").read_text()) == s
    log = read_log(out / "feliu-single-mass.csv", required=("time",), min_samples=2)
    tip, motor = log["tip_angle"], log["motor_angle"]
    t = s["tip"]
    # the figure's tip: 0 to about 780 mrad. The summary's range and deflection are the
    # true angles', the CSV's the sensors' (12-bit: one count 2 pi / 4096 = 1.53 mrad on the
    # motor, pi / 4096 = 0.77 mrad on the tip), to 4 significant digits (relative 5e-4)
    tip_count, motor_count = math.pi / 4096, 2 * math.pi / 4096
    lo, hi = t["tip_angle_range_rad"]
    assert lo == pytest.approx(tip.min(), abs=tip_count)
    assert hi == pytest.approx(tip.max(), abs=tip_count + 5e-4 * hi) and 0.7 < hi < 0.85
    peak = t["peak_deflection_angle_rad"]
    want = np.abs(tip - motor).max()
    assert peak == pytest.approx(want, abs=tip_count + motor_count + 5e-4 * peak)
    assert t["settling_time_s"] == "not within the 2 s record"  # it swings to the end
    assert s["command"] == "current" and s["command_unit"] == "A"
    line = demo_line("feliu-single-mass", s)
    assert "tip 0 to 775 mrad" in line and "peak deflection 377 mrad" in line
    assert "settling not within the 2 s record" in line and "4.12 A (current)" in line


def test_summary_numbers_have_at_most_4_significant_digits(single):
    _, s = single
    floats = list(_floats(s))
    assert len(floats) > 15
    assert max(_significant(x) for x in floats) <= 4, floats
    assert s["step_metrics"]["settling_time"] == 0.291  # was 0.29100000000000004-like


def test_a_joint_without_an_encoder_says_so_instead_of_none(tmp_path):
    sc = load_scenario("quanser-two-link")  # no quantised joint sensors
    s, _ = write_multilink(sc, tmp_path)
    text = (tmp_path / "quanser-two-link.summary.json").read_text()
    assert "null" not in text and "None" not in text
    assert "final_joint_error_counts" not in s
    assert s["no_encoder"].startswith("theta_1, theta_2: no quantised sensor")
    line = demo_line("quanser-two-link", s)
    assert "None" not in line and "mrad" in line and "not in counts" in line
    assert "0.94 A (current_1)" in line
    # the rendered line (rich markup) fits no 14-digit float
    c = Console(width=200, record=True)
    c.print(line)
    assert not re.search(r"\d\.\d{6,}", c.export_text())


def test_regulation_summary_is_rounded_too(tmp_path):
    from flexarm.analysis.summary import write_regulation

    s = write_regulation(load_scenario("deluca-two-link"), tmp_path)
    assert max(_significant(x) for x in _floats(s)) <= 4
    assert all(math.isfinite(x) for x in _floats(s))
