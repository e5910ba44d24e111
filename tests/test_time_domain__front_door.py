"""The one fit's front door (flexarm.fit with presets), the one result (FitResult.to_dict /
from_dict, the fitted scenario), the one prediction (flexarm.validate → Prediction) and the
unique log keys, on a short synthetic log of the one-link two-mode arm of
test_time_domain_general (a current drive with Coulomb friction, a sampled PD)."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import flexarm
from flexarm.identification.time_domain import presets
from flexarm.identification.time_domain.options import (
    FLAT_FIELDS,
    Cost,
    FitOptions,
    GlobalDE,
    Local,
    PredictOptions,
    Priors,
    ScenarioFitOptions,
    Shooting,
)
from flexarm.identification.time_domain.result import FitResult
from flexarm.identification.time_domain.synthetic import scenario_log
from flexarm.io.logs import Log, log_keys, write_log
from flexarm.specs.paths import scenario_with
from test_time_domain_general import staircase, two_mode_link

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """3 s of the two-mode link on a staircase, written twice under one file name in two
    folders (the keys must keep them apart); the template's Coulomb level 30 % high."""
    truth = two_mode_link()
    truth = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 3.0})}
    )
    t = np.arange(1501) * 0.002
    log = scenario_log(truth, {"reference": staircase(t, [0.0, 0.4, -0.1, 0.3], 0.75)}, seed=2)
    d = tmp_path_factory.mktemp("runs")
    for f in ("a", "b"):
        (d / f).mkdir()
    paths = [
        write_log(d / f / "run.csv", log.time, log.signals, required=("time",)) for f in ("a", "b")
    ]
    template = scenario_with(truth, {"arm.joints[0].friction.coulomb": 0.026})
    return truth, template, paths


def test_log_keys_keep_same_names_in_other_folders_apart(tmp_path):
    a = Log(tmp_path / "u6" / "run.csv", np.arange(3.0), {})
    b = Log(tmp_path / "u7" / "run.csv", np.arange(3.0), {})
    c = Log(tmp_path / "u7" / "other.csv", np.arange(3.0), {})
    assert log_keys([a, b, c]) == ["u6/run.csv", "u7/run.csv", "u7/other.csv"]
    assert log_keys([b, c]) == ["run.csv", "other.csv"]  # one folder: the file names
    assert log_keys([a, a]) == ["run.csv", "run.csv#2"]  # the same file twice: numbered


def test_a_scenario_without_free_runs_its_preset_and_says_which():
    two = presets.for_scenario(flexarm.load_scenario("quanser-two-link"))
    assert two.free == presets.two_link().free and len(two.free) == 9  # 15 after [*]
    assert two.options.priors.priors["arm.hubs[1].inertia"] == 0.3
    feliu = presets.for_scenario(flexarm.load_scenario("feliu-single-mass"))
    assert feliu.free == ["arm.friction.coulomb", "arm.friction.static", "arm.motor.viscous"]
    with pytest.raises(ValueError, match="deluca-two-link.*no \\[sampling\\]"):
        presets.for_scenario(flexarm.load_scenario("deluca-two-link"))


