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

# issue #25's classes (one row or more each, below)
DIVERGE = "a closed loop that diverges (simulate)"
CONTROLLER = "a wrong-shape or unstable [controller]"
DURATION = "an impossible duration"
WINDOW = "a fit window shorter than the delay search"
TIME_UNIT = "a wrong time unit"
DAMAGED = "a damaged v7.3 .mat"
ABSURD = "a finite but absurd value (1e308) in a log"
STAMPS = "bad .mat time stamps (all zero, swapped, repeated)"
INPUT = "an output pointed at an input, with --overwrite"
EXISTS = "an existing output without --overwrite"

S = "feliu-single-mass"  # a built-in single-link scenario (bench path)
R = "rotary-flexible-link"  # a built-in voltage-servo rig
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
    (
        TOML,
        ["simulate", S, "--out", "{o}/sim", "--log", "{d}/bad.csv", "--log-format", "{d}/bad.toml"],
    ),
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
    (
        OPTION,
        ["scenario-from-mat", "{d}/garbage.mat", "--out", "{o}/s.toml", "--current-limits", "1,x"],
    ),
    (CHOICE, ["reproduce", "nobody", "--out", "{o}/r"]),
    (OUTPUT, ["demo", "--out", "{d}/bad.csv"]),
    (OUTPUT, ["example-logs", "{d}/bad.csv"]),
    (OPTION, ["example-logs", "{o}/ex", "--seconds", "1"]),
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
    (PARSER, ["fit", "{d}/bad.csv", "--global-starts", "0"]),
    (MISSING, ["validate", R, "{d}/nope.csv"]),
    (LOG, ["validate", R, "{d}/bad.csv"]),
    (TOML, ["validate", "{d}/bad.toml", "{d}/bad.csv"]),
    (OPTION, ["validate", R, "{d}/bad.csv", "--window", "a:b"]),
    (OPTION, ["validate", R, "{d}/bad.csv", "--refit", "friction", "--refit-window", "2:1"]),
    (MISSING, ["export-c", "{d}/nope", "--out", "{o}/c"]),
    (TOML, ["export-c", "{d}/bad.toml", "--out", "{o}/c"]),
    (CHOICE, ["excite", "{o}/x.csv", *EXCITE, "--kind", "bogus"]),
    (
        PARSER,
        [
            "excite",
            "{o}/x.csv",
            "--fs",
            "fast",
            "--period",
            "1000",
            "--f-min",
            "1",
            "--f-max",
            "10",
        ],
    ),
    (MISSING, ["frf", "{d}/nope.csv", "--json", "{o}/f.json"]),
    (LOG, ["frf", "{d}/bad.csv", "--json", "{o}/f.json"]),
    (TOML, ["frf", "{d}/bad.csv", "--log-format", "{d}/bad.toml", "--json", "{o}/f.json"]),
    (MAT, ["frf", "{d}/garbage.mat", "--json", "{o}/f.json"]),
    (CHOICE, ["frf", "{d}/bad.csv", "--method", "guess", "--json", "{o}/f.json"]),
    (OPTION, ["frf", "{d}/bad.csv", "--period", "lots", "--json", "{o}/f.json"]),
    (MISSING, ["tfest", "{d}/nope.json", "--poles", "2", "--zeros", "0", "--json", "{o}/t.json"]),
    (JSON, ["tfest", "{d}/bad.json", "--poles", "2", "--zeros", "0", "--json", "{o}/t.json"]),
    (JSON, ["tfest", "{d}/not-frf.json", "--poles", "2", "--zeros", "0", "--json", "{o}/t.json"]),
    (MISSING, ["friction", "{d}/nope.json", "{d}/nope2.json", "--json", "{o}/fr.json"]),
    (JSON, ["friction", "{d}/bad.json", "{d}/bad.json", "--json", "{o}/fr.json"]),
    (PARSER, ["friction", "{d}/bad.json", "--iterations", "x", "--json", "{o}/fr.json"]),
    (MISSING, ["fit-many", "{d}/nope.csv", "--out", "{o}/fm"]),
    (LOG, ["fit-many", "{d}/bad.csv", "--out", "{o}/fm"]),
    (OPTION, ["fit-many", "{d}/bad.csv", "--out", "{o}/fm", "--workers", "0"]),
]

