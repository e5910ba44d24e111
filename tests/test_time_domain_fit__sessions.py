"""Issue #47 item 1, several sessions of one rig in one fit: mechanics shared, friction and
bias per session, and the tip gauge's sign per session (the rotary rig's 5/2 session reads
its gauge with the sign opposite to 4/27's: README of ``../shared/data/rotary-rig``).

* :func:`guesses.session_signs` on synthetic logs whose tip is exactly the estimate's own
  model, d = g H(s)(−L θ̈) (so each session's gain comes back to rounding: 1e-9 relative);
* the four training runs of both sessions through ``flexarm fit --sessions 0,0,1,1`` and
  ``flexarm validate`` of each session's written scenario (slow, real data).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.signal

from flexarm.identification.time_domain import guesses
from flexarm.io.logs import Log

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
FORMAT = Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml"
SHEET = ["--drive", "voltage", "--gear-ratio", "48.4", "--motor-constant", "0.0107"]
SHEET += ["--armature-resistance", "3.29", "--link-length", "0.45"]
CLI = [sys.executable, "-m", "flexarm"]


def _log(gain: float, seed: int, wc: float = 11.3, length: float = 0.45) -> Log:
    dt, n = 1e-3, 4000
    t = np.arange(n) * dt
    rng = np.random.default_rng(seed)
    th = np.cumsum(np.cumsum(rng.normal(size=n))) * 1e-6  # a smooth random hub motion
    acc = np.gradient(np.gradient(th, dt), dt)
    sysd = scipy.signal.cont2discrete(([1.0], [1.0, 2 * 0.03 * wc, wc**2]), dt, "bilinear")
    d = gain * scipy.signal.lfilter(np.ravel(sysd[0]), sysd[1], -length * acc)
    return Log(path=None, time=t, signals={"motor_angle": th, "tip_deflection": d})


def test_session_signs_finds_a_gauge_read_the_other_way():
    logs = [_log(-0.7, 0), _log(-0.7, 1), _log(0.7, 2), _log(0.7, 3), _log(-0.7, 4)]
    signs, est = guesses.session_signs(logs, [0, 0, 1, 1, 2], 11.3, 0.45)
    assert signs == [1, -1, 1]
    for e, g in zip(est, (-0.7, 0.7, -0.7), strict=True):
        assert e["gain"] == pytest.approx(g, rel=1e-9)
        assert e["r2"] == pytest.approx(1.0, abs=1e-9)


def test_a_session_without_tip_information_keeps_its_sign():
    quiet = _log(0.7, 2)
    quiet.signals["tip_deflection"] = np.zeros_like(quiet.signals["tip_deflection"])
    signs, est = guesses.session_signs([_log(-0.7, 0), quiet], [0, 1], 11.3, 0.45)
    assert signs == [1, 1] and est[1]["gain"] is None


def _run(args: list[str]) -> None:
    r = subprocess.run([*CLI, *args], capture_output=True, text=True)
    assert r.returncode == 0 and "Traceback" not in r.stderr, (r.stdout[-2000:], r.stderr[-3000:])


@pytest.mark.slow
@pytest.mark.rig
@pytest.mark.skipif(not DATA.is_dir(), reason=f"real rig logs not found at {DATA}")
def test_two_sessions_fitted_together(tmp_path):
    """The 4/27 and 5/2 training runs, ``--sessions 0,0,1,1`` (the data sheet, default
    options: three global starts, as nothing ties the delays of these sessions down).
    Measured on 2 cores: 4/27 85.2 / 54.2 and 87.4 / 65.0, 5/2 90.3 / 64.6 and 90.3 / 69.5
    (hub / tip %; means 88.3 / 63.3); one start gave 83.0 / 55.5, 85.3 / 65.0, 90.5 / 62.2,
    90.6 / 64.7; before the per-session gauge sign, 54.6 / 3.6, 63.2 / 1.2, 89.5 / 61.6,
    88.7 / 63.0 (the joint hub -> tip estimate explained 5 % of the tips). Floors: the
    issue's, mean hub 85 and mean tip 62, no run under 80 / 50 (a start's outcome moves the
    runs by 1-5 points; the means by about 1.5). Each session's written scenario, validated
    on its own runs, gives the fit's figures to 0.1 point."""
    a = [DATA / "flexarm_K1_6", DATA / "flexarm_K1K2_6_-5"]
    b = [DATA / "flexarm_K1K2K3_6_-3_213", DATA / "flexarm_K1K2K3k4_6_-3_213_4"]
    toml, fit_json = tmp_path / "rig.toml", tmp_path / "fit.json"
    _run(
        ["fit", *map(str, a + b), "--sessions", "0,0,1,1", "--log-format", str(FORMAT), *SHEET]
        + ["--scenario-out", str(toml), "--json", str(fit_json)]
    )
    fit = json.loads(fit_json.read_text())
    fp = fit["fit_percent"]
    hubs = [fp[g.name]["motor_angle"] for g in a + b]
    tips = [fp[g.name]["tip_deflection"] for g in a + b]
    assert min(hubs) >= 80 and min(tips) >= 50, fp
    assert sum(hubs) / 4 >= 85 and sum(tips) / 4 >= 62, fp
    g0 = fit["params"]["sensors.tip_deflection.gain"]
    g1 = fit["params"]["sessions[1].sensors.tip_deflection.gain"]
    assert g1 == pytest.approx(-g0, rel=1e-12)  # one size, the sign per session
    assert any("sign differs between sessions" in w for w in fit["warnings"])
    ses = fit["stages"]["sessions"]
    assert ses["of_log"] == [0, 0, 1, 1] and ses["tip_gauge_signs"] == [1, -1]
    assert "arm.friction.coulomb" in ses["per_session"] and "arm.motor.inertia" in ses["shared"]
    assert "sensors.tip_deflection.gain" in ses["per_session"]
    _each_session_validates_to(tmp_path, ((toml, a), (tmp_path / "rig.session1.toml", b)), fp)
    # the general engine on these rig logs, from the written scenarios (a scenario first:
    # each log with the law it declares, as validate runs it; the sessions with their own
    # friction, bias and gauge gain, session 1 started at its written values). Before,
    # the scenario's own [controller] (K2 = 0) ran the K1 K2 run: a fit of the 4/27 runs
    # reported 74.1 / 59.6 on it where validate of the scenario it wrote gave 76.5 / 58.0.
    # Measured (30 evaluations, 12 s): 91.4 / 58.1, 81.5 / 61.8, 90.6 / 63.1, 89.9 / 64.8;
    # each session's written scenario validates to the fit's figures (0.1 point)
    from flexarm.specs import load_scenario
    from flexarm.specs.paths import get as path_get

    free = ["arm.motor.inertia", "arm.friction.coulomb", "arm.friction.static"]
    free += ["arm.motor.viscous", "arm.friction.bias", "sensors.tip_deflection.gain"]
    free += ["arm.beam.flexural_rigidity", "arm.beam.damping_ratio", "arm.beam.masses[0].mass"]
    s1 = load_scenario(tmp_path / "rig.session1.toml").model_dump()
    starts = [f"1:{p}={float(path_get(s1, p))!r}" for p in free[1:6]]
    g_toml, g_json = tmp_path / "g.toml", tmp_path / "g.json"
    args = ["fit", str(toml), *map(str, a + b), "--log-format", str(FORMAT)]
    args += [x for p in free for x in ("--free", p)] + ["--sessions", "0,0,1,1"]
    args += [x for st in starts for x in ("--session-start", st)] + ["--max-nfev", "10"]
    _run(args + ["--scenario-out", str(g_toml), "--json", str(g_json)])
    g_fit = json.loads(g_json.read_text())
    assert "declared_laws" in g_fit["stages"]
    assert g_fit["stages"]["sessions"]["per_session"] == free[1:6]
    assert g_fit["params"]["sessions[1].sensors.tip_deflection.gain"] * g0 < 0  # its own sign
    _each_session_validates_to(
        tmp_path, ((g_toml, a), (tmp_path / "g.session1.toml", b)), g_fit["fit_percent"]
    )