@pytest.mark.slow
def test_fit_result_document_round_trip_and_default_free(short_run, tmp_path):
    """flexarm.fit(template, logs) with no free list: the preset (here the joint friction)
    runs and the result says so; the Coulomb level comes back within 5 % of the truth
    (the synthetic acceptance's tolerance; noise 1e-4 rad, 3 s); to_dict is JSON, from_dict
    reads it back to the same document; the scenario writes and loads."""
    truth, template, paths = short_run
    res = flexarm.fit(template, paths, options=FitOptions(local=Local(max_nfev=20)))
    assert isinstance(res, FitResult)
    assert res.free_source == "preset two-mode-link"
    assert res.free == ["arm.joints[0].friction.coulomb", "arm.joints[0].viscous"]
    assert res.params["arm.joints[0].friction.coulomb"] == pytest.approx(0.02, rel=0.05)
    assert set(res.fit_percent) == {"a/run.csv", "b/run.csv"}
    doc = json.loads(json.dumps(res.to_dict()))
    assert FitResult.from_dict(doc).to_dict() == doc
    out = res.write_scenario(tmp_path / "fitted.toml")
    again = flexarm.load_scenario(out)
    assert again.arm.joints[0].friction.coulomb == pytest.approx(
        res.params["arm.joints[0].friction.coulomb"], rel=1e-12
    )
    # the one prediction of the fitted model: fit % per log key and signal, the truth's
    # own prediction as the reference (noise only)
    pred = flexarm.validate(res, paths, PredictOptions(windows=[(0.0, 2.0), None]))
    ref = flexarm.validate(truth, paths, PredictOptions(windows=[(0.0, 2.0), None]))
    assert set(pred.fit_percent) == {"a/run.csv", "b/run.csv"}
    for k in pred.fit_percent:
        assert pred.fit_percent[k]["theta_1"] == pytest.approx(
            ref.fit_percent[k]["theta_1"], abs=1.0
        )
    assert len(pred.traces["a/run.csv"]["time"]) == 1000  # [0, 2) s at 2 ms
    fig = flexarm.identification.time_domain.overlay_figure(pred, "a/run.csv")
    assert len(fig.axes) == len(pred.traces["a/run.csv"]["simulated"])
    # how they read (issue #26): <= 80 columns, the numbers whole; one HTML table
    from flexarm.display import fmt

    for obj, numbers in (
        (res, [res.params["arm.joints[0].friction.coulomb"]]),
        (pred, [pred.fit_percent["a/run.csv"]["theta_1"]]),
    ):
        text = repr(obj)
        assert all(len(line) <= 80 for line in text.splitlines()), text
        assert all(fmt(x) in text for x in numbers), text
        html = obj._repr_html_()
        assert html.count("<table") == 1 and all(fmt(x) in html for x in numbers)
    assert "arm.joints[0].friction.coulomb" in repr(res) and "a/run.csv" in repr(pred)


def test_grouped_options_resolve_for_the_engine():
    """The engine reads ``options.<group>.<field>`` of resolved options: every engine group
    filled (the defaults where none is given), the given fields kept, no global stage or
    delay search unless given."""
    opts = FitOptions(
        cost=Cost(residual_level=0.2), shooting=Shooting(segment=3.0), windows=[(0.0, 5.0)]
    ).resolved()
    assert (opts.cost.residual_level, opts.shooting.segment, opts.windows) == (
        0.2,
        3.0,
        [(0.0, 5.0)],
    )
    assert opts.cost.correlation_time == Cost().correlation_time
    assert (opts.local, opts.priors) == (Local(), Priors())
    assert (opts.global_de, opts.delay_search) == (None, None)
    assert FitOptions(global_de=GlobalDE(popsize=4)).resolved().global_de == GlobalDE(popsize=4)


def test_given_groups_override_only_their_changed_fields_over_a_preset():
    """Over a preset's options (the two-link arm's) only the fields a given group changes
    from its defaults override: ``Local(max_nfev=60)`` keeps the preset's ``ftol`` None,
    ``Priors(priors=...)`` keeps its bounds, ties and bound factor; the preset's options
    themselves are left as they were (the resolved groups are fresh objects)."""
    base = presets.two_link().options
    before = copy.deepcopy(base)
    mine = FitOptions(
        local=Local(max_nfev=60),
        priors=Priors(priors={"arm.hubs[1].inertia": 0.1}),
        global_de=GlobalDE(seed=3),
        period_tolerance=1e-3,
    )
    opts = mine.resolved(base)
    assert (opts.local.max_nfev, opts.local.ftol) == (60, None)
    assert opts.priors.priors == {"arm.hubs[1].inertia": 0.1}
    assert (opts.priors.bounds, opts.priors.ties) == (base.priors.bounds, base.priors.ties)
    assert opts.priors.bound_factor == 4.0
    assert (opts.cost, opts.shooting) == (base.cost, base.shooting)
    assert opts.global_de == GlobalDE(seed=3) and opts.period_tolerance == 1e-3
    opts.cost.substeps = 99
    opts.priors.priors["x"] = 1.0
    assert base == before
    assert mine.priors.priors == {"arm.hubs[1].inertia": 0.1, "x": 1.0}  # values shared


