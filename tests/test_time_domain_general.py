"""The general time-domain fit (identification/time_domain/general.py) on synthetic logs:
logs simulated from a known scenario (sensor noise, quantisation, the sampled controller,
the actuator's saturation), fitted from a template whose free parameters are perturbed
(×1.3, ÷1.25, ×1.2 ...). Issue #13's must-show: the physical parameters come back within
5 %."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.identification.time_domain.general import fit_scenario
from flexarm.identification.time_domain.options import Cost, FitOptions, Local, Priors, Shooting
from flexarm.identification.time_domain.synthetic import scenario_log
from flexarm.specs.paths import expand_paths, parse_path, scenario_with
from flexarm.specs.scenario import load_scenario, scenario_from_dict

#: the template's values are the truth times these factors (cycled over the free list)
PERTURB = (1.3, 1 / 1.25, 1.2, 1 / 1.3, 1.25, 1 / 1.2, 1.3)


def staircase(t: np.ndarray, steps, hold: float) -> np.ndarray:
    """Moves of several sizes and both signs, so that viscous and Coulomb friction act at
    different speeds and the joint stops (sticks) between moves."""
    return np.asarray([steps[max(0, min(int(tk / hold), len(steps) - 1))] for tk in t])


def two_mode_link():
    """A one-link multi_link arm: one assumed-modes link with 2 modes, a current drive,
    joint Coulomb friction (breakaway = Coulomb level), viscous friction, a sampled PD."""
    return scenario_from_dict(
        {
            "name": "two-mode-link",
            "arm": {
                "kind": "multi_link",
                "gravity": 0.0,
                "links": [
                    {
                        "length": 0.5,
                        "linear_density": 0.2,
                        "flexural_rigidity": 2.0,
                        "modes": 2,
                        "damping_ratio": 0.01,
                    }
                ],
                "hubs": [{"inertia": 0.02}],
                "payload": {"mass": 0.05, "inertia": 1e-5},
                "joints": [
                    {
                        "viscous": 0.01,
                        "drive": {"drive": "current", "torque_constant": 0.5, "current_limit": 3.0},
                        "friction": {"model": "coulomb", "coulomb": 0.02},
                    }
                ],
            },
            "sampling": {"period": 0.002},
            "simulation": {"duration": 6.0, "substeps": 4},
            "sensors": {
                "theta_1": {"bits": 16, "range": 2 * np.pi, "noise": 1e-4},
                "deflection_1": {"bits": 14, "range": 0.1, "noise": 2e-5},
            },
            "controller": {"type": "pd", "kp": 1.0, "kd": 0.08, "measured": "theta_1"},
        }
    )


def quantised_link():
    """The two-mode link behind a coarse 9-bit hub encoder (12.3 mrad a count), 4 s, and its
    staircase reference: a loop whose quantised cost stalls finite differences."""
    d = two_mode_link().model_dump()
    d["sensors"]["theta_1"]["bits"] = 9
    d["simulation"]["duration"] = 4.0
    t = np.arange(2001) * 0.002
    return scenario_from_dict(d), staircase(t, [0.3, -0.2, 0.5, 0.1], 1.0)


def _recover(truth, free, ref, options, seed=1):
    log = scenario_log(truth, {"reference": ref}, seed=seed)
    d = truth.model_dump()
    true = {p: float(_get(d, p)) for p in free}
    template = scenario_with(
        truth, {p: v * PERTURB[i % len(PERTURB)] for i, (p, v) in enumerate(true.items())}
    )
    res = fit_scenario(template, [log], free, options)
    err = {p: res.params[p] / true[p] - 1 for p in free}
    return res, err


def _get(d, path):
    for k in parse_path(path):
        d = d[k]
    return d


def test_paths_parse_and_expand():
    d = load_scenario("deluca-two-link-geared").model_dump()
    assert parse_path("arm.joints[1].friction.coulomb") == [
        "arm",
        "joints",
        1,
        "friction",
        "coulomb",
    ]
    assert expand_paths(d, ["arm.joints[*].friction.coulomb"]) == [
        "arm.joints[0].friction.coulomb",
        "arm.joints[1].friction.coulomb",
    ]
    with pytest.raises(ValueError, match="arm.links has no 5"):
        fit_scenario(load_scenario("deluca-two-link-geared"), [], ["arm.links[5].mass"])
    with pytest.raises(ValueError, match="not a path"):
        parse_path("arm..joints")


@pytest.mark.slow  # ~35 s on a shared 2-core machine
def test_two_mode_link_recovered_within_5_percent():
    """Multiple shooting on 0.5 s segments, each started from the state read off the log
    with its offsets estimated (node states), then a polish on the whole 6 s log (its start
    state estimated the same way). 5 % is #13's acceptance; measured <= 0.21 % on these
    logs (noise 1e-4 rad / 20 µm, 16/14-bit converters)."""
    truth = two_mode_link()
    t = np.arange(3001) * 0.002
    ref = staircase(t, [0.0, 0.4, -0.1, 0.6, 0.05, -0.3, 0.2, 0.0], 0.75)
    free = [
        "arm.joints[0].friction.coulomb",
        "arm.joints[0].viscous",
        "arm.links[0].flexural_rigidity",
        "arm.hubs[0].inertia",
        "arm.joints[0].drive.torque_constant",
        "arm.links[0].damping_ratio",
    ]
    opts = FitOptions(shooting=Shooting(segment=0.5, polish=True), local=Local(max_nfev=60))
    res, err = _recover(truth, free, ref, opts)
    assert all(abs(e) < 0.05 for e in err.values()), err
    # the whole-run prediction of the fitted model matches the log (noise only: > 97 %)
    assert res.fit_percent["synthetic"]["theta_1"] > 97
    assert res.fit_percent["synthetic"]["deflection_1"] > 97


@pytest.mark.slow
def test_feliu_current_driven_arm_recovered_within_5_percent():
    """FRB's single-mass arm (current drive, Coulomb friction, lumped beam with the pinned
    tip mass), PD on the motor angle at 3 ms with one period of computation delay, the
    12-bit D/A, 14-bit A/D converters. All torques and inertias scaled together (J, V, K,
    F_c, EI, m) leave the motion unchanged, so one must be known: the catalogue torque
    constant K stays fixed. With the paper's 12-bit A/D (1.5 mrad count) the PD's derivative
    chatters by ±0.15 A; the smooth fitted loop (quantisation off while fitting) lacks that
    dither and the viscous V comes out 5–11 % off (measured), so this test uses 14 bits.
    Reference: 4 s of two sines (a range of speeds separates V from F_c), then a
    staircase. Measured errors: <= 0.70 % (EI and m, which the data barely separate)."""
    sc = load_scenario("feliu-single-mass")
    fr = sc.arm.friction.model_copy(update={"static": None})
    sens = {k: v.model_copy(update={"bits": 14}) for k, v in sc.sensors.items()}
    truth = sc.model_copy(
        update={
            "arm": sc.arm.model_copy(update={"friction": fr}),
            "sensors": sens,
            "simulation": sc.simulation.model_copy(update={"duration": 8.2}),
        }
    )
    t = np.arange(2734) * sc.sampling.period
    ref = np.where(
        t < 4.0,
        0.3 * np.sin(2 * np.pi * 0.5 * t) + 0.15 * np.sin(2 * np.pi * 1.3 * t),
        staircase(t - 4.0, [0.0, 0.4, -0.1, 0.6, 0.05, -0.3], 0.7),
    )
    free = [
        "arm.motor.inertia",
        "arm.motor.viscous",
        "arm.friction.coulomb",
        "arm.beam.youngs_modulus",
        "arm.beam.masses[0].mass",
    ]
    opts = FitOptions(shooting=Shooting(segment=0.6, polish=True), local=Local(max_nfev=60))
    res, err = _recover(truth, free, ref, opts)
    assert all(abs(e) < 0.05 for e in err.values()), err
    # a pinned tip mass on a massless wire: only ω² = 3EI/(L³m) and the coupling C = 3EI/L
    # reach the hub, and the data barely separate EI from m: the fit must say so
    assert any("youngs_modulus" in w and "masses[0].mass" in w for w in res.warnings)


def test_bad_input_names_the_field_and_value():
    truth = two_mode_link()
    log = scenario_log(
        truth.model_copy(
            update={"simulation": truth.simulation.model_copy(update={"duration": 0.2})}
        )
    )
    free = ["arm.hubs[0].inertia"]
    with pytest.raises(ValueError, match=r"bounds\['arm.hubs\[0\].inertia'\].*does not contain"):
        fit_scenario(
            truth,
            [log],
            free,
            FitOptions(priors=Priors(bounds={"arm.hubs[0].inertia": (0.03, 0.05)})),
        )
    with pytest.raises(ValueError, match="has a prior or bounds but is not free"):
        fit_scenario(
            truth, [log], free, FitOptions(priors=Priors(priors={"arm.joints[0].viscous": 0.3}))
        )
    # a parameter at 0 is fitted in linear space and needs a scale (#44): named, with --bound
    with pytest.raises(ValueError, match=r"arm.hubs\[0\].mass' starts at 0 .*--bound"):
        fit_scenario(truth, [log], ["arm.payload.mass"] * 0 + ["arm.hubs[0].mass"])
    with pytest.raises(ValueError, match="no log holds channel 'theta_2'|not a sensor channel"):
        fit_scenario(truth, [log], free, FitOptions(cost=Cost(channels={"theta_2": 1.0})))
    slow = log.__class__(log.path, log.time * 2, log.signals)
    with pytest.raises(ValueError, match="sampled every 0.004 s.*period is 0.002 s"):
        fit_scenario(truth, [slow], free)
    with pytest.raises(
        ValueError,
        match=r"FitOptions\.priors\.priors\['arm.hubs\[0\].inertia'\] = 0.0: the relative standard",
    ):
        fit_scenario(
            truth, [log], free, FitOptions(priors=Priors(priors={"arm.hubs[0].inertia": 0.0}))
        )
    blind = log.__class__(
        log.path, log.time, {k: v for k, v in log.signals.items() if k != "theta_1"}
    )
    # a segment after the log's first sample starts the controller from its run over the
    # logged channels: the ones it reads must be logged (from the first sample none are)
    with pytest.raises(ValueError, match="no column 'theta_1', which the controller"):
        fit_scenario(
            truth,
            [blind],
            free,
            FitOptions(
                cost=Cost(channels={"deflection_1": 1.0}),
                shooting=Shooting(segment=0.1),
                local=Local(max_nfev=1),
            ),
        )
    with pytest.raises(ValueError, match="none of scenario .* sensor channels"):
        fit_scenario(truth, [log.__class__(log.path, log.time, {"x": log.time})], free)


def test_prior_pulls_an_unidentifiable_parameter_to_its_data_sheet_value():
    """A parameter the data cannot see (a sensor gain on a channel left out of the cost)
    stays at its prior mean, and its std is the prior's: |p| σ_p (eq. 2 alone). (The log
    starts from the scenario's state: with initial="log" the gain would scale the start
    deflection read off the log, which the data do see.)"""
    truth = two_mode_link()
    log = scenario_log(
        truth.model_copy(
            update={"simulation": truth.simulation.model_copy(update={"duration": 0.5})}
        ),
        {"reference": np.full(251, 0.2)},
    )
    res = fit_scenario(
        truth,
        [log],
        ["sensors.deflection_1.gain"],
        FitOptions(
            cost=Cost(channels={"theta_1": 1.0}),
            shooting=Shooting(initial="scenario"),
            priors=Priors(priors={"sensors.deflection_1.gain": 0.25}),
            local=Local(max_nfev=5),
        ),
    )
    assert res.params["sensors.deflection_1.gain"] == pytest.approx(1.0, abs=1e-9)
    assert res.std["sensors.deflection_1.gain"] == pytest.approx(0.25, rel=1e-6)


@pytest.mark.slow  # ~45 s: two fits and three predictions through the CLI
def test_cli_fit_and_validate_refit_friction(tmp_path):
    """flexarm fit SCENARIO LOG... --free ... and flexarm validate --refit friction on a
    synthetic log of the two-mode link (CSV through the default log format). The refit
    starts from a scenario whose Coulomb level is 1.3× the truth and must bring it back
    within 5 % (the synthetic acceptance's tolerance), everything else fixed."""
    import json

    from typer.testing import CliRunner

    from flexarm.cli import app
    from flexarm.identification.time_domain.result import drop_none as _drop_none
    from flexarm.io.logs import write_log
    from flexarm.io.write import write_toml

    truth = two_mode_link()
    t = np.arange(1501) * 0.002
    ref = staircase(t, [0.0, 0.4, -0.1, 0.3], 0.75)
    short = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 3.0})}
    )
    log = scenario_log(short, {"reference": ref}, seed=2)
    path = write_log(tmp_path / "run.csv", log.time, log.signals, required=("time",))
    wrong = scenario_with(short, {"arm.joints[0].friction.coulomb": 0.026})
    sc_path = tmp_path / "template.toml"
    write_toml(sc_path, _drop_none(wrong.model_dump()))
    runner = CliRunner()
    r = runner.invoke(
        app,
        [
            "fit",
            str(sc_path),
            str(path),
            "--free",
            "arm.hubs[0].inertia",
            "--free",
            "arm.joints[0].friction.coulomb",
            "--json",
            str(tmp_path / "fit.json"),
            "--max-nfev",
            "20",
        ],
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "fit.json").read_text())
    assert d["params"]["arm.hubs[0].inertia"] == pytest.approx(0.02, rel=0.05)
    assert d["params"]["arm.joints[0].friction.coulomb"] == pytest.approx(0.02, rel=0.05)
    r = runner.invoke(
        app,
        [
            "validate",
            str(sc_path),
            str(path),
            "--refit",
            "friction",
            "--refit-window",
            "0:3",
            "--json",
            str(tmp_path / "val.json"),
        ],
    )
    assert r.exit_code == 0, r.output
    v = json.loads((tmp_path / "val.json").read_text())
    assert v["refit"]["params"]["arm.joints[0].friction.coulomb"] == pytest.approx(0.02, rel=0.05)
    before = v["fit_percent"]["run.csv" if "run.csv" in v["fit_percent"] else str(path)]
    after = v["refit"]["fit_percent"][next(iter(v["refit"]["fit_percent"]))]
    assert after["theta_1"] > before["theta_1"]


