"""Every command with bad input (issue #25 item 3): one line on stderr, exit 2, no
traceback, the inputs unchanged; an internal error: one line naming a log file that holds
the traceback, exit 1; ``flexarm --version``."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexarm import __version__
from flexarm.cli import app

runner = CliRunner()

# The bad-input classes the table covers (each row names one).
MISSING = "missing file"
OPTION = "malformed option value (the command's own parsing)"
PARSER = "option the parser refuses (type, unknown, missing required)"
TOML = "bad TOML (scenario or log format)"
LOG = "bad log (text)"
MAT = "bad MAT file"
JSON = "bad JSON"
CHOICE = "value outside the choices"
OUTPUT = "an output path that cannot be written (a file for a folder, a missing folder)"

S = "feliu-single-mass"          # a built-in single-link scenario (bench path)
R = "rotary-flexible-link"       # a built-in voltage-servo rig
EXCITE = ["--fs", "1000", "--period", "1000", "--f-min", "1", "--f-max", "10"]

# (class, argv); {d}: the folder of inputs (hashed before and after), {o}: an output folder
CASES = [
    (PARSER, ["scenarios", "--bogus"]),
    (MISSING, ["info", "{d}/nope.toml"]),
    (TOML, ["info", "{d}/bad.toml"]),
    (MISSING, ["simulate", "{d}/nope.toml", "--out", "{o}/sim"]),
    (TOML, ["simulate", "{d}/bad.toml", "--out", "{o}/sim"]),
    (MISSING, ["simulate", S, "--out", "{o}/sim", "--log", "{d}/nope.csv"]),
    (LOG, ["simulate", S, "--out", "{o}/sim", "--log", "{d}/bad.csv"]),
    (TOML, ["simulate", S, "--out", "{o}/sim", "--log", "{d}/bad.csv", "--log-format",
            "{d}/bad.toml"]),
    (OPTION, ["simulate", S, "--out", "{o}/sim", "--log", "{d}/bad.csv", "--window", "5:x"]),
    (MISSING, ["design", "{d}/nope.toml", "--out", "{o}/d"]),
    (TOML, ["design", "{d}/bad.toml", "--out", "{o}/d"]),
    (OPTION, ["design", S, "--method", "place", "--poles", "-20,x", "--out", "{o}/d"]),
    (OPTION, ["design", S, "--q", "motor_angle=lots", "--out", "{o}/d"]),
    (JSON, ["design", S, "--fit-json", "{d}/bad.json", "--out", "{o}/d"]),
    (MISSING, ["design", S, "--fit-json", "{d}/nope.json", "--out", "{o}/d"]),
    (PARSER, ["design", S, "--plants", "abc", "--out", "{o}/d"]),
    (PARSER, ["design", S]),
    (CHOICE, ["design", S, "--method", "magic", "--out", "{o}/d"]),
    (MISSING, ["scenario-from-mat", "{d}/nope.mat", "--out", "{o}/s.toml"]),
    (MAT, ["scenario-from-mat", "{d}/garbage.mat", "--out", "{o}/s.toml"]),
    (OPTION, ["scenario-from-mat", "{d}/garbage.mat", "--out", "{o}/s.toml",
              "--current-limits", "1,x"]),
    (CHOICE, ["reproduce", "nobody", "--out", "{o}/r"]),
    (OUTPUT, ["demo", "--out", "{d}/bad.csv"]),
    (OUTPUT, ["simulate", S, "--out", "{d}/bad.csv/sim"]),
    (OUTPUT, ["fit", "{d}/bad.csv", "--json", "{o}/missing/f.json"]),
    (MISSING, ["experiment", "{d}/nope.toml", "--out", "{o}/e"]),
    (OPTION, ["experiment", S, "--out", "{o}/e", "--frequencies", "1,x"]),
    (MISSING, ["identify", "{d}/nope.csv", "--motor-constant", "0.25"]),
    (LOG, ["identify", "{d}/bad.csv", "--motor-constant", "0.25"]),
    (OPTION, ["identify", "{d}/bad.csv", "--motor-constant", "0.25", "--motor-orders", "2,x"]),
    (OPTION, ["identify", "{d}/bad.csv", "--motor-constant", "0.25", "--beam-orders", "2"]),
    (MISSING, ["fit", "{d}/nope.csv", "--gear-ratio", "70"]),
    (LOG, ["fit", "{d}/bad.csv", "--gear-ratio", "70"]),
    (OPTION, ["fit", "{d}/bad.csv", "--window", "5:x"]),
    (OPTION, ["fit", "{d}/bad.csv", "--validate-window", "3:1"]),
    (OPTION, ["fit", "{d}/bad.csv", "--sessions", "0,x"]),
    (TOML, ["fit", "{d}/bad.csv", "--log-format", "{d}/bad.toml"]),
    (TOML, ["fit", "{d}/bad.toml", "{d}/bad.csv"]),
    (LOG, ["fit", S, "{d}/bad.csv"]),
    (OPTION, ["fit", S, "{d}/bad.csv", "--prior", "arm.motor.inertia"]),
    (PARSER, ["fit", "{d}/bad.csv", "--gear-ratio", "seventy"]),
    (MISSING, ["validate", R, "{d}/nope.csv"]),
    (LOG, ["validate", R, "{d}/bad.csv"]),
    (TOML, ["validate", "{d}/bad.toml", "{d}/bad.csv"]),
    (OPTION, ["validate", R, "{d}/bad.csv", "--window", "a:b"]),
    (OPTION, ["validate", R, "{d}/bad.csv", "--refit", "friction", "--refit-window", "2:1"]),
    (MISSING, ["export-c", "{d}/nope", "--out", "{o}/c"]),
    (TOML, ["export-c", "{d}/bad.toml", "--out", "{o}/c"]),
    (CHOICE, ["excite", "{o}/x.csv", *EXCITE, "--kind", "bogus"]),
    (PARSER, ["excite", "{o}/x.csv", "--fs", "fast", "--period", "1000", "--f-min", "1",
              "--f-max", "10"]),
    (MISSING, ["frf", "{d}/nope.csv", "--json", "{o}/f.json"]),
    (LOG, ["frf", "{d}/bad.csv", "--json", "{o}/f.json"]),
    (TOML, ["frf", "{d}/bad.csv", "--log-format", "{d}/bad.toml", "--json", "{o}/f.json"]),
    (MAT, ["frf", "{d}/garbage.mat", "--json", "{o}/f.json"]),
    (CHOICE, ["frf", "{d}/bad.csv", "--method", "guess", "--json", "{o}/f.json"]),
    (OPTION, ["frf", "{d}/bad.csv", "--period", "lots", "--json", "{o}/f.json"]),
    (MISSING, ["tfest", "{d}/nope.json", "--poles", "2", "--zeros", "0", "--json", "{o}/t.json"]),
    (JSON, ["tfest", "{d}/bad.json", "--poles", "2", "--zeros", "0", "--json", "{o}/t.json"]),
    (JSON, ["tfest", "{d}/not-frf.json", "--poles", "2", "--zeros", "0", "--json",
            "{o}/t.json"]),
    (MISSING, ["friction", "{d}/nope.json", "{d}/nope2.json", "--json", "{o}/fr.json"]),
    (JSON, ["friction", "{d}/bad.json", "{d}/bad.json", "--json", "{o}/fr.json"]),
    (PARSER, ["friction", "{d}/bad.json", "--iterations", "x", "--json", "{o}/fr.json"]),
]


def _inputs(d: Path) -> None:
    d.mkdir()
    (d / "bad.toml").write_text('name = "unterminated\n[arm\n')
    (d / "bad.csv").write_text("this is not a log\n1;2;x\n\x00\x01\n")
    (d / "bad.json").write_text('{"frequency_hz": [1, 2,')
    (d / "not-frf.json").write_text('{"hello": "world"}\n')
    (d / "garbage.mat").write_bytes(b"MATLAB 5.0 MAT-file" + bytes(range(256)) * 4)


def _hashes(d: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.iterdir())}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli-bad") / "in"
    _inputs(d)
    return d


def test_the_table_covers_every_command_and_every_class():
    from typer.main import get_command

    commands = set(get_command(app).commands)
    assert {argv[0] for _, argv in CASES} == commands
    assert {c for c, _ in CASES} == {MISSING, OPTION, PARSER, TOML, LOG, MAT, JSON, CHOICE,
                                     OUTPUT}


@pytest.mark.parametrize("cls, argv", CASES, ids=[" ".join(a[:1] + [c.split(" (")[0]]) + f"-{i}"
                                                  for i, (c, a) in enumerate(CASES)])
def test_bad_input_is_one_line_exit_2_no_traceback_inputs_unchanged(cls, argv, inputs,
                                                                   tmp_path):
    before = _hashes(inputs)
    args = [a.replace("{d}", str(inputs)).replace("{o}", str(tmp_path)) for a in argv]
    r = runner.invoke(app, args)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2, (cls, r.exit_code, r.output)
    assert len(lines) == 1 and lines[0].startswith("error: "), (cls, r.stderr)
    assert "Traceback" not in r.output and "internal error" not in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), r.exception
    assert _hashes(inputs) == before


def test_an_internal_error_is_one_line_naming_a_log_with_the_traceback(tmp_path, monkeypatch):
    import flexarm.specs

    def broken():
        raise RuntimeError("the list of scenarios:\nbroke")

    monkeypatch.setattr(flexarm.specs, "builtin_scenarios", broken)
    monkeypatch.setenv("FLEXARM_LOG_DIR", str(tmp_path / "logs"))
    r = runner.invoke(app, ["scenarios"])
    assert r.exit_code == 1, r.output
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("internal error: RuntimeError: the list "
                                                   "of scenarios: broke"), r.stderr
    logs = list((tmp_path / "logs").iterdir())
    assert len(logs) == 1 and str(logs[0]) in lines[0]
    text = logs[0].read_text()
    assert "Traceback" in text and "def broken" not in text and "in broken" in text
    assert f"flexarm {__version__}" in text


def test_a_project_error_escaping_a_command_is_one_line_exit_2(monkeypatch):
    """A library error no command catches itself reaches the one handler."""
    import flexarm.specs
    from flexarm.io.logs import LogError

    def broken():
        raise LogError("trial1.csv: column 'time', row 3: 'x' is not a number; fix the row")

    monkeypatch.setattr(flexarm.specs, "builtin_scenarios", broken)
    r = runner.invoke(app, ["scenarios"])
    assert r.exit_code == 2, r.output
    assert r.stderr.strip() == ("error: trial1.csv: column 'time', row 3: 'x' is not a "
                                "number; fix the row")


def test_version():
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0 and r.stdout.strip() == f"flexarm {__version__}"


def test_python_dash_m_flexarm_runs_the_cli():
    import os
    import subprocess
    import sys

    src = str(Path(__file__).resolve().parents[1] / "src")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    p = subprocess.run([sys.executable, "-m", "flexarm", "--version"], capture_output=True,
                       text=True, env=env, timeout=120)
    assert p.returncode == 0 and p.stdout.strip() == f"flexarm {__version__}", p.stderr
