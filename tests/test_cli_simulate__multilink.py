"""``flexarm simulate`` on multi-link arms in the sampled loop: the friction scenarios of issue
#13 (De Luca's arm, geared voltage drives with stiction, law (8) sampled; and with Feliu's
friction compensation), their files, summaries and the overlay figure."""

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.io.logs import read_log
from flexarm.specs import load_scenario

COUNT = 2 * math.pi / 2**16  # the scenarios' 16-bit encoders over one turn (rad)
NAMES = ("deluca-two-link-geared", "deluca-two-link-geared-fc")


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    out = tmp_path_factory.mktemp("geared") / "sim"
    r = CliRunner().invoke(app, ["simulate", *NAMES, "--out", str(out)])
    assert r.exit_code == 0, r.output
    return out, json.loads(r.output)


def test_files_and_overlay_figure(written):
    out, summary = written
    for name in NAMES:
        for ext in (".csv", ".png", ".summary.json"):
            assert (out / f"{name}{ext}").stat().st_size > 0
        assert json.loads((out / f"{name}.summary.json").read_text()) == summary[name]
    fig = out / summary["comparison_figure"]
    assert fig.name == "deluca-two-link-geared_vs_deluca-two-link-geared-fc.png"
    assert fig.read_bytes()[:4] == b"\x89PNG"


def test_summary_errors_in_counts_follow_from_the_csv(written):
    # The summary's final errors, (θ_d − θ(4 s)) / count, recomputed from the CSV's joint
    # angles (written with 10 significant digits: 4e-10 rad, 4e-6 counts) and the target;
    # the summary keeps 4 significant digits (relative 5e-4, issue #46).
    out, summary = written
    for name in NAMES:
        sc = load_scenario(name)
        log = read_log(out / f"{name}.csv", required=("time",), min_samples=2)
        th = np.array([log["theta_1"][-1], log["theta_2"][-1]])
        counts = (np.asarray(sc.controller.target) - th) / COUNT
        np.testing.assert_allclose(
            summary[name]["final_joint_error_counts"], counts, rtol=5e-4, atol=1e-5
        )
        assert log["time"][-1] == pytest.approx(4.0)
    # the must-show: stiction stops law (8) short by more than ten counts; with the
    # friction compensation the error is below one count (tests/test_assembly.py checks
    # |u − g_θ| <= F_s at rest)
    assert np.abs(summary[NAMES[0]]["final_joint_error_counts"]).max() > 10
    assert np.abs(summary[NAMES[1]]["final_joint_error_counts"]).max() < 1
