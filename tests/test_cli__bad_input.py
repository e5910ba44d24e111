"""Issue #45 item 4: the bad inputs that ended in "internal error" (exit 1) or ran on with
a nonsense value now end in one ``error:`` line and exit 2, naming the option or file:
numeric options checked at parse time (finite, in range), readers that refuse what is not
a regular file or is too large, nested TOML / JSON, a JSON list for an object, a UTF-16
manifest; and the exceptions that are inputs rather than bugs (cli/errors.input_error).

Fuzz class (hypothesis, derandomized): any float (NaN, ±inf, negatives, subnormals) for
``excite``'s --fs and --rms (40 examples): exit 0 or exit 2, never "internal error".
"""

from __future__ import annotations

import errno

import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.cli.errors import input_error

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

runner = CliRunner()
EXCITE = ["--fs", "1000", "--period", "1000", "--f-min", "1", "--f-max", "10"]
LAW = "state_feedback K1=6 K2=-40 K3=0.15 K4=0"


def _one_line(r, *words):
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.exit_code == 2, r.output
    assert len(lines) == 1 and lines[0].startswith("error:"), r.stderr
    assert "internal error" not in r.output
    for w in words:
        assert w in lines[0], lines[0]


@pytest.fixture
def inputs(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text(f"# controller: {LAW}\ntime,voltage,motor_angle\n0,0,0\n0.001,0,0\n")
    (tmp_path / "deep.toml").write_text("a = " + "[" * 3000 + "]" * 3000 + "\n")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp_path / "list.json").write_text("[1, 2, 3]")
    (tmp_path / "m16.csv").write_text("id,logs\nr1,log.csv\n", encoding="utf-16")
    (tmp_path / "big.csv").write_text("time,voltage,motor_angle\n0,0," + "1" * 5_000_000 + "\n")
    return tmp_path


NUMERIC = [
    (["excite", "{t}/e.csv", *EXCITE, "--fs", "0"], "--fs"),
    (["excite", "{t}/e.csv", *EXCITE, "--fs", "inf"], "--fs"),
    (["excite", "{t}/e.csv", *EXCITE, "--rms", "nan"], "--rms"),
    (["excite", "{t}/e.csv", *EXCITE, "--period", "0"], "--period"),
    (["excite", "{t}/e.csv", *EXCITE, "--f-min", "-1"], "--f-min"),
    (["excite", "{t}/e.csv", *EXCITE, "--periods", "0"], "--periods"),
    (["fit", "{t}/log.csv", "--computation-delay", "-1"], "--computation-delay"),
    (["fit", "{t}/log.csv", "--gear-ratio", "inf"], "--gear-ratio"),
    (["fit", "{t}/log.csv", "--encoder-counts", "0"], "--encoder-counts"),
    (["fit", "{t}/log.csv", "--voltage-limit", "nan"], "--voltage-limit"),
    (["fit", "{t}/log.csv", "--gear-efficiency", "1.5"], "--gear-efficiency"),
    (["tfest", "{t}/list.json", "--json", "{t}/t.json", "--gear-ratio", "-2"], "--gear-ratio"),
    (["frf", "{t}/log.csv", "--period", "0", "--json", "{t}/f.json"], "--period"),
]


@pytest.mark.parametrize("argv, option", NUMERIC, ids=[" ".join(a[:1] + [o]) for a, o in NUMERIC])
def test_a_numeric_option_out_of_range_is_refused_before_any_work(inputs, argv, option):
    r = runner.invoke(app, [a.replace("{t}", str(inputs)) for a in argv])
    _one_line(r, option)
    assert not (inputs / "e.csv").exists() and not (inputs / "f.json").exists()


READERS = [
    (["frf", "/dev/zero", "--json", "{t}/f.json"], "/dev/zero: not a regular file"),
    (
        ["frf", "{t}/log.csv", "--log-format", "/dev/zero", "--json", "{t}/f.json"],
        "/dev/zero: not a regular file",
    ),
    (["frf", "{t}/big.csv", "--json", "{t}/f.json"], "line 2: 5000004 characters"),
    (["simulate", "{t}/deep.toml", "--out", "{t}/o"], "nested too deeply"),
    (["tfest", "{t}/deep.json", "--json", "{t}/t.json"], "deep.json: nested too deeply"),
    (["tfest", "{t}/list.json", "--json", "{t}/t.json"], "list.json: a JSON list"),
    (["tfest", "/dev/zero", "--json", "{t}/t.json"], "/dev/zero: not a regular file"),
    (["fit-many", "{t}/m16.csv", "--out", "{t}/fm"], "not UTF-8 text"),
]


@pytest.mark.parametrize("argv, words", READERS, ids=[a[0] + " " + w[:20] for a, w in READERS])
def test_an_input_that_cannot_be_read_is_one_line(inputs, argv, words):
    r = runner.invoke(app, [a.replace("{t}", str(inputs)) for a in argv])
    _one_line(r, words)


def test_exceptions_that_are_inputs_are_told_apart_from_bugs():
    import json

    try:
        json.loads("[" * 100_000 + "]" * 100_000)
    except RecursionError as exc:
        assert "nested too deeply" in input_error(exc)

    def recurse(n):
        return recurse(n + 1)

    try:
        recurse(0)
    except RecursionError as exc:  # flexarm's own recursion: a bug, reported as such
        assert input_error(exc) is None
    assert "not enough memory" in input_error(MemoryError())
    full = OSError(errno.ENOSPC, "No space left on device", "/data/fit.json")
    assert input_error(full) == (
        "cannot write /data/fit.json: No space left on device; free space or choose another folder"
    )
    assert input_error(ZeroDivisionError("x")) is None


@settings(max_examples=40, deadline=None)
@given(fs=st.floats(allow_nan=True, allow_infinity=True), rms=st.floats(allow_nan=True))
def test_any_float_for_excite_is_a_result_or_one_line(tmp_path_factory, fs, rms):
    out = tmp_path_factory.mktemp("ex") / "e.csv"
    argv = ["excite", str(out), "--fs", repr(fs), "--period", "64", "--f-min", "1"]
    r = runner.invoke(app, [*argv, "--f-max", "10", "--rms", repr(rms)])
    assert r.exit_code in (0, 2), r.output
    assert "internal error" not in r.output
    if r.exit_code == 2:
        assert len([ln for ln in r.stderr.splitlines() if ln.strip()]) == 1


@pytest.mark.parametrize("shape", [(0, 0), (0,), (1, 0)])
def test_an_empty_mat_variable_is_named_not_an_internal_error(tmp_path, shape):
    import numpy as np
    import scipy.io as sio

    from flexarm.io.matfile import MatFileError, read_mat

    p = tmp_path / "rec.mat"
    sio.savemat(p, {"t": np.arange(5) * 1e-3, "u": np.zeros(shape)})
    with pytest.raises(MatFileError, match=r"\[columns\] voltage = 'u': u is empty"):
        read_mat(p, {"time": "t", "voltage": "u"})
