"""The command line: each command's happy path and its refusals."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app

runner = CliRunner()


def said(r) -> str:
    """The output with rich's line wrapping undone."""
    return " ".join(r.output.split())


def test_scenarios_lists_the_builtins():
    r = runner.invoke(app, ["scenarios"])
    assert r.exit_code == 0
    for name in ("feliu-single-mass", "feliu-two-mass", "rotary-flexible-link"):
        assert name in said(r)


def test_info_json_gives_eq_12_from_the_identified_scenario():
    r = runner.invoke(app, ["info", "feliu-single-mass-identified", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    m = d["transfer_functions"]["motor"]
    np.testing.assert_allclose(m["num"], 394.94 * np.array([1, 0.06, 43.75]), rtol=5e-3)
    np.testing.assert_allclose(m["den"][:4], [1, 2.26, 165.7, 103.56], rtol=5e-3)
    assert m["integrators"] == 1
    b = d["transfer_functions"]["beam"]
    assert b["static_gain"] == pytest.approx(1.0)
    assert b["natural_frequencies_rad_s"][0]["wn_rad_s"] == pytest.approx(np.sqrt(43.75))


def test_info_two_mass_reports_the_rhp_zero():
    r = runner.invoke(app, ["info", "feliu-two-mass", "--json"])
    d = json.loads(r.output)
    z = d["transfer_functions"]["beam"]["right_half_plane_zeros"]
    assert len(z) == 1 and z[0]["re"] == pytest.approx(np.sqrt(1273.3), rel=1e-2)


def test_simulate_writes_csv_figure_summary_and_refuses_to_overwrite(tmp_path):
    out = tmp_path / "sim"
    r = runner.invoke(app, ["simulate", "feliu-single-mass", "--out", str(out)])
    assert r.exit_code == 0, r.output
    for f in ("feliu-single-mass.csv", "feliu-single-mass.png", "feliu-single-mass.summary.json"):
        assert (out / f).stat().st_size > 0
    s = json.loads((out / "feliu-single-mass.summary.json").read_text())
    assert s["samples"] == 667 and s["peak_command"] <= 4.12
    before = (out / "feliu-single-mass.csv").read_bytes()
    r = runner.invoke(app, ["simulate", "feliu-single-mass", "--out", str(out)])
    assert r.exit_code == 2 and "--overwrite" in said(r)
    assert (out / "feliu-single-mass.csv").read_bytes() == before


def test_bad_scenario_exits_2_naming_the_field(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[arm.motor]\ndrive = "current"\ninertia = "-1 kg*m**2"\n')
    r = runner.invoke(app, ["info", str(bad)])
    assert r.exit_code == 2
    assert "arm.motor.inertia" in said(r) and "must be > 0" in said(r)


def test_validate_true_model_on_its_own_log_and_fit_without_controller(tmp_path):
    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.specs import load_scenario

    sc = load_scenario("rotary-flexible-link")
    log = synthetic_log(sc, [6.0, -3.0, 0.213, 0.0], tmp_path / "a.csv", duration=2.0)
    j = tmp_path / "v.json"
    r = runner.invoke(app, ["validate", "rotary-flexible-link", str(log), "--json", str(j)])
    assert r.exit_code == 0, r.output
    fit = json.loads(j.read_text())["fit_percent"]["a.csv"]
    assert fit["motor_angle"] > 99.0 and fit["tip_deflection"] > 98.0  # noise and quantisation
    lines = [ln for ln in log.read_text().splitlines() if not ln.startswith("# controller")]
    bare = tmp_path / "bare.csv"
    bare.write_text("\n".join(lines) + "\n")
    r = runner.invoke(
        app,
        [
            "fit",
            str(bare),
            "--gear-ratio",
            "70",
            "--motor-constant",
            "7.68e-3",
            "--armature-resistance",
            "2.6",
            "--link-length",
            "0.42",
        ],
    )
    assert r.exit_code == 2 and "no controller declared" in said(r) and "bare.csv" in said(r)


def test_identify_empty_folder_and_missing_column(tmp_path):
    r = runner.invoke(app, ["identify", str(tmp_path), "--motor-constant", "0.25"])
    assert r.exit_code == 2 and "no experiment logs" in said(r)
    f = tmp_path / "x.csv"
    f.write_text("time,reference,i,motor_angle,tip_angle\n0,0,0,0,0\n")
    r = runner.invoke(app, ["identify", str(f), "--motor-constant", "0.25"])
    assert r.exit_code == 2 and "current" in said(r)


def test_info_multilink_reports_modes_deflection_alpha_conditions():
    r = runner.invoke(app, ["info", "deluca-two-link", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert [ln["modes"] for ln in d["links"]] == [2, 2]
    f = d["links"][0]["frequencies_hz"]
    assert 0 < f[0] < f[1]
    k = np.asarray(d["links"][0]["stiffness_k_ij_N_per_m"])
    assert np.allclose(k, k.T) and np.all(np.linalg.eigvalsh(k) > 0)
    t = d["target"]
    # hanging arm raised to -45 deg: the first link sags downwards (negative first mode)
    assert t["delta_d_m"][0] < 0
    assert t["alpha"]["value"] > 0
    for c in ("14", "15"):
        cond = t["conditions"][c]
        assert cond["holds"] == (cond["margin"] > 0)


def test_multilink_regulation_joint_count_is_checked(tmp_path):
    from flexarm.specs import builtin_scenarios

    src = builtin_scenarios()["deluca-two-link"].read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(src.replace("kp = [18.0, 18.0]", "kp = [18.0]"))
    r = runner.invoke(app, ["info", str(bad)])
    assert r.exit_code == 2 and "kp has 1 entries; target has 2" in said(r)


@pytest.mark.slow
def test_fit_reports_with_and_without_friction(tmp_path):
    """`flexarm fit --compare-no-friction`: both fits in the table and the JSON, and the
    friction-free model fits the stick-slip log clearly worse."""
    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.specs import load_scenario

    log = synthetic_log(
        load_scenario("rotary-flexible-link"),
        [6.0, -3.0, 0.213, 0.0],
        tmp_path / "b.csv",
        duration=4.0,
        amplitude=(0.5, 0.15),
        period=3.0,
    )
    j = tmp_path / "f.json"
    r = runner.invoke(
        app,
        [
            "fit",
            str(log),
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
            "--seconds",
            "2",
            "--compare-no-friction",
            "--json",
            str(j),
        ],
    )
    assert r.exit_code == 0, r.output
    assert "fit % without" in said(r)
    d = json.loads(j.read_text())
    with_f = d["fit_percent"]["b.csv"]
    without = d["without_friction"]["fit_percent"]["b.csv"]
    assert with_f["tip_deflection"] > without["tip_deflection"] + 10


def test_fit_and_validate_read_logs_in_other_names_and_units(tmp_path):
    """A rig's own log (other column names, degrees, millimetres) read with --column/--unit
    gives the same validation as the same log in SI; bad mapping options are named."""
    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.io.logs import read_log, write_log
    from flexarm.specs import load_scenario

    si = synthetic_log(
        load_scenario("rotary-flexible-link"),
        [6.0, -3.0, 0.213, 0.0],
        tmp_path / "si.csv",
        duration=2.0,
    )
    log = read_log(si, required=("time", "reference"))
    s = log.signals
    rig = write_log(
        tmp_path / "rig.csv",
        log.time,
        {
            "ref_deg": np.degrees(s["reference"]),
            "Vm": s["voltage"],
            "theta_deg": np.degrees(s["motor_angle"]),
            "strain_mm": 1e3 * s["tip_deflection"],
        },
        comments=log.comments,
        required=("time",),
        fmt="%.17g",
    )
    maps = [
        "--column",
        "reference=ref_deg",
        "--column",
        "voltage=Vm",
        "--column",
        "motor_angle=theta_deg",
        "--column",
        "tip_deflection=strain_mm",
        "--unit",
        "reference=deg",
        "--unit",
        "motor_angle=deg",
        "--unit",
        "tip_deflection=mm",
    ]
    fits = {}
    for name, path, extra in (("si", si, []), ("rig", rig, maps)):
        j = tmp_path / f"{name}.json"
        r = runner.invoke(
            app, ["validate", "rotary-flexible-link", str(path), "--json", str(j), *extra]
        )
        assert r.exit_code == 0, r.output
        fits[name] = json.loads(j.read_text())["fit_percent"][path.name]
    for sig in ("motor_angle", "tip_deflection"):
        assert fits["rig"][sig] == pytest.approx(fits["si"][sig], abs=1e-6)
    r = runner.invoke(app, ["validate", "rotary-flexible-link", str(rig)])
    assert r.exit_code == 2 and "rig.csv" in said(r)  # unmapped: names the file
    # a logger whose time stamps jitter by +-2 % of the period (the controller did not)
    jit = log.time + 0.02 * log.dt * np.random.default_rng(0).uniform(-1, 1, len(log.time))
    jittered = write_log(
        tmp_path / "jit.csv", jit, s, comments=log.comments, required=("time",), fmt="%.17g"
    )
    r = runner.invoke(app, ["validate", "rotary-flexible-link", str(jittered)])
    assert r.exit_code == 2 and "non-uniform sampling" in said(r) and "--max-jitter" in said(r)
    j = tmp_path / "jit.json"
    r = runner.invoke(
        app,
        [
            "validate",
            "rotary-flexible-link",
            str(jittered),
            "--max-jitter",
            "0.05",
            "--json",
            str(j),
        ],
    )
    assert r.exit_code == 0, r.output
    got = json.loads(j.read_text())["fit_percent"]["jit.csv"]
    for sig in ("motor_angle", "tip_deflection"):  # same samples, same replay
        assert got[sig] == pytest.approx(fits["si"][sig], abs=1e-6)
    rig_args = [
        "fit",
        str(rig),
        "--gear-ratio",
        "70",
        "--motor-constant",
        "7.68e-3",
        "--armature-resistance",
        "2.6",
        "--link-length",
        "0.42",
        *maps,
    ]
    r = runner.invoke(app, [*rig_args, "--tip-sign", "2"])
    assert r.exit_code == 2 and "--tip-sign 2" in said(r)
    r = runner.invoke(app, [*rig_args, "--sessions", "0,x"])
    assert r.exit_code == 2 and "--sessions" in said(r)
    r = runner.invoke(app, [*rig_args, "--sessions", "0,1"])
    assert r.exit_code == 2 and "sessions" in said(r)  # two indices for one log
    r = runner.invoke(app, [*rig_args, "--filter", "tip_deflection=fast"])
    assert r.exit_code == 2 and "--filter tip_deflection=fast" in said(r)
    r = runner.invoke(app, [*rig_args, "--delay-search", "all"])
    assert r.exit_code == 2 and "delay_search" in said(r) and "both" in said(r)
    r = runner.invoke(app, [*rig_args, "--filter", "strain=50"])
    assert r.exit_code == 2 and "strain" in said(r)  # unknown channel, named


# ---------------------------------------------------------------- output paths (issue #12)
def _no_temp_files(folder) -> bool:
    """The atomic writer's temporary files start with '.' + the target's name."""
    return not [p for p in folder.iterdir() if p.name.startswith(".")]


def test_simulate_out_an_existing_file_exits_2_and_keeps_the_file(tmp_path):
    """The issue's report: --out FILE ended in a NotADirectoryError traceback."""
    f = tmp_path / "result.txt"
    f.write_text("mine\n")
    r = runner.invoke(app, ["simulate", "feliu-single-mass", "--out", str(f)])
    assert r.exit_code == 2, r.output
    assert "--out" in said(r) and str(f) in said(r) and "is a file, not a folder" in said(r)
    assert r.exception is None or isinstance(r.exception, SystemExit)
    assert f.read_text() == "mine\n"


def test_out_folder_below_a_file_exits_2(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    r = runner.invoke(app, ["reproduce", "feliu", "--out", str(f / "sub")])
    assert r.exit_code == 2, r.output
    assert "--out" in said(r) and "is a file, so the folder cannot be created" in said(r)


def test_json_option_given_a_folder_exits_2(tmp_path):
    r = runner.invoke(
        app, ["identify", str(tmp_path / "x.csv"), "--motor-constant", "1", "--json", str(tmp_path)]
    )
    assert r.exit_code == 2, r.output
    assert "--json" in said(r) and "is a folder, not a file" in said(r)


def test_json_option_in_a_missing_folder_exits_2(tmp_path):
    j = tmp_path / "nope" / "f.json"
    r = runner.invoke(app, ["fit", str(tmp_path / "x.csv"), "--json", str(j)])
    assert r.exit_code == 2, r.output
    assert "--json" in said(r) and "does not exist" in said(r) and "mkdir -p" in said(r)
    assert not (tmp_path / "nope").exists()


def test_scenario_out_below_a_file_and_plots_a_file_exit_2(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    r = runner.invoke(app, ["fit", str(tmp_path / "x.csv"), "--scenario-out", str(f / "arm.toml")])
    assert r.exit_code == 2 and "--scenario-out" in said(r) and "is a file, not a folder" in said(r)
    r = runner.invoke(
        app, ["validate", "feliu-single-mass", str(tmp_path / "x.csv"), "--plots", str(f)]
    )
    assert r.exit_code == 2 and "--plots" in said(r) and "is a file, not a folder" in said(r)


def test_existing_json_is_refused_without_overwrite(tmp_path):
    j = tmp_path / "v.json"
    j.write_text("{}")
    r = runner.invoke(
        app, ["validate", "feliu-single-mass", str(tmp_path / "x.csv"), "--json", str(j)]
    )
    assert r.exit_code == 2 and "--json" in said(r) and "--overwrite" in said(r)
    assert j.read_text() == "{}"


def test_unwritable_output_folder_exits_2(tmp_path, monkeypatch):
    """A folder without write permission.  chmod does not stop root (CI containers), so
    ``os.access`` is made to report what a non-root user would get for that folder."""
    import os

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    real = os.access
    monkeypatch.setattr(
        os,
        "access",
        lambda p, mode, **kw: (
            False if os.path.realpath(p) == os.path.realpath(ro) else real(p, mode, **kw)
        ),
    )
    try:
        r = runner.invoke(app, ["simulate", "feliu-single-mass", "--out", str(ro / "sim")])
        assert r.exit_code == 2 and "--out" in said(r) and "permission denied" in said(r)
        r = runner.invoke(app, ["fit", str(tmp_path / "x.csv"), "--json", str(ro / "f.json")])
        assert r.exit_code == 2 and "--json" in said(r) and "permission denied" in said(r)
    finally:
        ro.chmod(0o700)


def _fake_fit():
    """The smallest fit result (the one FitResult of every rig)."""
    from flexarm.identification.time_domain.result import FitResult

    return FitResult(
        free=["J"],
        params={"J": 1.5e-3},
        template={"J": 1e-3},
        std={"J": float("nan")},
        correlation=np.full((1, 1), np.nan),
        warnings=[],
        fit_percent={},
        segment_fit_percent={},
        scenario=None,
        converged=False,
        message="global stage, generation 3",
        nfev=3,
        cost=1.0,
        seconds=0.5,
    )


def _interrupting_fit(monkeypatch, result):
    import flexarm.cli.fit
    from flexarm.errors import FitInterrupted
    from flexarm.identification.time_domain import engine

    def fake(*a, **k):
        if result is KeyboardInterrupt:
            raise KeyboardInterrupt
        raise FitInterrupted(result)

    monkeypatch.setattr(engine, "fit", fake)  # the one fit the command calls
    monkeypatch.setattr(flexarm.cli.fit, "bench_logs", lambda *a, **k: [])


def test_fit_interrupted_writes_best_result_marked_and_exits_130(tmp_path, monkeypatch):
    from flexarm.identification.time_domain.result import FitResult

    _interrupting_fit(monkeypatch, _fake_fit())
    j = tmp_path / "f.json"
    r = runner.invoke(app, ["fit", "x.csv", "--json", str(j)])
    assert r.exit_code == 130, r.output
    assert "fit interrupted" in said(r) and str(j) in said(r)
    d = json.loads(j.read_text())
    assert d["interrupted"] is True and d["status"] == "interrupted"
    assert d["params"]["J"] == 1.5e-3 and d["std"]["J"] is None
    assert FitResult.from_dict(d).to_dict() == d  # the one document, read back
    assert _no_temp_files(tmp_path)


def test_fit_interrupted_replaces_json_only_with_overwrite(tmp_path, monkeypatch):
    _interrupting_fit(monkeypatch, _fake_fit())
    j = tmp_path / "f.json"
    j.write_text("old")
    r = runner.invoke(app, ["fit", "x.csv", "--json", str(j)])
    assert r.exit_code == 2 and j.read_text() == "old"
    r = runner.invoke(app, ["fit", "x.csv", "--json", str(j), "--overwrite"])
    assert r.exit_code == 130 and json.loads(j.read_text())["interrupted"] is True


def test_plain_ctrl_c_in_fit_exits_130_writing_a_marked_stub(tmp_path, monkeypatch):
    """A KeyboardInterrupt that is not (yet) a FitInterrupted: no result, still no traceback."""
    _interrupting_fit(monkeypatch, KeyboardInterrupt)
    j = tmp_path / "f.json"
    r = runner.invoke(app, ["fit", "x.csv", "--json", str(j)])
    assert r.exit_code == 130, r.output
    d = json.loads(j.read_text())
    assert d["status"] == "interrupted" and d["params"] == {}
    assert d["message"] == "interrupted before any model was evaluated"
    r = runner.invoke(app, ["fit", "x.csv"])
    assert r.exit_code == 130 and "nothing written" in said(r)


def test_scenario_valid_as_data_but_not_as_a_model_exits_2(tmp_path):
    """Found by tests/test_scenario__properties.py: an improper G_b passed the schema and
    `info` ended in a ValueError traceback from the model layer."""
    from flexarm.specs import builtin_scenarios

    text = builtin_scenarios()["feliu-single-mass-identified"].read_text()
    bad = tmp_path / "improper.toml"
    bad.write_text(text.replace("tip_num = [43.75]", "tip_num = [1.0, 2.0, 3.0, 4.0]"))
    assert bad.read_text() != text
    r = runner.invoke(app, ["info", str(bad)])
    assert r.exit_code == 2, r.output
    assert "tip_num" in said(r) and "proper" in said(r)


@pytest.mark.slow
def test_sigint_during_fit_writes_best_result_marked_interrupted(tmp_path):
    """Ctrl-C (a real SIGINT) during `flexarm fit`: exit 130, a complete JSON marked
    interrupted with the best parameters so far, and no partial or temporary file left."""
    import os
    import signal
    import subprocess
    import sys

    from flexarm.identification.time_domain.synthetic import synthetic_log
    from flexarm.specs import load_scenario

    sc = load_scenario("rotary-flexible-link")
    logs = [
        synthetic_log(
            sc, g, tmp_path / f"{i}.csv", duration=10.0, period=3.0, amplitude=(0.5, 0.15), seed=i
        )
        for i, g in enumerate(([6.0, -40.0, 0.15, 0.0], [8.0, -60.0, 0.2, -0.5]))
    ]
    out = tmp_path / "out"
    out.mkdir()
    j = out / "fit.json"
    # the child restores Python's Ctrl-C handler itself: a suite started in the background
    # (`nohup make test &` from a script) has SIGINT ignored, an ignored signal stays ignored
    # across fork and exec, and Python then installs no handler (issue #25). Done in the
    # child's own code, not a preexec_fn (which forks a multithreaded JAX process)
    restore = (
        "import runpy, signal, sys; "
        "signal.signal(signal.SIGINT, signal.default_int_handler); "
        "sys.argv[0] = 'flexarm'; runpy.run_module('flexarm.cli', run_name='__main__')"
    )
    cmd = [
        sys.executable,
        "-c",
        restore,
        "fit",
        *map(str, logs),
        "--gear-ratio",
        "70",
        "--motor-constant",
        "7.68e-3",
        "--armature-resistance",
        "2.6",
        "--link-length",
        "0.42",
        "--json",
        str(j),
        "--delay-search",
        "both",
        "--polish-iter",
        "20",
    ]
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    # interrupted in the global stage, once it has a best point (this fit, two 10 s logs
    # with two delay starts and a long friction polish, runs on long after that)
    for line in p.stderr:  # stages are printed as lines when stderr is not a terminal
        if b"generation 2" in line:  # the global stage has a best point
            break
    else:
        raise AssertionError(p.communicate())
    assert p.poll() is None, p.communicate()
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 130, (p.returncode, stderr.decode()[-2000:])
    d = json.loads(j.read_text())
    assert d["interrupted"] is True and d["status"] == "interrupted"
    assert "arm.motor.inertia" in d["params"] and "fit_percent" in d, d.keys()
    assert d["message"].startswith("INTERRUPTED")
    assert sorted(x.name for x in out.iterdir()) == ["fit.json"]