@pytest.mark.slow  # ~1 min: a two-link arm with stick-slip, 8 channels, segments
def test_two_link_rig_model_recovered_from_segments_started_on_the_log():
    """The built-in quanser-two-link (current drives with stiction, torsional links, the
    lab's digital filters on the strain gauges and encoders, the LQR) simulated on its own
    square waves; fitted on 1.5 s segments, each started from the logged state (strain
    gauge reading recovered by inverting its 2 Hz filter, filter states from the log,
    controller run over the log) with node offsets: the stiffnesses, torque constants and
    the shoulder's Coulomb level come back within 5 %."""
    sc = load_scenario("quanser-two-link")
    truth = sc.model_copy(update={"simulation": sc.simulation.model_copy(update={"duration": 9.0})})
    free = [
        "arm.links[0].torsional_stiffness",
        "arm.links[1].torsional_stiffness",
        "arm.joints[0].drive.torque_constant",
        "arm.joints[1].drive.torque_constant",
        "arm.joints[0].friction.coulomb",
    ]
    d = truth.model_dump()
    true = {p: float(_get(d, p)) for p in free}
    log = scenario_log(truth, seed=0)
    template = scenario_with(truth, {p: v * PERTURB[i] for i, (p, v) in enumerate(true.items())})
    res = fit_scenario(
        template,
        [log],
        free,
        FitOptions(
            cost=Cost(
                channels={c: 1.0 for c in ("theta_1", "alpha_f_1", "theta_2", "alpha_f_2")},
                substeps=4,
            ),
            shooting=Shooting(segment=1.5),
            local=Local(max_nfev=30),
        ),
        predict=False,
    )
    err = {p: res.params[p] / true[p] - 1 for p in free}
    assert all(abs(e) < 0.05 for e in err.values()), err