def _each_session_validates_to(tmp_path, pairs, fp: dict) -> None:
    """``flexarm validate`` of each (session scenario, its logs) in ``pairs`` gives the fit's
    figures ``fp`` (log -> signal -> fit %) to 0.1 point."""
    for sc, logs in pairs:
        out = tmp_path / f"{sc.stem}.v.json"
        _run(
            ["validate", str(sc), *map(str, logs), "--log-format", str(FORMAT), "--json", str(out)]
        )
        val = json.loads(out.read_text())["fit_percent"]
        for g in logs:
            for sig, v in fp[g.name].items():
                assert val[g.name][sig] == pytest.approx(v, abs=0.1), (g.name, sig, val, fp)


def _result(params: dict, template: dict, fit_percent: dict):
    from flexarm.identification.time_domain.result import FitResult

    return FitResult(
        free=list(params),
        params=params,
        template=template,
        std={k: 0.0 for k in params},
        correlation=np.eye(len(params)),
        warnings=[],
        fit_percent=fit_percent,
        segment_fit_percent={},
        scenario=None,
        converged=True,
        message="",
        nfev=0,
        cost=0.0,
        seconds=0.0,
        rmse={"run": {"tip_deflection": 0.0027}},
    )


def test_fit_quality_does_not_call_a_friction_level_that_vanishes_the_wrong_model():
    """The one poor-fit rule (:func:`flexarm.identification.fit_quality.fit_quality`, which
    the one fit runs on every preset's result): a signal under 50 % is "not described", a
    parameter 10 times from its start is named; a viscous level that falls to 4e-6 of its
    start (the 4/27 + 5/2 fit: the back-EMF damping carries it) is not."""
    from flexarm.identification.fit_quality import fit_quality

    res = _result(
        {"arm.motor.inertia": 0.9, "arm.motor.viscous": 8e-8, "arm.beam.masses[0].mass": 0.0002},
        {"arm.motor.inertia": 0.002, "arm.motor.viscous": 0.0197, "arm.beam.masses[0].mass": 0.05},
        {"run": {"motor_angle": 83.0, "tip_deflection": 41.0}},
    )
    w = fit_quality(res)
    assert len(w) == 3, w
    assert w[0].startswith("run: fit 41.000 % on tip_deflection (below 50 %: the model does not")
    assert "RMSE 0.0027 m" in w[0]
    assert w[1].startswith("arm.motor.inertia ended at 0.9, 450 times its start")
    assert w[2].startswith("arm.beam.masses[0].mass ended at 0.0002, 0.004 times its start")