@pytest.mark.parametrize(
    "opts, named",
    [
        (FitOptions(shooting=Shooting(segment=-1.0)), r"FitOptions\.shooting\.segment = -1.0 s"),
        (FitOptions(shooting=Shooting(initial="rest")), r"FitOptions\.shooting\.initial = 'rest'"),
        (FitOptions(cost=Cost(residual_level=0.0)), r"FitOptions\.cost\.residual_level = 0.0"),
        (FitOptions(local=Local(fd_step=float("nan"))), r"FitOptions\.local\.fd_step = nan"),
        (FitOptions(priors=Priors(bound_factor=1.0)), r"FitOptions\.priors\.bound_factor = 1.0"),
        (FitOptions(period_tolerance=-1.0), r"FitOptions\.period_tolerance = -1.0"),
    ],
)
def test_bad_options_name_the_grouped_field(opts, named):
    with pytest.raises(ValueError, match=named):
        opts.resolved().check()


def test_flat_fields_map_to_groups_and_back():
    """``FitOptions.from_flat`` is the exact inverse of the old flat mapping: every one of
    the flat record's fields lands on one grouped field with its value (``global_stage``:
    ``global_de`` given); ``from_fields`` (fit-many's row options) gives only the groups
    named, and an unknown name is one line listing the known ones."""
    flat = ScenarioFitOptions(
        segment=2.0,
        max_nfev=7,
        priors={"a": 0.3},
        residual_level=0.3,
        global_stage=True,
        popsize=4,
        windows=[(0.0, 1.0)],
        period_tolerance=1e-3,
        corr_warn=0.9,
        threads=1,
    )
    opts = FitOptions.from_flat(flat)
    for name, (group, field) in FLAT_FIELDS.items():
        got = getattr(opts, field) if not group else getattr(getattr(opts, group), field)
        assert got == getattr(flat, name), name
    assert len(FLAT_FIELDS) + 1 == len(dataclasses.fields(ScenarioFitOptions))  # global_stage
    assert FitOptions.from_flat(ScenarioFitOptions()).global_de is None
    row = FitOptions.from_fields(max_nfev=10, segment=3.0)
    assert (row.local, row.shooting) == (Local(max_nfev=10), Shooting(segment=3.0))
    assert (row.cost, row.priors, row.global_de) == (None, None, None)
    with pytest.raises(ValueError, match=r"fit option 'max_iter': not an option of the fit"):
        FitOptions.from_fields(max_iter=3)


def test_deprecated_flat_record_warns_and_fits_as_the_grouped_options():
    """The old flat record is still accepted by ``fit_scenario`` and ``flexarm.fit``, with
    a ``DeprecationWarning`` naming ``FitOptions``, and gives the grouped options' fit bit
    for bit (the same resolved options); its bad values are named by the grouped field."""
    from flexarm.identification.time_domain.general import fit_scenario

    truth = two_mode_link()
    short = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 0.5})}
    )
    t = np.arange(251) * 0.002
    log = scenario_log(short, {"reference": staircase(t, [0.0, 0.3], 0.25)}, seed=5)
    free = ["arm.hubs[0].inertia"]
    template = scenario_with(short, {free[0]: 0.024})
    grouped = fit_scenario(
        template,
        [log],
        free,
        FitOptions(shooting=Shooting(segment=0.25), local=Local(max_nfev=2)),
        predict=False,
    )
    with pytest.warns(DeprecationWarning, match="ScenarioFitOptions .* deprecated.*FitOptions"):
        flat = fit_scenario(
            template, [log], free, ScenarioFitOptions(segment=0.25, max_nfev=2), predict=False
        )
    assert flat.params == grouped.params and flat.cost == grouped.cost
    assert grouped.params[free[0]] != 0.024  # it moved: the comparison is not vacuous
    with (
        pytest.warns(DeprecationWarning, match="flexarm.fit: ScenarioFitOptions"),
        pytest.raises(ValueError, match=r"FitOptions\.shooting\.segment = -1.0 s"),
    ):
        flexarm.fit(template, [log], free, ScenarioFitOptions(segment=-1.0))