@pytest.mark.slow  # ~36 s: three fits of a quantised loop
def test_quantised_fit_reached_by_continuation():
    """A coarse 9-bit encoder (12.3 mrad a count) in the loop: fitted with the converters'
    rounding (``quantise``), the local stage on the rounded loop alone stalls where it
    starts (its cost is piecewise constant at the scale of one count, so the
    finite-difference Jacobian sees no slope: Coulomb stays ≥ 15 % off, the template's
    +30 %), while the continuation (smooth loop first, then the rounded one from its
    optimum, as the servo rig engine does) brings Coulomb and viscous friction within 5 %
    (#13's acceptance; measured 0.2 % and 1.0 %) and the hub inertia within 10 %
    (measured 4.3 %: the count hides small accelerations)."""
    truth, ref = quantised_link()
    free = ["arm.joints[0].friction.coulomb", "arm.joints[0].viscous", "arm.hubs[0].inertia"]
    errs = {}
    for cont in (False, True):
        opts = FitOptions(
            cost=Cost(quantise=True, continuation=cont), shooting=Shooting(segment=0.5)
        )
        res, errs[cont] = _recover(truth, free, ref, opts)
        assert ("smooth" in res.stages) is cont
    assert abs(errs[False]["arm.joints[0].friction.coulomb"]) >= 0.15, errs[False]
    e = errs[True]
    assert abs(e["arm.joints[0].friction.coulomb"]) < 0.05, e
    assert abs(e["arm.joints[0].viscous"]) < 0.05, e
    assert abs(e["arm.hubs[0].inertia"]) < 0.10, e


