"""io/write.py: the one output policy (issue #45): names are data (``safe_name``,
``distinct_names``), all of a command's outputs checked together before any work
(``check_outputs``), one writer per output folder (``lock_folder`` in a ``run_scope``),
bounded reading of inputs (``read_input``); and the commands that use them: simulate's
``<name>.*`` files, fit-many's ids and folders, fit's output options.

Fuzz class (hypothesis, derandomized): any Unicode text as a name (200 examples): either
refused in one line or a file name of letters, digits and ``._-`` that stays in its folder.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.errors import FlexarmError, InputOverwriteError, OutputExistsError
from flexarm.io import write

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import example, given, settings  # noqa: E402 - optional: after importorskip
from hypothesis import strategies as st  # noqa: E402 - optional: after importorskip

runner = CliRunner()


# ------------------------------------------------------------------ names
@pytest.mark.parametrize(
    "name, want",
    [
        ("rig", "rig"),
        ("../victim", "___victim"),
        ("/tmp/abs", "_tmp_abs"),
        ("a\x00b", "a_b"),
        ("-rf", "_rf"),
        (".hidden", "_hidden"),
        ("Unit 7 (trial 1)", "Unit_7__trial_1_"),
        ("θ-tip", "_-tip"),
    ],
)
def test_safe_name_keeps_a_name_in_its_folder(name, want):
    assert write.safe_name(name) == want


@pytest.mark.parametrize("name", ["", ".", "..", "...", "/", "\x00", "x" * 101, "---"])
def test_a_name_that_cannot_be_made_safe_is_refused_in_one_line(name):
    with pytest.raises(FlexarmError) as e:
        write.safe_name(name, what="scenario name")
    msg = str(e.value)
    assert "scenario name" in msg and "\n" not in msg and len(msg) < 300


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=120))
@example("../../etc/passwd")
@example("a/../../b")
@example("..\\..\\x")
def test_any_text_is_refused_or_a_file_name_inside_its_folder(tmp_path_factory, text):
    try:
        n = write.safe_name(text)
    except FlexarmError as exc:
        assert "\n" not in str(exc)
        return
    folder = Path("/srv/out")
    assert 1 <= len(n) <= write.NAME_MAX and n not in (".", "..")
    assert all(c.isascii() and (c.isalnum() or c in "._-") for c in n)
    assert n[0] not in ".-"
    assert os.path.normpath(folder / n) == str(folder / n)  # no .., no separator


def test_two_scenarios_of_one_name_get_distinct_stated_names():
    assert write.distinct_names(["rig", "rig", "Rig", "r/g", "r_g"]) == [
        "rig",
        "rig-2",
        "Rig-3",
        "r_g",
        "r_g-2",
    ]


# ------------------------------------------------------------------ outputs of one run
def test_outputs_are_checked_together_before_the_work(tmp_path):
    a = tmp_path / "a"
    with pytest.raises(OutputExistsError, match="--scenario-out .*the same path as --json"):
        write.check_outputs([("--json", a), ("--scenario-out", tmp_path / "x" / ".." / "a")])
    src = tmp_path / "in.mat"
    src.write_bytes(b"x")
    with write.inputs([src]), pytest.raises(InputOverwriteError, match="input of this run"):
        write.check_outputs([("--out", src)], overwrite=True)
    with pytest.raises(OutputExistsError, match="exists already"):
        write.check_outputs([("--out", src)])
    write.check_outputs([("--out", src), ("--json", None)], overwrite=True)


def test_a_second_writer_into_the_same_folder_is_refused(tmp_path):
    out = tmp_path / "out"
    with write.run_scope():
        write.output_folder(out)
        assert (out / write.LOCK_NAME).is_file()
        write.output_folder(out)  # the same run again: its own lock is no file of others
        with write.run_scope():  # another command, same time, same folder
            with pytest.raises(OutputExistsError, match="another flexarm run is writing"):
                write.output_folder(out, overwrite=True)
    assert not (out / write.LOCK_NAME).exists()  # released with the run
    assert list(out.iterdir()) == []


def test_inputs_that_are_not_regular_files_or_too_large_are_not_read(tmp_path):
    with pytest.raises(FlexarmError, match="not a regular file"):
        write.read_input("/dev/zero")
    big = tmp_path / "big.csv"
    big.write_bytes(b"1" * 2000)
    with pytest.raises(FlexarmError, match="2000 bytes, more than the 1000"):
        write.read_input(big, limit=1000)
    assert write.read_input(big, limit=2000) == b"1" * 2000


# ------------------------------------------------------------------ simulate's files
def _scenario(tmp_path, tag, name):
    import tomli_w

    from flexarm.specs import load_scenario

    d = load_scenario("feliu-single-mass").model_dump(mode="json", exclude_none=True)
    d["name"], d["simulation"]["duration"] = name, 0.2
    p = tmp_path / f"{tag}.toml"
    p.write_text(tomli_w.dumps(d))
    return p


def test_simulate_writes_names_inside_out_distinct_and_never_over_a_run(tmp_path):
    victim = tmp_path / "victim.csv"
    victim.write_text("mine\n")
    out = tmp_path / "o" / "sub"
    trav = _scenario(tmp_path, "trav", "../../victim")
    a1, a2 = _scenario(tmp_path, "a1", "rig"), _scenario(tmp_path, "a2", "rig")
    r = runner.invoke(app, ["simulate", str(trav), str(a1), str(a2), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert victim.read_text() == "mine\n"
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        f"{s}.{e}" for s in ("___.._victim", "rig", "rig-2") for e in ("csv", "png", "summary.json")
    )
    assert '"file_name_from": "rig"' in r.stdout and '"rig-2"' in r.stdout
    r = runner.invoke(app, ["simulate", str(a1), "--out", str(out)])  # a second run
    assert r.exit_code == 2 and "--overwrite" in r.stderr
    for bad, why in (("", "needs a letter or digit"), ("x" * 300, "300 characters")):
        r = runner.invoke(
            app, ["simulate", str(_scenario(tmp_path, "b", bad)), "--out", str(tmp_path / "q")]
        )
        assert r.exit_code == 2 and why in r.stderr and "internal error" not in r.output


# ------------------------------------------------------------------ fit-many
def _manifest(tmp_path, rows, name="m.csv"):
    p = tmp_path / name
    p.write_text("id,logs\n" + "".join(f"{i},{lg}\n" for i, lg in rows))
    return p


@pytest.mark.parametrize("rid", ["..", ".", ".x", "-x", "a/b", "summary.csv", "x" * 101])
def test_a_manifest_id_that_is_not_a_safe_folder_name_is_refused(tmp_path, rid):
    import flexarm.distributed as fd

    (tmp_path / "a.csv").write_text("t\n0\n")
    with pytest.raises(fd.ManifestError, match="give a folder name"):
        fd.read_manifest(_manifest(tmp_path, [(rid, "a.csv")]))


def test_ids_alike_but_for_case_are_refused(tmp_path):
    import flexarm.distributed as fd

    (tmp_path / "a.csv").write_text("t\n0\n")
    with pytest.raises(fd.ManifestError, match="used by an earlier row"):
        fd.read_manifest(_manifest(tmp_path, [("Rig", "a.csv"), ("rig", "a.csv")]))


def test_fit_many_writes_only_into_its_own_folder_and_rows(tmp_path):
    import json

    import flexarm.distributed as fd

    (tmp_path / "a.csv").write_text("t\n0\n")
    m = _manifest(tmp_path, [("r1", "a.csv")])
    rows = fd.read_manifest(m)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match="not this manifest's fit-many results"):
        fd.fit_many_todo(rows, out, m)
    assert fd.fit_many_todo(rows, out, m, overwrite=True) == rows
    # a manifest named summary.csv inside --out is never written over
    inner = _manifest(out, [("r1", str(tmp_path / "a.csv"))], name="summary.csv")
    with pytest.raises(InputOverwriteError, match="its summary.csv is the manifest"):
        fd.fit_many_todo(fd.read_manifest(inner), out, inner, overwrite=True)
    # a finished fit of another row is not resumed as this one's, nor written over
    own = tmp_path / "own"
    (own / "r1").mkdir(parents=True)
    (own / "summary.csv").write_text("id\n")
    other = {"flexarm_fit_many": {"status": "done", "row": {"id": "r1", "logs": ["b.csv"]}}}
    (own / "r1" / "fit.json").write_text(json.dumps(other))
    with pytest.raises(OutputExistsError, match="a finished fit of another row"):
        fd.fit_many_todo(rows, own, m)
    assert fd.fit_many_todo(rows, own, m, overwrite=True) == rows
    import dataclasses

    mine = {"flexarm_fit_many": {"status": "done", "row": dataclasses.asdict(rows[0])}}
    (own / "r1" / "fit.json").write_text(json.dumps(mine, default=str))
    assert fd.fit_many_todo(rows, own, m) == []  # its own finished row: resumed (skipped)


# ------------------------------------------------------------------ fit's outputs
def test_fit_refuses_two_outputs_on_one_path_before_the_fit(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("# controller: state_feedback K1=6 K2=-40 K3=0.15 K4=0\ntime,voltage\n0,0\n")
    (tmp_path / "o").mkdir()
    a = tmp_path / "o" / "a"
    r = runner.invoke(app, ["fit", str(log), "--json", str(a), "--scenario-out", str(a)])
    assert r.exit_code == 2, r.output
    assert "--scenario-out" in r.stderr and "the same path as --json" in r.stderr


def test_scenario_from_mat_never_writes_over_its_input(tmp_path):
    ws = tmp_path / "X.mat"
    ws.write_bytes(b"MATLAB 5.0 MAT-file, not really")
    before = ws.read_bytes()
    r = runner.invoke(app, ["scenario-from-mat", str(ws), "--out", str(ws), "--overwrite"])
    assert r.exit_code == 2, r.output
    assert "is an input of this run" in r.stderr and "internal error" not in r.output
    assert ws.read_bytes() == before


def test_demo_refuses_a_folder_holding_files(tmp_path):
    (tmp_path / "feliu-single-mass.csv").write_text("mine\n")
    r = runner.invoke(app, ["demo", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "--overwrite" in r.stderr, r.output
    assert (tmp_path / "feliu-single-mass.csv").read_text() == "mine\n"


@pytest.mark.parametrize("cmd", ["fit", "validate"])
def test_plots_folders_holding_files_are_refused_before_the_work(tmp_path, cmd):
    plots = tmp_path / "plots"
    plots.mkdir()
    (plots / "overlay.png").write_bytes(b"earlier figure")
    log = tmp_path / "l.csv"
    log.write_text("time,motor_angle\n")
    head = ["validate", "feliu-single-mass"] if cmd == "validate" else ["fit"]
    r = runner.invoke(app, [*head, str(log), "--plots", str(plots)])
    assert r.exit_code == 2, r.output
    assert "--plots" in r.stderr and "holds files already" in r.stderr
    assert (plots / "overlay.png").read_bytes() == b"earlier figure"