# the data sheet and the declared law of the simulated rotary rig's log (trial.csv)
DS = [
    "--gear-ratio",
    "70",
    "--motor-constant",
    "7.68e-3",
    "--armature-resistance",
    "2.6",
    "--link-length",
    "0.42",
    "--gear-efficiency",
    "0.9",
    "--motor-efficiency",
    "0.69",
    "--controller",
    "state_feedback K1=6 K2=-40 K3=0.15 K4=0",
    "--seconds",
    "2",
]
#: the fit's progress lines on stderr before an error (cli.common.progress)
PROGRESS = {"estimates: hub-to-tip model, hub delay, link frequency"}
FRF = ["--period", "500"]
# (class, argv, a word the one line must hold, xfail reason or None)
CASES_25 = [
    (DIVERGE, ["simulate", "{d}/diverge.toml", "--out", "{o}/s"], "diverged", None),
    (CONTROLLER, ["simulate", "{d}/ctrl-shape.toml", "--out", "{o}/s"], "D is 2 × 2", None),
    (CONTROLLER, ["simulate", "{d}/ctrl-unstable.toml", "--out", "{o}/s"], "unstable", None),
    (DURATION, ["simulate", "{d}/duration.toml", "--out", "{o}/s"], "duration", None),
    (
        WINDOW,
        ["fit", "{d}/trial.csv", *DS, "--window", "0:0.07", "--json", "{o}/f.json"],
        "window",
        None,
    ),
    (
        TIME_UNIT,
        ["fit", "{d}/trial.csv", *DS, "--unit", "time=ms", "--json", "{o}/f.json"],
        "time",
        None,
    ),
    (
        DAMAGED,
        ["frf", "{d}/damaged73.mat", "--log-format", "{d}/mat.toml", "--json", "{o}/f.json"],
        "damaged73.mat",
        None,
    ),
    (ABSURD, ["frf", "{d}/huge.csv", *FRF, "--json", "{o}/f.json"], "1e+308", None),
    (
        STAMPS,
        ["frf", "{d}/t-zeros.mat", "--log-format", "{d}/mat.toml", "--json", "{o}/f.json"],
        "time stamps are 0",
        None,
    ),
    (
        STAMPS,
        ["frf", "{d}/t-swap.mat", "--log-format", "{d}/mat.toml", "--json", "{o}/f.json"],
        "swapped",
        None,
    ),
    (
        STAMPS,
        ["frf", "{d}/t-repeat.mat", "--log-format", "{d}/mat.toml", "--json", "{o}/f.json"],
        "time repeats",
        None,
    ),
    (
        INPUT,
        ["frf", "{d}/rec.csv", *FRF, "--json", "{d}/rec.csv", "--overwrite"],
        "is an input",
        None,
    ),
    (
        INPUT,
        [
            "tfest",
            "{d}/frf.json",
            "--poles",
            "2",
            "--zeros",
            "0",
            "--json",
            "{d}/frf.json",
            "--overwrite",
        ],
        "is an input",
        None,
    ),
    (
        INPUT,
        ["fit", "{d}/trial.csv", *DS, "--json", "{d}/trial.csv", "--overwrite"],
        "is an input",
        None,
    ),
    (
        INPUT,
        [
            "validate",
            R,
            "{d}/trial.csv",
            "--controller",
            DS[-3],
            "--json",
            "{d}/trial.csv",
            "--overwrite",
        ],
        "is an input",
        None,
    ),
    (EXISTS, ["frf", "{d}/rec.csv", *FRF, "--json", "{d}/not-frf.json"], "--overwrite", None),
    (
        EXISTS,
        ["frf", "{d}/rec.csv", *FRF, "--json", "{o}/f.json", "--plots", "{d}"],
        "--overwrite",
        None,
    ),
    (
        EXISTS,
        ["tfest", "{d}/frf.json", "--poles", "2", "--zeros", "0", "--json", "{d}/not-frf.json"],
        "--overwrite",
        None,
    ),
    (
        EXISTS,
        ["friction", "{d}/frf.json", "{d}/frf.json", "--json", "{d}/not-frf.json"],
        "--overwrite",
        None,
    ),
]


def _rows():
    rows = [
        pytest.param(c, a, None, id=" ".join(a[:1] + [c.split(" (")[0]]) + f"-{i}")
        for i, (c, a) in enumerate(CASES)
    ]
    for i, (c, a, word, xf) in enumerate(CASES_25):
        marks = [pytest.mark.xfail(strict=True, reason=xf)] if xf else []
        rows.append(pytest.param(c, a, word, marks=marks, id=f"{a[0]} #25 {c.split(' (')[0]}-{i}"))
    return rows


def _periodic(path: Path, spike: bool = False):
    """A 4-period multisine recording (1 kHz, 500 samples a period, odd lines 1..19) of
    current → motor_angle through a 3-tap filter; with ``spike`` one 1e308 value."""
    import numpy as np

    t = np.arange(2000) / 1000.0
    u = sum(np.cos(2 * np.pi * k * 2.0 * t + k) for k in range(1, 20, 2))
    y = np.convolve(u, [0.1, 0.05, 0.02])[: len(u)]
    if spike:
        y[700] = 1e308
    np.savetxt(path, np.c_[t, u, y], delimiter=",", header="time,current,motor_angle", comments="")
    return t, u, y