@pytest.mark.slow
def test_cli_fit_builtin_without_free_runs_the_preset_and_json_is_to_dict(tmp_path):
    """Issue #23: ``flexarm fit quanser-two-link LOG --log-format ... --window a:b`` without
    ``--free`` runs the preset's free list and says so; its ``--json`` is exactly
    ``FitResult.to_dict()`` (read back by ``FitResult.from_dict``). A short window and a
    small budget: this checks the path, not the fit's quality (test_two_link does)."""
    import json
    import subprocess
    import sys

    from flexarm.identification.time_domain.result import FitResult

    data = ROOT.parent / "shared" / "data" / "two-link-rig" / "lqr_full_10deg.mat"
    if not data.exists():
        pytest.skip(f"two-link workspace not found at {data} (../shared is absent)")
    out = tmp_path / "fit.json"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "flexarm",
            "fit",
            "quanser-two-link",
            str(data),
            "--log-format",
            str(ROOT / "examples" / "two-link-workspace.toml"),
            "--window",
            "0:5",
            "--max-nfev",
            "2",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=1200,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "free parameters (15): preset quanser-two-link" in r.stdout
    d = json.loads(out.read_text())
    assert d["free_source"] == "preset quanser-two-link" and len(d["free"]) == 15
    back = FitResult.from_dict(d)
    assert json.loads(json.dumps(back.to_dict())) == d


def test_rig_trace_draws_only_what_the_log_measures():
    """A rigid arm's log (its tip column all zeros): the rig engines' dummy link mode has
    no panel, measured or simulated; a flexible log keeps the tip; the command always."""
    from flexarm.identification.time_domain.predict import Prediction, overlay_figure, rig_trace

    t = np.arange(200) * 1e-3
    hub = np.sin(7 * t)
    sim = [hub * 1.01, 0.02 * np.sin(30 * t), 0.5 * np.cos(7 * t)]
    sig = {"motor_angle": hub, "reference": 0 * t, "voltage": 0.5 * np.cos(7 * t)}
    rigid = rig_trace(Log(None, t, {**sig, "tip_deflection": 0 * t}), sim)
    assert list(rigid["simulated"]) == ["motor_angle", "command"]
    assert list(rigid["measured"]) == ["motor_angle", "command"]
    flex = rig_trace(Log(None, t, {**sig, "tip_deflection": 0.01 * np.sin(30 * t)}), sim)
    assert list(flex["simulated"]) == ["motor_angle", "tip_deflection", "command"]
    fig = overlay_figure(Prediction("rig", {"r": {"motor_angle": 99.0}}, {"r": rigid}), "r")
    assert len(fig.get_axes()) == 2


@pytest.mark.parametrize(
    "opts, named",
    [
        (FitOptions(shooting=Shooting(segment=2.0)), "shooting"),
        (FitOptions(cost=Cost(quantise=True), local=Local(max_nfev=5)), "cost, local"),
        (FitOptions(continuous=True), "continuous"),
    ],
)
def test_servo_rig_preset_refuses_the_groups_its_engine_does_not_read(opts, named):
    """The rotary servo's engine reads FitOptions.servo_rig and windows only: another group
    is one ValueError naming it (before any log is read), not dropped silently."""
    preset = presets.servo_rig(presets.DataSheet(gear_ratio=70.0))
    with pytest.raises(ValueError, match=rf"FitOptions\.{named}: the rotary servo preset"):
        flexarm.fit(preset, ["no-such-log.csv"], options=opts)


def test_fit_draws_its_prediction_into_options_plots(short_run, tmp_path):
    """``FitOptions.plots``: the engine writes the whole-run prediction's overlay figures
    (one PNG a log, named NN_FILE_fit.png, both same-named logs kept) and lists them in
    ``FitResult.plots``; the fit % it reports is the one prediction's
    (``flexarm.validate`` of the fitted result on the same logs, equal to 1e-9: the same
    deterministic simulation)."""
    _, template, paths = short_run
    res = flexarm.fit(
        template,
        paths,
        ["arm.joints[0].friction.coulomb"],
        FitOptions(local=Local(max_nfev=2), plots=tmp_path / "figs"),
    )
    assert [Path(p).name for p in res.plots] == ["00_run.csv_fit.png", "01_run.csv_fit.png"]
    assert all(Path(p).stat().st_size > 10_000 for p in res.plots)
    again = flexarm.validate(res, paths)
    for k in ("a/run.csv", "b/run.csv"):
        assert res.fit_percent[k]["theta_1"] == pytest.approx(
            again.fit_percent[k]["theta_1"], abs=1e-9
        )


