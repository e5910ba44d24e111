"""`flexarm fit LOG...` (the rotary servo route) names every missing data-sheet value by
its option, in one line, once the log is read and before any work on it (the declared
law's check, the fit; issue #46 item 4)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexarm.analysis.example_logs import write_example_logs
from flexarm.cli import app

runner = CliRunner()
FORMAT = str(Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml")


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    d = tmp_path_factory.mktemp("sheet")
    return write_example_logs(d, which=("rotary-rigid",), duration=3.0).files["rotary-rigid"]


def _error(args):
    r = runner.invoke(app, ["fit", *args])
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    return r.exit_code, lines, r.stdout


def test_every_missing_value_is_named_by_its_option_before_any_work(log):
    code, lines, out = _error([str(log), "--log-format", FORMAT, "--gear-ratio", "48.4"])
    assert code == 2 and len(lines) == 1, lines
    msg = lines[0]
    for opt in ("--motor-constant", "--armature-resistance", "--link-length"):
        assert opt in msg, msg
    assert "field" not in msg and "None" not in msg
    assert "controller check" not in out  # the declared law was not checked yet


def test_a_current_drive_needs_no_resistance_and_one_value_missing_is_named_alone(log):
    base = [str(log), "--log-format", FORMAT]
    code, lines, _ = _error(
        [*base, "--drive", "current", "--motor-constant", "0.1", "--gear-ratio", "2"]
    )
    assert code == 2 and len(lines) == 1
    assert "--link-length" in lines[0] and "--armature-resistance" not in lines[0]
    assert "--motor-constant" not in lines[0]
    code, lines, _ = _error(
        [*base, "--motor-constant", "0.01", "--armature-resistance", "3",
         "--link-length", "0.4", "--gear-ratio", "0"]
    )  # fmt: skip
    # refused at parse time (the option's own check), before any log is read
    assert code == 2 and len(lines) == 1, lines
    assert "--gear-ratio" in lines[0] and "0.0" in lines[0] and "> 0" in lines[0], lines


def test_a_ms_clock_read_as_s_is_flagged_before_any_work(log, tmp_path):
    """The lab logger's ms column read without the format's [units] time = "ms": the
    loop looks like 1 Hz; the reader refuses it (io.checks.check_rate, no unit stated) in
    one line naming the log, the step and --unit time=ms, before the data sheet's refusal
    (and before the declared law's check).  slow_clock still warns on such a Log."""
    from dataclasses import replace

    import flexarm
    from flexarm.cli.fit import slow_clock

    fmt = tmp_path / "no-units.toml"
    text = Path(FORMAT).read_text()
    fmt.write_text(text.replace("[units]", "").replace('time = "ms"', ""))
    good = flexarm.load_log(log, FORMAT)
    assert slow_clock(good) is None  # 1 ms steps
    msg = slow_clock(replace(good, time=good.time * 1e3))
    assert msg is not None and "steps by 1 s" in msg and "--unit time=ms" in msg
    code, lines, out = _error([str(log), "--log-format", str(fmt)])
    assert code == 2 and len(lines) == 1, lines
    assert lines[0].startswith("error: ") and "--unit time=ms" in lines[0]
    assert "a sampling rate of 1 Hz" in lines[0] and "no time unit stated" in lines[0]
    assert "controller check" not in out