@pytest.mark.slow  # ~19 s: two fits
def test_restart_goes_on_where_a_collapsed_trust_region_stopped():
    """``restarts``: a local stage that stopped early (here forced: ``xtol`` = 0.2, so trf
    ends as soon as its trust region shrinks to a fifth of |z|, far from the optimum) is
    restarted from its optimum with a fresh trust region; the restarts lower Σ r² by more
    than its resolution (ftol of itself), each restart's gain is recorded, and without
    restarts the same fit ends higher. (On the real two-link split a collapse on a kink of
    the stick-slip cost ended one machine's fit at Σ r² 534 against 453 on others.)"""
    truth = two_mode_link()
    t = np.arange(751) * 0.002
    short = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 1.5})}
    )
    log = scenario_log(short, {"reference": staircase(t, [0.0, 0.4, -0.1], 0.5)}, seed=3)
    free = ["arm.joints[0].viscous", "arm.hubs[0].inertia", "arm.links[0].flexural_rigidity"]
    d = short.model_dump()
    template = scenario_with(short, {p: float(_get(d, p)) * 1.3 for p in free})
    costs = {}
    for k in (0, 2):
        opts = FitOptions(
            local=Local(xtol=0.2, max_nfev=30, restarts=k),
            shooting=Shooting(estimate_states=False),
        )
        res = fit_scenario(template, [log], free, opts, predict=False)
        costs[k] = res.stages["local"]["cost"]
        gains = res.stages["local"]["restarts"]
        if k == 0:
            assert gains == []
        else:
            assert gains and gains[0] > Local().ftol * costs[0], gains
    print("local cost without / with restarts:", costs)
    assert costs[2] < costs[0] * (1 - 1e-6), costs