def test_prediction_reports_rmse_in_si_and_nrmse(short_run):
    """Issue #44 item 6: beside fit %, every prediction carries the RMSE in the signal's SI
    unit and the NRMSE (RMSE over the signal's range), checked against their definitions
    computed here from the returned traces (to round-off, 1e-12 relative), and fit % to 3
    decimals (its own definition, 100 (1 − ‖y − ŷ‖/‖y − ȳ‖), to 5e-4 points: the
    rounding). The truth predicting its own log from the logged start has a small RMSE."""
    truth, _, paths = short_run
    pred = flexarm.validate(truth, [paths[0]], PredictOptions(initial="log"))
    key = next(iter(pred.fit_percent))
    tr = pred.traces[key]
    for c, fp in pred.fit_percent[key].items():
        y, yh = np.asarray(tr["measured"][c]), np.asarray(tr["simulated"][c])
        rmse = float(np.sqrt(np.mean((y - yh) ** 2)))
        assert pred.rmse[key][c] == pytest.approx(rmse, rel=1e-12), c
        assert pred.nrmse[key][c] == pytest.approx(rmse / np.ptp(y), rel=1e-12), c
        fit = 100 * (1 - np.linalg.norm(y - yh) / np.linalg.norm(y - y.mean()))
        assert fp == pytest.approx(fit, abs=5e-4), c
        assert pred.to_dict()["rmse"][key][c] == pred.rmse[key][c]
    assert pred.rmse[key]["theta_1"] < 1e-2  # rad: the truth's own log


def test_the_drive_command_is_scored_like_a_sensor_channel(short_run):
    """Issue #44 item 3: the drive's command (here ``current_1``, the current drive's input)
    is a channel a prediction (and a fit: ``Cost(channels=...)``, ``--channel``) compares,
    though the scenario declares no sensor for it: the engine adds the command channel
    (:func:`flexarm.sim.sampled.command_signal`). The truth predicting its own run: the
    logged command is the controller's on noisy measurements, the simulated one on the
    simulated measurements, so the fit is high but not exact (measured 97-99 %; floor
    90 %), with its RMSE in A."""
    from dataclasses import replace

    from flexarm.io.logformat import load_log

    truth, _, paths = short_run
    log = load_log(paths[0])
    sig = dict(log.signals)
    sig["current_1"] = sig.pop("command")
    log = replace(log, signals=sig)
    assert "current_1" not in truth.sensors
    pred = flexarm.validate(
        truth, [log], PredictOptions(channels=["theta_1", "current_1"], initial="log")
    )
    fp = next(iter(pred.fit_percent.values()))
    e = next(iter(pred.rmse.values()))
    print("fit %", fp, "RMSE", e)
    assert fp["current_1"] > 90.0 and fp["theta_1"] > 95.0, fp
    assert 0 < e["current_1"] < 0.1 * np.ptp(sig["current_1"])


def test_the_old_fit_names_are_deprecated_aliases(monkeypatch):
    """Issue #43 item 4: ``time_domain.fit``, ``time_domain.fit_scenario`` and
    ``general.refit_friction`` warn (DeprecationWarning naming ``flexarm.fit``) and call
    the engine they always called (here a stand-in that records the call)."""
    import importlib

    import flexarm.identification.time_domain as td
    from flexarm.identification.time_domain import general

    # the module (the package's attribute ``fit`` is the alias)
    rig_module = importlib.import_module("flexarm.identification.time_domain.fit")

    calls = []
    monkeypatch.setattr(rig_module, "fit", lambda logs, **kw: calls.append(("rig", kw)) or 1)
    monkeypatch.setattr(
        general, "fit_scenario", lambda *a, **kw: calls.append(("scenario", a[2])) or 2
    )
    with pytest.warns(DeprecationWarning, match=r"flexarm\.fit\(presets\.servo_rig"):
        assert td.fit(["log"], gear_ratio=48.4) == 1
    with pytest.warns(DeprecationWarning, match=r"use flexarm\.fit\(scenario, logs, free"):
        assert td.fit_scenario("sc", ["log"], ["a.b"]) == 2
    assert calls == [("rig", {"gear_ratio": 48.4}), ("scenario", ["a.b"])]
