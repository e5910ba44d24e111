"""Progress with elapsed time on every long step (issue #46 item 5): the CLI's
:class:`flexarm.cli.common.Working` prints each stage with the seconds since the job
began, and a "still:" line every HEARTBEAT_S seconds while one stage lasts; fit, validate,
design and fit-many run under it."""

from __future__ import annotations

import re
import time
from pathlib import Path

import flexarm.cli.common as common

ROOT = Path(__file__).resolve().parents[1]
LINE = re.compile(r"^\[\s*(\d+\.\d) s\] (.*)$")


class _Status:
    """A stand-in for rich's Status (not a terminal: the lines go to stderr)."""

    def __init__(self):
        self.texts = []

    def update(self, text):
        self.texts.append(text)


def test_each_stage_and_every_heartbeat_prints_the_elapsed_seconds(capsys, monkeypatch):
    """Stages print at once; a stage of 0.65 s with a 0.2 s heartbeat prints 3 "still:"
    lines (at 0.2, 0.4, 0.6 s: one per heartbeat, the thread wakes every 0.2 s); every
    line's seconds grow and match the wall clock within 0.15 s (a loaded 2-core machine's
    scheduling)."""
    monkeypatch.setattr(common, "HEARTBEAT_S", 0.2)
    st = _Status()
    t0 = time.perf_counter()
    with common.Working(st, "designing") as w:
        common.progress(w, "stage one")
        time.sleep(0.65)
        common.progress(w, "stage two")
    wall = time.perf_counter() - t0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    parsed = [LINE.match(ln) for ln in lines]
    assert all(parsed), lines
    secs = [float(m.group(1)) for m in parsed]
    texts = [m.group(2) for m in parsed]
    assert texts[:2] == ["designing", "stage one"] and texts[-2:] == [
        "stage two",
        "done: designing",
    ]
    assert 2 <= texts.count("still: stage one") <= 4, texts
    assert secs == sorted(secs) and abs(secs[-1] - wall) <= 0.15, (secs, wall)
    assert st.texts and st.texts[-1].startswith("stage two (")  # the status line ticks


def test_a_short_job_or_a_failed_one_prints_no_line(capsys, monkeypatch):
    """A job shorter than HEARTBEAT_S prints nothing (a bad input stays one line); one
    that raises after it stops its heartbeat (no "done:" line, no line after it)."""
    monkeypatch.setattr(common, "HEARTBEAT_S", 0.3)
    with common.Working(_Status(), "predicting") as w:
        common.progress(w, "stage")
    try:
        with common.Working(_Status(), "fitting"):
            raise KeyError("x")
    except KeyError:
        pass
    assert capsys.readouterr().err == ""
    monkeypatch.setattr(common, "HEARTBEAT_S", 0.05)
    try:
        with common.Working(_Status(), "fitting"):
            time.sleep(0.2)
            raise KeyError("x")
    except KeyError:
        pass
    n = len(capsys.readouterr().err.splitlines())
    time.sleep(0.2)
    assert capsys.readouterr().err == "" and n >= 2


def test_the_long_commands_run_under_it():
    """fit (both routes), validate, design and fit-many enter :func:`working`, not a bare
    status line."""
    cli = ROOT / "src" / "flexarm" / "cli"
    fit = (cli / "fit.py").read_text()
    assert fit.count("with working(") == 3 and "console.status(" not in fit
    design = (cli / "design.py").read_text()
    assert "with working(" in design and "console.status(" not in design
    assert "with working(" in (cli / "distributed.py").read_text()