def _inputs_25(d: Path) -> None:
    """The inputs of issue #25's rows (scenarios, logs, .mat files, an FRF JSON)."""
    import json

    import numpy as np
    import scipy.io as sio
    import tomli_w

    from flexarm.specs import load_scenario

    t, u, y = _periodic(d / "rec.csv")
    _periodic(d / "huge.csv", spike=True)
    (d / "mat.toml").write_text('[columns]\ntime = "t"\ncurrent = "u"\nmotor_angle = "th"\n')
    for kind in ("zeros", "swap", "repeat"):
        tt = t.copy()
        if kind == "zeros":
            tt[:] = 0.0
        elif kind == "swap":
            tt[[10, 11]] = tt[[11, 10]]
        else:
            tt[11] = tt[10]
        sio.savemat(d / f"t-{kind}.mat", {"t": tt[:, None], "u": u[:, None], "th": y[:, None]})
    h5py = pytest.importorskip("h5py")
    p = d / "damaged73.mat"
    with h5py.File(p, "w") as f:
        for name, x in (("t", t), ("u", u), ("th", y)):
            f.create_dataset(name, data=x[None, :])
            f[name].attrs["MATLAB_class"] = np.bytes_("double")
    p.write_bytes(p.read_bytes()[:600])  # cut short: the signature kept, the data gone
    base = load_scenario(R).model_dump(mode="json", exclude_none=True)

    def scenario(name, **changes):
        x = json.loads(json.dumps(base))
        x["simulation"]["duration"] = 0.5
        for k, v in changes.items():
            node = x
            keys = k.split(".")
            for kk in keys[:-1]:
                node = node[kk]
            node[keys[-1]] = v
        (d / name).write_bytes(tomli_w.dumps(x).encode())

    # positive feedback of the hub angle and no amplifier limit: the loop grows without bound
    scenario(
        "diverge.toml",
        **{
            "controller.k1": -1e6,
            "actuator.limit": 1e12,
            "arm.motor.voltage_limit": 1e12,
            "simulation.duration": 3.0,
        },
    )
    scenario("duration.toml", **{"simulation.duration": 1e9})  # 1e12 samples
    (d / "ctrl-shape.json").write_text(json.dumps({"D": [[1.0, 2.0], [3.0, 4.0]]}))
    (d / "ctrl-unstable.json").write_text(
        json.dumps({"A": [[2.0]], "B": [[1.0]], "C": [[1.0]], "D": [[0.0]]})
    )
    lti = {
        "type": "lti",
        "inputs": ["motor_angle"],
        "setpoints": ["reference"],
        "outputs": ["voltage"],
    }
    scenario("ctrl-shape.toml", controller={**lti, "file": "ctrl-shape.json"})
    scenario("ctrl-unstable.toml", controller={**lti, "file": "ctrl-unstable.json"})
    # a closed-loop log of the rig (its own simulation, 1 s)
    scenario("trial-rig.toml", **{"simulation.duration": 1.0})
    r = runner.invoke(app, ["simulate", str(d / "trial-rig.toml"), "--out", str(d / "sim")])
    assert r.exit_code == 0, r.output
    (d / "sim" / f"{R}.csv").rename(d / "trial.csv")
    import shutil

    shutil.rmtree(d / "sim")
    r = runner.invoke(app, ["frf", str(d / "rec.csv"), *FRF, "--json", str(d / "frf.json")])
    assert r.exit_code == 0, r.output


def _inputs(d: Path) -> None:
    d.mkdir()
    (d / "bad.toml").write_text('name = "unterminated\n[arm\n')
    (d / "bad.csv").write_text("this is not a log\n1;2;x\n\x00\x01\n")
    (d / "bad.json").write_text('{"frequency_hz": [1, 2,')
    (d / "not-frf.json").write_text('{"hello": "world"}\n')
    (d / "garbage.mat").write_bytes(b"MATLAB 5.0 MAT-file" + bytes(range(256)) * 4)
    _inputs_25(d)


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
    assert {c for c, _ in CASES} == {MISSING, OPTION, PARSER, TOML, LOG, MAT, JSON, CHOICE, OUTPUT}
    # issue #25: 10 more classes, 19 more rows; 19 classes in all
    assert {c for c, *_ in CASES_25} == {
        DIVERGE,
        CONTROLLER,
        DURATION,
        WINDOW,
        TIME_UNIT,
        DAMAGED,
        ABSURD,
        STAMPS,
        INPUT,
        EXISTS,
    }
    assert len({c for c, _ in CASES} | {c for c, *_ in CASES_25}) == 19


