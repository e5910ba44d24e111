"""Issue #23 item 6: the fit and validate commands decide nothing the library does not.

The data-sheet fit is the one fit (``flexarm.fit``) on the rotary-servo preset; the log
reading with a format per log, the declared-law check and ``--refit friction`` are library
functions (each tested here against an independent computation on a small log)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.io.logs import LogError, write_log

runner = CliRunner()


def _log(path: Path, k1: float = 2.0, n: int = 400, dt: float = 1e-3, gain: float = 1.0):
    """A servo-rig log whose command is exactly ``gain`` × the declared law K1 (r − θ) −
    K3 θ̇ (K3 = 0.1): the controller check must find gain × the declared gains."""
    t = np.arange(n) * dt
    r = np.where(t > 0.1, 0.5, 0.0)
    th = 0.5 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.05)) + 0.01 * np.sin(37 * t)
    om = np.r_[0.0, np.diff(th) / dt]
    u = gain * (k1 * (r - th) - 0.1 * om)
    return write_log(
        path,
        t,
        {"reference": r, "motor_angle": th, "voltage": u},
        comments=[f"controller: state_feedback K1={k1} K2=0 K3=0.1 K4=0"],
        required=("time", "reference"),
    )


def test_load_logs_a_format_per_log_or_by_pattern(tmp_path):
    """One format for all, one per log, PATTERN=FILE; a mismatch is one line naming it."""
    from flexarm.io.logformat import load_logs

    a, b = _log(tmp_path / "a.csv"), _log(tmp_path / "b.csv", k1=3.0)
    logs = load_logs([a, b])
    assert [g.name for g in logs] == ["a.csv", "b.csv"]
    assert logs[1].controller.k1 == 3.0  # the declared law travels with each log
    fmt = tmp_path / "f.toml"
    fmt.write_text('[columns]\nmotor_angle = "motor_angle"\n')
    assert len(load_logs([a, b], [str(fmt), str(fmt)])) == 2
    with pytest.raises(LogError, match=r"b\.csv: no log-format PATTERN matches"):
        load_logs([a, b], [f"a*={fmt}"])
    with pytest.raises(LogError, match="given 3 times for 2 logs"):
        load_logs([a, b], [str(fmt)] * 3)
    # a format already read serves for all; a log already read passes through unchanged
    from flexarm.io.logformat import load_log_format

    read = load_logs([logs[0], b], load_log_format(fmt))
    assert read[0] is logs[0] and read[1].controller.k1 == 3.0
    assert np.array_equal(read[1].signals["motor_angle"], logs[1].signals["motor_angle"])


def test_checked_logs_regress_the_declared_law_and_apply_it_on_request(tmp_path):
    """A log whose command is 1.3 × its declared law: the check raises naming K1; with
    use_regressed it returns the log with K1 = 1.3 × 2 (the command is exact, so to the
    regression's precision: 1e-6 relative)."""
    from flexarm.identification.time_domain.controller_check import checked_logs
    from flexarm.identification.time_domain.logs import FitInputError
    from flexarm.io.logformat import load_logs

    good, bad = load_logs([_log(tmp_path / "g.csv"), _log(tmp_path / "b.csv", gain=1.3)])
    out, checks = checked_logs([good])
    assert out == [good] and len(checks) == 1
    with pytest.raises(FitInputError, match="K1"):
        checked_logs([bad])
    (fixed,), _ = checked_logs([bad], use_regressed=True)
    assert fixed.controller.k1 == pytest.approx(2.6, rel=1e-6)


def test_fit_on_a_data_sheet_is_the_one_fit_on_the_rotary_preset(tmp_path, monkeypatch):
    """``flexarm fit LOG --gear-ratio 70 ...`` hands the preset built from the options and
    the grouped options to ``flexarm.fit``, nothing else (the fit stopped at once)."""
    from flexarm.errors import FitInterrupted
    from flexarm.identification.time_domain import engine
    from flexarm.identification.time_domain.options import FitOptions

    seen = {}

    def fake(model, logs, free=None, options=None, **kw):
        seen.update(model=model, logs=logs, free=free, options=options)
        raise FitInterrupted(None)

    monkeypatch.setattr(engine, "fit", fake)
    log = _log(tmp_path / "run.csv")
    r = runner.invoke(
        app,
        ["fit", str(log), "--gear-ratio", "70", "--motor-constant", "0.00768"]
        + ["--armature-resistance", "2.6", "--link-length", "0.42"]
        + ["--window", "0:0.3", "--delay-search", "both"],
    )
    assert r.exit_code == 130, r.output
    p, opts = seen["model"], seen["options"]
    assert p.engine == "servo_rig" and p.sheet["gear_ratio"] == 70.0
    assert p.sheet["motor_constant"] == 0.00768 and p.sheet["link_length"] == 0.42
    assert isinstance(opts, FitOptions) and opts.servo_rig is not None
    assert opts.servo_rig.delay_search == "both"
    assert opts.windows == [(0.0, 0.3)] and seen["free"] is None
    assert [g.name for g in seen["logs"]] == ["run.csv"]


def test_validate_keeps_same_named_logs_apart_in_json_and_table(tmp_path):
    """``flexarm validate`` of one servo-rig log given from two folders: the JSON is the one
    prediction's ``to_dict()`` with two entries ``a/run.csv`` and ``b/run.csv``, equal to
    each other (the same log, the same simulation: to 1e-9), both printed."""
    import json
    import shutil

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    src = _log(tmp_path / "a" / "run.csv", n=1000)
    shutil.copy(src, tmp_path / "b" / "run.csv")
    j = tmp_path / "v.json"
    r = runner.invoke(
        app,
        ["validate", "rotary-flexible-link", str(src), str(tmp_path / "b" / "run.csv")]
        + ["--json", str(j)],
    )
    assert r.exit_code == 0, r.output
    d = json.loads(j.read_text())
    assert set(d) == {
        "scenario",
        "fit_percent",
        "rmse",
        "nrmse",
        "diverged",
        "warnings",
        "notes",
    } | {"plots"}
    a, b = d["fit_percent"]["a/run.csv"], d["fit_percent"]["b/run.csv"]
    assert a["motor_angle"] == pytest.approx(b["motor_angle"], abs=1e-9)
    assert "a/run.csv" in r.output and "b/run.csv" in r.output