@pytest.mark.slow  # ~20 s: one fit of a 4 s log
def test_signed_bias_fitted_in_linear_space_from_zero():
    """Issue #44 item 4: a bias torque (a signed parameter) starts at 0 and ends with the
    truth's sign and size, inside its reported 3 σ. It is fitted as p = p0 + s z with the
    scale s from the joint's Coulomb level (0.02 N·m); the log-space form, p0·exp(z), could
    neither leave 0 nor change sign. Moves of both signs make the bias (constant) and the
    Coulomb torque (against the motion) separable; 3 σ is the usual coverage of a
    Gaussian std estimate (99.7 %)."""
    truth = scenario_with(two_mode_link(), {"arm.joints[0].friction.bias": -0.008})
    truth = truth.model_copy(
        update={"simulation": truth.simulation.model_copy(update={"duration": 4.0})}
    )
    t = np.arange(2001) * 0.002
    log = scenario_log(
        truth, {"reference": staircase(t, [0.0, 0.3, -0.2, 0.25, -0.3], 0.8)}, seed=4
    )
    free = ["arm.joints[0].friction.bias", "arm.joints[0].friction.coulomb"]
    template = scenario_with(truth, {free[0]: 0.0, free[1]: 0.02 * 1.3})
    res = fit_scenario(template, [log], free, FitOptions(local=Local(max_nfev=20)))
    bias, sd = res.params[free[0]], res.std[free[0]]
    print("bias", bias, "+-", sd, "coulomb", res.params[free[1]], res.stages.get("linear"))
    assert res.stages["linear"] == [free[0]]
    assert bias < 0 and np.isfinite(sd) and sd > 0
    assert abs(bias - (-0.008)) <= 3 * sd, (bias, sd)  # measured 9.8e-6 = 1.3 sd
    assert res.params[free[1]] == pytest.approx(0.02, rel=0.1)


def test_signed_parameter_at_zero_without_a_scale_names_the_bound_option():
    truth = scenario_with(two_mode_link(), {"arm.joints[0].friction.coulomb": 0.0})
    log = scenario_log(
        truth.model_copy(
            update={"simulation": truth.simulation.model_copy(update={"duration": 0.2})}
        ),
        {"reference": np.full(101, 0.1)},
    )
    with pytest.raises(ValueError, match=r"starts at 0 .*--bound arm\.joints\[0\]\.friction\.bias"):
        fit_scenario(
            truth, [log], ["arm.joints[0].friction.bias"], FitOptions(local=Local(max_nfev=2))
        )
    # with a range it has its scale (half the range / bound_factor) and bounds that may
    # change sign: one evaluation runs
    res = fit_scenario(
        truth,
        [log],
        ["arm.joints[0].friction.bias"],
        FitOptions(
            local=Local(max_nfev=1),
            priors=Priors(bounds={"arm.joints[0].friction.bias": (-0.03, 0.03)}),
        ),
    )
    assert res.stages["linear"] == ["arm.joints[0].friction.bias"]
