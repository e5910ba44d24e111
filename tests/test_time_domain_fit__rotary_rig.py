"""Issue #11 acceptance on the real rotary-rig logs (``../shared/data/rotary-rig``): the
lab's files as they are, read with ``examples/quanser-rotflex.toml``, fitted with the data
sheet's values and default options only, and judged on held-out data.

Thresholds: the issue's (an independent gray-box fit of the same logs, closed loop with
stiction and sensor delays, reached held-out hub 97.6 % / tip 83.9 % on unit 6 and 77.3 % /
56.9 % on unit 7; the issue asks at least 95 / 80 and 75 / 55). One fit per data set
(module fixtures); marked slow (about 30 s per fit on 2 cores).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flexarm.identification.time_domain import load_rig_log, predict
from flexarm.identification.time_domain.fit import fit

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rotary-rig"
FORMAT = Path(__file__).resolve().parents[1] / "examples" / "quanser-rotflex.toml"
#: the lab's data sheet (README of the data): geared voltage-driven servo, 0.45 m link
SHEET = dict(
    drive="voltage",
    gear_ratio=48.4,
    motor_constant=0.0107,
    armature_resistance=3.29,
    link_length=0.45,
    computation_delay=1,
    voltage_limit=10.0,
)  # the limit the tests' figures were measured at

pytestmark = [
    pytest.mark.slow,
    pytest.mark.rig,
    pytest.mark.skipif(
        not DATA.is_dir(),
        reason=f"real rig logs not found at {DATA} (../shared is absent in a "
        "user's clone; CI has it)",
    ),
]


def _log(name: str):
    return load_rig_log(DATA / name, log_format=FORMAT)


def _split(name: str):
    g = _log(name)
    return g.window(0.0, 5.0), g.window(5.0, 10.0)


@pytest.fixture(scope="module")
def unit6():
    ident, held = _split("4PM_Group37_FlexArm_Unit6")
    res = fit([ident], **SHEET)
    return res, predict(res, [held])


@pytest.fixture(scope="module")
def unit7():
    ident, held = _split("Unit7_Flex_trial1.csv")
    res = fit([ident], **SHEET)
    return res, predict(res, [held])


def _report(res, held):
    print(res.summary())
    print("held-out fit %:", held["fit_percent"])
    est = res.stages["guesses"]["estimates"]
    print(
        "estimates:",
        {k: v for k, v in est["tip_model"].items() if k != "profile"},
        {k: v for k, v in est["hub_delay"].items() if k != "profile"},
    )


def test_unit6_held_out(unit6):
    res, held = unit6
    _report(res, held)
    fp = next(iter(held["fit_percent"].values()))
    assert fp["motor_angle"] >= 95.0 and fp["tip_deflection"] >= 80.0, fp
    # the link rings near its nominal 1.8 Hz clamped frequency (data sheet): the fitted
    # clamped frequency lies within the data-derived bounds, not at their edge (#11)
    wc = res.params["link_frequency"]
    assert 2 * np.pi * 1.2 < wc < 2 * np.pi * 2.5, wc
    assert not any("lies at a bound" in w for w in res.warnings), res.warnings
    # its hub -> tip model is trusted (82 %): the delays are tied down, no seed warning
    assert not any("depends on its seed" in w for w in res.warnings), res.warnings
    # real rigs lag by tens of milliseconds at the hub and more at the tip
    assert 5 <= res.delays["motor_angle"] <= 60
    assert res.delays["tip_deflection"] > res.delays["motor_angle"] + 10


def test_unit7_held_out(unit7):
    res, held = unit7
    _report(res, held)
    fp = next(iter(held["fit_percent"].values()))
    # this fit's own split and prediction (82.8 / 61.8 measured; the documented command's
    # figures and the floors: tests/test_time_domain_predict__written_scenario.py)
    assert fp["motor_angle"] >= 75.0 and fp["tip_deflection"] >= 55.0, fp
    # unit 7's gauge reads with the opposite sign to unit 6's (the data say so)
    assert res.params["tip_gain"] > 0
    # the tip sensor reads after the hub's (tip_after_hub over overlapping ranges)
    assert res.delays["tip_deflection"] >= res.delays["motor_angle"], res.delays


#: the rigid session of 4/25: fitted on K1 = 6, 8 and K1K3 = 6, 8, validated on the others
RIGID_FIT = ["rigidarm_K1_6", "rigidarm_K1_8", "rigidarm_k1k3_6", "rigidarm_k1k3_8"]
RIGID_HELD = ["rigidarm_K1_7", "rigidarm_K1_9", "rigidarm_k1k3_7", "rigidarm_k1k3_9"]


@pytest.fixture(scope="module")
def rigid():
    """The rigid session's fit through the front door, ``flexarm.fit`` of the servo-rig
    preset (the same keywords as ``fit(logs, **SHEET)``): the one FitResult."""
    import flexarm
    from flexarm.identification.time_domain.options import FitOptions, ServoRig
    from flexarm.identification.time_domain.presets import DataSheet, servo_rig

    sheet = DataSheet(**{k: v for k, v in SHEET.items() if k != "computation_delay"})
    # default options: on a rigid arm the global stage fits whole logs ("auto"; on the
    # first 5 s, two of the four moves, it ends in a basin at 2.5 x the data sheet's inertia)
    opts = FitOptions(servo_rig=ServoRig(computation_delay=SHEET["computation_delay"]))
    return flexarm.fit(servo_rig(sheet), [_log(n) for n in RIGID_FIT], options=opts)


def test_rigid_session(rigid):
    """The eight rigid-arm runs of 4/25 are one session: fit on K1 = 6, 8 and K1K3 = 6, 8;
    validate on the other four. A rigid arm fits the hub inertia and friction only.
    Thresholds: issue #23's 70 % on each held-out run, and 80 % on the training runs (a
    model without friction misses the stuck hub's stops, tens of mrad of a 0.2 rad swing,
    on every run). Default options: on a rigid arm the global stage fits whole logs (the
    runs step every 2.5 s; on the first 5 s, a flexible link's default: held out
    72.7 / 65.6 / 84.4 / 73.5 %); seeds 0-3: held out 81.5-87.2 %, training 84.0-91.7 %."""
    res = rigid
    held = predict(res, [_log(n) for n in RIGID_HELD])  # the rig's own loop (engine_result)
    print(res.engine_result.summary())
    print("held-out fit %:", held["fit_percent"])
    assert "arm.beam.flexural_rigidity" not in res.params  # no tip channel: a rigid hub
    assert res.params["arm.friction.coulomb"] > 0
    for name, fp in res.fit_percent.items():
        assert fp["motor_angle"] >= 80.0, (name, fp)
        assert fp["tip_deflection"] is None
    for name, fp in held["fit_percent"].items():
        assert fp["motor_angle"] >= 70.0, (name, fp)
        assert fp["tip_deflection"] is None


def test_rigid_session_cli_fit_json_is_the_python_result_and_validates(rigid, tmp_path):
    """Issue #23 item 4, one result, one document: ``flexarm fit`` on the rigid session
    with ``--json`` and ``--scenario-out``, then ``flexarm validate`` of the written scenario
    on the session's other four runs: no traceback; the JSON is ``FitResult.to_dict()``
    (it reads back through ``FitResult.from_dict`` unchanged) and holds what the Python
    call ``flexarm.fit`` gives with the same options (the fit is seeded: same parameters,
    fit %, keys; only the seconds differ)."""
    import json
    import subprocess
    import sys

    from flexarm.identification.time_domain.result import FitResult
    from flexarm.specs import load_scenario

    j, toml, v = tmp_path / "fit.json", tmp_path / "arm.toml", tmp_path / "validate.json"
    # the module's data sheet as options: --drive voltage --gear-ratio 48.4 ...
    sheet = [a for k, v in SHEET.items() for a in (f"--{k.replace('_', '-')}", str(v))]
    fmt = ["--log-format", str(FORMAT)]
    cli = [sys.executable, "-m", "flexarm"]
    logs = [str(DATA / n) for n in RIGID_FIT]
    r = subprocess.run(
        [*cli, "fit", *logs, *fmt, *sheet] + ["--json", str(j), "--scenario-out", str(toml)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    d = json.loads(j.read_text())
    assert FitResult.from_dict(json.loads(json.dumps(d))).to_dict() == d
    py = json.loads(json.dumps(rigid.to_dict()))
    assert set(d) == set(py) and set(d["stages"]) == set(py["stages"])
    assert (
        set(d["stages"]["servo_rig"])
        == set(py["stages"]["servo_rig"])
        >= {
            "derived",
            "delays_samples",
            "initial_states",
            "settings",
            "std_iid",
            "units",
            "docs",
            "uncertainty_note",
        }
    )
    assert d["free"] == py["free"] == list(d["params"]) and set(d["std"]) == set(py["std"])
    for k, x in py["params"].items():
        # the same seeded fit in two processes, whose rounding can differ: each parameter
        # agrees to the local stage's own resolution, ten times its step tolerance
        # (xtol = 1e-6, relative in log-parameter space), 1e-5 of its value, or a
        # millionth of its std where that is wider. A parameter the data do not determine
        # (the breakaway excess near its bound, 9.3e-6 N*m, std 9.3e-9) differed by 3e-7
        # and by 1.3e-6 of itself between the two processes in two clean-clone runs
        sd = py["std"].get(k)
        ok = sd is not None and np.isfinite(sd) and sd > 0
        tol = max(1e-5 * abs(x), 1e-6 * sd if ok else 0.0)
        assert d["params"][k] == pytest.approx(x, rel=1e-9, abs=tol), k
    assert set(d["fit_percent"]) == set(py["fit_percent"]) == set(RIGID_FIT)
    for log, fp in py["fit_percent"].items():
        assert set(d["fit_percent"][log]) == set(fp)
        for sig, x in fp.items():
            assert (d["fit_percent"][log][sig] is None) == (x is None), (log, sig)
            if x is not None:
                assert d["fit_percent"][log][sig] == pytest.approx(x, abs=1e-6), (log, sig)
    for key in ("converged", "message", "warnings", "free_source", "nfev", "template"):
        assert d[key] == py[key], key
    assert d["stages"]["servo_rig"]["delays_samples"] == py["stages"]["servo_rig"]["delays_samples"]
    # the scenario written is the rig's commented TOML, and the Python result's
    assert toml.read_text().startswith("# Fitted by flexarm.identification.time_domain from")
    sc = load_scenario(toml)
    assert sc.arm.motor.inertia == pytest.approx(rigid.params["arm.motor.inertia"], rel=1e-9)
    r = subprocess.run(
        [
            *cli,
            "validate",
            str(toml),
            *(str(DATA / n) for n in RIGID_HELD),
            *fmt,
            "--json",
            str(v),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    out = json.loads(v.read_text())
    print("validate fit %:", out["fit_percent"])
    assert set(out["fit_percent"]) == set(RIGID_HELD)
    for name, fp in out["fit_percent"].items():
        # issue #23's 70 % each (the one simulator; measured 83.9-87.3 %)
        assert fp["motor_angle"] is not None and fp["motor_angle"] >= 70.0, (name, fp)
    # issue #43 item 2: validate of the written scenario on the fitted runs gives what the
    # fit reported, to 0.1 point (one computation: the one prediction of that scenario)
    v2 = tmp_path / "validate-fitted.json"
    r = subprocess.run(
        [*cli, "validate", str(toml), *logs, *fmt, "--json", str(v2)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-3000:]
    again = json.loads(v2.read_text())["fit_percent"]
    for log, fp in d["fit_percent"].items():
        assert again[log]["motor_angle"] == pytest.approx(fp["motor_angle"], abs=0.1), (log, again)
        assert again[log]["tip_deflection"] is None and fp["tip_deflection"] is None


#: the 4/27 session's two runs (README of the data: a hard session), fitted together
ROTARY_HARD = ("flexarm_K1_6", "flexarm_K1K2_6_-5")


@pytest.fixture(scope="module")
def hard_session():
    """The servo-rig fit of the 4/27 session's two runs together, whole logs, default
    options, the data sheet only (one fit for the module)."""
    return fit([_log(n) for n in ROTARY_HARD], **SHEET)


def _stuck_ring_hz(name: str) -> list[tuple[float, float]]:
    """(mean command V, ringing frequency Hz) of each stuck phase (the hub within 3 mrad,
    three counts, of its first reading for more than 0.8 s): the tip's mean period between
    upward zero crossings (25-sample moving average); from the log alone, independent of
    the fit and of its stuck-phase detection."""
    g = _log(name)
    th, d, v = (g.columns[k] for k in ("motor_angle", "tip_deflection", "voltage"))
    out, i, n = [], 0, len(th)
    while i < n:
        j = i
        while j + 1 < n and abs(th[j + 1] - th[i]) <= 0.003:
            j += 1
        if (j - i) * g.dt > 0.8:
            x = np.convolve(d[i:j] - d[i:j].mean(), np.ones(25) / 25, mode="valid")
            up = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
            if up.size >= 3:
                out.append((float(v[i:j].mean()), (up.size - 1) / ((up[-1] - up[0]) * g.dt)))
        i = j + 1
    return out


def test_hard_session_stuck_phases():
    """What makes 4/27 hard, from the logs alone: the hub sticks for seconds (stuck phases
    found within three encoder counts, the hub dithering), the link rings in them at its
    clamped frequency, about 1.8 Hz (data sheet: nominal 1.8 Hz), and faster (> 1.9 Hz)
    where the controller pushes the stuck gear train with > 0.3 V (the K1K2 run's stops
    60 mrad short of the reference)."""
    light, push = [], []
    for name in ROTARY_HARD:
        for v, f in _stuck_ring_hz(name):
            (push if abs(v) > 0.3 else light).append(f)
    print("stuck-phase ringing, light push:", light, "pushed > 0.3 V:", push)
    assert len(light) >= 3 and len(push) >= 2
    assert all(1.7 < f < 1.85 for f in light), light
    assert all(f > 1.9 for f in push), push


def test_hard_session_training_fit(hard_session):
    """Issue #23 item 3: the 4/27 session (heavy gear friction, a bias torque) fitted on its
    two runs together, whole logs, default options, the data sheet only. Measured on a
    2-core EPYC: hub 85.2 / 84.4 %, tip 56.7 / 66.3 %, delays 25 / 47 samples. Thresholds:
    the issue's hub 80 % (an independent gray-box fit reached 83-84 %) and tip 55 % (61 %).
    Nothing ties the delays down here (the hub -> tip model 29 %, the hub regression's R²
    0.02), so the tip delay is searched at or above the hub's (``tip_after_hub``, the
    default). Before, the delays came out in either order and the default seed ended at
    89 / 65 samples, hub 83.1 / **78.8** %, tip 64.5 / 67.7 % (the late hub standing for
    the stuck gear train's late start); over seeds 0-2 at 5 and 10 V four of six met the
    floors, with the order five of six (lowest: tip 54.2 %, 10 V seed 2;
    docs/tasks/fit-rotary-rig.md). With one clamp stiffness (before the pushed-clamp
    stiffening) 85.5 / 88.3 %, 58.2 / 48.5 %; before the stuck-phase detection tolerated
    the encoder's one-count dither, tip 2-3 % at a link frequency of 2.5 rad/s and a tip
    delay of 134 samples. The fitted clamped frequency lies where the stuck phases ring
    (1.7-2.0 Hz, measured above). The fit says its outcome depends on the global stage's
    seed (``global_starts``)."""
    res = hard_session
    assert any("depends on its seed" in w and "global_starts=3" in w for w in res.warnings)
    print(res.summary())
    fp = res.fit_percent
    assert fp["flexarm_K1_6"]["motor_angle"] >= 80.0, fp
    assert fp["flexarm_K1K2_6_-5"]["motor_angle"] >= 80.0, fp
    assert fp["flexarm_K1_6"]["tip_deflection"] >= 55.0, fp
    wc = res.params["link_frequency"]
    assert 2 * np.pi * 1.7 < wc < 2 * np.pi * 2.0, wc
    assert res.params["bias"] < 0  # the up-moves stop short, the down-moves overshoot
    assert res.params["coulomb"] > 0.02  # several times units 6 and 7's
    # the tip channel lags the hub's on such rigs: searched so (tip_after_hub)
    d = res.delays
    assert d["tip_deflection"] >= d["motor_angle"], d
    assert res.settings["tip_after_hub"] is True
    # a poor signal is called poor
    for name in ROTARY_HARD:
        if fp[name]["tip_deflection"] < 70:
            assert any(
                w.startswith(f"{name}: fit") and "tip_deflection is low" in w for w in res.warnings
            ), res.warnings


def test_hard_session_tip_k1k2(hard_session):
    """Issue #23 item 3 on the K1K2 run (tip feedback): its tip rings at 1.89-1.92 Hz in
    its pushed stuck phases and 1.78-1.81 Hz in the light ones. With one clamp stiffness
    the fit's tip stopped at 48.5 %; with the pushed-clamp stiffening estimated from those
    phases (up to x1.13 from 0.10 to 0.32 V, not fitted) it reaches 66.3 % (floor: the
    issue's 55 %). The fitted scenario carries the stiffening, so the one prediction
    through the simulator (``validate``, each log's start state read from the log, not
    refined) keeps the K1K2 tip (measured 66.1 %) and stays within 3 points of the fit's
    own figures on every signal (measured: 0.5-1.8; the fit refines each log's start
    state, validate reads it). Before validate read the hub's start at the hub channel's
    delay, as the fit does, it read it at sample 0: one encoder count off on the K1 run,
    whose model hub then stayed stuck for the first 0.5 s where the fit's slid, and its
    tip fell to 46.2 % against the fit's 56.7 %. A step at the middle of the gap instead
    of the stiffening's ramp had sent the K1 run's tip there to 10.7 %."""
    from flexarm.identification.time_domain.report import scenario_from_fit
    from flexarm.identification.time_domain.validate import validate
    from flexarm.specs import scenario_from_dict

    fp = hard_session.fit_percent
    assert fp["flexarm_K1K2_6_-5"]["tip_deflection"] >= 55.0, fp
    d, _ = scenario_from_fit(hard_session)
    assert d["arm"]["friction"]["pushed_stiffening"] > 0.1
    v = validate(scenario_from_dict(d), [_log(n) for n in ROTARY_HARD])["fit_percent"]
    print("validate through the fitted scenario:", v)
    assert v["flexarm_K1K2_6_-5"]["tip_deflection"] >= 55.0, v
    for name in ROTARY_HARD:
        for sig in ("motor_angle", "tip_deflection"):
            assert abs(v[name][sig] - fp[name][sig]) <= 3.0, (v, fp)
    push = hard_session.stages["guesses"]["estimates"]["pushed_ringing"]
    assert push is not None, push
    assert 0.08 < push["threshold_command"] < 0.15 and 0.3 < push["full_command"] < 0.33, push
    assert any("times stiffer while the" in w for w in hard_session.warnings)


def test_pushed_ringing_estimate_from_the_stuck_phases():
    """The stiffening s = (f_pushed / f_light)² − 1 from the 4/27 stuck phases, against the
    frequencies measured independently above (:func:`_stuck_ring_hz`: 3 mrad from the
    first reading, mean-removed): their pushed / light ratio of median frequencies is 1.090;
    the estimate's own cut (within three counts, detrended) gives 1.063. A phase cut that
    starts or ends a few tenths of a second elsewhere moves a 4-8 period zero-crossing
    mean by up to 2 %, so the ratios agree within 3 %. Units 6 and 7 and the rigid
    session: none (no phases of 0.8 s with a ringing link)."""
    from flexarm.identification.time_domain import guesses

    ku = 48.4 * 0.0107 / 3.29
    push = guesses.pushed_ringing([_log(n) for n in ROTARY_HARD], ku)
    light, pushed = [], []
    for name in ROTARY_HARD:
        for v, f in _stuck_ring_hz(name):
            (pushed if abs(v) > 0.3 else light).append(f)
    s_ref = (np.median(pushed) / np.median(light)) ** 2 - 1
    print(push, s_ref)
    assert push is not None
    assert abs(np.sqrt(1 + push["stiffening"]) - np.sqrt(1 + s_ref)) < 0.03, (push, s_ref)
    # the light phases' largest push and the pushed phases' smallest (|u| 0.10 and 0.32 V)
    assert push["threshold"] == pytest.approx(
        max(abs(v) for v, f in _stuck_ring_hz(ROTARY_HARD[0])) * ku, rel=0.05
    )
    assert push["full"] == pytest.approx(
        min(abs(v) for v, _ in _stuck_ring_hz(ROTARY_HARD[1]) if abs(v) > 0.3) * ku, rel=0.05
    )
    for names in (("4PM_Group37_FlexArm_Unit6",), ("Unit7_Flex_trial1.csv",), RIGID_FIT[:2]):
        assert guesses.pushed_ringing([_log(n) for n in names], ku) is None, names