def test_a_session_whose_gauge_estimate_explains_little_keeps_its_sign():
    """Under :data:`guesses.SIGN_R2` (0.1) a session's estimate does not flip its sign: an
    opposite gain buried in noise (R² about 0.03 here) is not taken as a re-wired gauge."""
    weak = _log(0.7, 2)
    d = weak.signals["tip_deflection"]
    noise = np.random.default_rng(9).normal(size=d.size)
    weak.signals["tip_deflection"] = d + 5.5 * np.std(d) * noise
    signs, est = guesses.session_signs([_log(-0.7, 0), weak], [0, 1], 11.3, 0.45)
    assert est[1]["gain"] > 0 and 0.005 < est[1]["r2"] < guesses.SIGN_R2, est
    assert signs == [1, 1]


@pytest.mark.slow
@pytest.mark.rig
@pytest.mark.skipif(not DATA.is_dir(), reason=f"real rig logs not found at {DATA}")
def test_two_sessions_through_the_general_route(tmp_path):
    """``--local general --sessions 0,0,1,1`` (#43 with #47): the servo's estimates and
    global stage, then the general engine with the sessions' friction, bias and (read the
    other way on 5/2) gauge gain per session, each started at the global stage's own. Each
    session's written scenario validates to the fit's figures (0.1 point: one computation),
    and session 1's gauge gain keeps its opposite sign. Measured on 2 cores (82 s):
    82.1 / 50.5, 79.1 / 57.8, 92.0 / 61.0, 92.5 / 62.6 (the servo route: means 88.3 / 63.3;
    the issue's mean floors 85 / 62 are not met this way, said in the closing note)."""
    a = [DATA / "flexarm_K1_6", DATA / "flexarm_K1K2_6_-5"]
    b = [DATA / "flexarm_K1K2K3_6_-3_213", DATA / "flexarm_K1K2K3k4_6_-3_213_4"]
    toml, fit_json = tmp_path / "rig.toml", tmp_path / "fit.json"
    _run(
        ["fit", *map(str, a + b), "--sessions", "0,0,1,1", "--log-format", str(FORMAT), *SHEET]
        + ["--local", "general", "--scenario-out", str(toml), "--json", str(fit_json)]
    )
    fit = json.loads(fit_json.read_text())
    print("general route, sessions:", fit["fit_percent"])
    g0 = fit["params"]["sensors.tip_deflection.gain"]
    g1 = fit["params"]["sessions[1].sensors.tip_deflection.gain"]
    assert g0 * g1 < 0, (g0, g1)
    assert "sensors.tip_deflection.gain" in fit["stages"]["sessions"]["per_session"]
    _each_session_validates_to(
        tmp_path, ((toml, a), (tmp_path / "rig.session1.toml", b)), fit["fit_percent"]
    )