@pytest.mark.parametrize("cls, argv, word", _rows())
def test_bad_input_is_one_line_exit_2_no_traceback_inputs_unchanged(
    cls, argv, word, inputs, tmp_path
):
    before = _hashes(inputs)
    args = [a.replace("{d}", str(inputs)).replace("{o}", str(tmp_path)) for a in argv]
    r = runner.invoke(app, args)
    # stderr: a long command's progress lines (stages, when stderr is not a terminal), then
    # the error as the one last line
    lines = [ln for ln in r.stderr.splitlines() if ln.strip() and ln not in PROGRESS]
    assert r.exit_code == 2, (cls, r.exit_code, r.output)
    assert len(lines) == 1 and lines[0].startswith("error: "), (cls, r.stderr)
    assert word is None or word in lines[0], (word, lines[0])
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
    assert len(lines) == 1 and lines[0].startswith(
        "internal error: RuntimeError: the list of scenarios: broke"
    ), r.stderr
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
    assert r.stderr.strip() == (
        "error: trial1.csv: column 'time', row 3: 'x' is not a number; fix the row"
    )


def test_version():
    r = runner.invoke(app, ["--version"])
    assert r.exit_code == 0 and r.stdout.strip() == f"flexarm {__version__}"


def test_python_dash_m_flexarm_runs_the_cli():
    import os
    import subprocess
    import sys

    src = str(Path(__file__).resolve().parents[1] / "src")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    p = subprocess.run(
        [sys.executable, "-m", "flexarm", "--version"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert p.returncode == 0 and p.stdout.strip() == f"flexarm {__version__}", p.stderr


def test_two_logs_of_the_same_name_are_two_entries(inputs, tmp_path):
    """Two `trial1.csv` in different folders: two result entries (keys relative to the
    common folder: a/trial1.csv, b/trial1.csv), not one that the second overwrote."""
    import json
    import shutil

    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(inputs / "trial.csv", tmp_path / sub / "trial1.csv")
    out = tmp_path / "f.json"
    r = runner.invoke(
        app,
        [
            "fit",
            str(tmp_path / "a" / "trial1.csv"),
            str(tmp_path / "b" / "trial1.csv"),
            *DS,
            "--json",
            str(out),
        ],
    )
    assert r.exit_code == 0, r.output
    assert set(json.loads(out.read_text())["fit_percent"]) == {"a/trial1.csv", "b/trial1.csv"}


def test_guarded_declares_the_inputs_and_ends_an_interrupt_with_128_plus_the_signal(tmp_path):
    """`cli.common.guarded`: inside it an input file cannot be written over (overwrite or
    not), a missing path or a built-in scenario name is skipped; `Interrupted` (SIGTERM)
    ends the command with exit 143, Ctrl-C with 130, each with one line."""
    import typer

    from flexarm.cli.common import guarded
    from flexarm.errors import InputOverwriteError, Interrupted
    from flexarm.io.write import write_text

    log = tmp_path / "log.csv"
    log.write_text("time\n0\n")
    with guarded([log, None], "rotary-flexible-link", tmp_path / "nope.csv"):
        with pytest.raises(InputOverwriteError):
            write_text(log, "x", overwrite=True)
        write_text(tmp_path / "out.json", "{}")
    assert log.read_text() == "time\n0\n"
    write_text(log, "y", overwrite=True)  # outside, a file like any other
    for exc, code in (
        (Interrupted("stopped by SIGTERM", signal="SIGTERM", number=15), 143),
        (KeyboardInterrupt(), 130),
    ):
        with pytest.raises(typer.Exit) as info:
            with guarded():
                raise exc
        assert info.value.exit_code == code


def test_a_failed_final_write_is_rescued_next_to_the_path_and_said(inputs, tmp_path, monkeypatch):
    """`tfest --json`: the final write fails (a full disk, simulated: OSError ENOSPC for
    the path asked for); the result is saved as <stem>.rescued-<UTC>.json beside it, one
    error line names it, exit 2 (the command did not write where asked; issue #45)."""
    import errno
    import json

    import flexarm.io.write as w

    target = tmp_path / "t.json"
    real = w.write_text

    def full_disk(path, text, **kw):
        if Path(path) == target:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, text, **kw)

    monkeypatch.setattr(w, "write_text", full_disk)
    r = runner.invoke(
        app,
        ["tfest", str(inputs / "frf.json"), "--poles", "2", "--zeros", "0", "--json", str(target)],
    )
    assert r.exit_code == 2, r.output
    assert r.stderr.startswith("error: --json: could not write")
    saved = list(tmp_path.glob("t.rescued-*.json"))
    assert not target.exists() and len(saved) == 1
    assert "No space left on device" in r.stderr and saved[0].name in r.stderr.replace("\n", "")
    assert json.loads(saved[0].read_text())["den"]  # the fitted model, complete
