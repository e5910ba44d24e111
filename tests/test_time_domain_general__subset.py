"""The friction re-search of the general engine (``FitOptions.subset_search``,
:mod:`flexarm.identification.time_domain.subset`; issue #43: the rotary servo's friction
polish as an option of the one engine, for every rig)."""

from __future__ import annotations

import numpy as np
import pytest

from flexarm.identification.time_domain.options import (
    Cost,
    FitOptions,
    Shooting,
    SubsetSearch,
)
from test_time_domain_general import _recover, quantised_link, staircase, two_mode_link

C, B, J = "arm.joints[0].friction.coulomb", "arm.joints[0].viscous", "arm.hubs[0].inertia"


def test_bad_subset_options_name_the_field():
    for bad, field in (
        (SubsetSearch(width=0.0), "width"),
        (SubsetSearch(width=1.5), "width"),
        (SubsetSearch(popsize=0), "popsize"),
        (SubsetSearch(maxiter=2.5), "maxiter"),  # type: ignore[arg-type]
    ):
        with pytest.raises(ValueError, match=rf"FitOptions\.subset_search\.{field} = "):
            FitOptions(subset_search=bad).check()


@pytest.mark.slow  # ~40 s: two fits of a quantised loop
def test_friction_re_search_moves_a_stalled_quantised_fit():
    """The quantised case of ``test_quantised_fit_reached_by_continuation`` (a 9-bit
    encoder in the loop, every parameter started 30 % high): the local stage on the rounded
    loop alone stalls with Coulomb friction >= 15 % off (its cost is piecewise constant at
    one count). The re-search of Coulomb and viscous friction (differential evolution in
    the box z* ± 0.2 of each coordinate's range: with the bounds' factor 3 a box of
    ×/÷ 1.55 around z*, which holds the truth at 1/1.3 of the start) finds a lower
    cost, the local stage again from it is kept and goes on from there: the cost falls by
    more than a fifth and the Coulomb error by more than half (the search unsticks the
    friction levels; the continuation of the test above, smooth loop first, is what brings
    them within 5 %). The result's cost is that last local stage's."""
    truth, ref = quantised_link()
    free = [C, B, J]
    errs, recs = {}, {}
    for search in (None, SubsetSearch(width=0.2)):
        opts = FitOptions(
            cost=Cost(quantise=True, continuation=False),
            shooting=Shooting(segment=0.5),
            subset_search=search,
        )
        res, errs[search is not None] = _recover(truth, free, ref, opts)
        recs[search is not None] = res.stages
    assert abs(errs[False][C]) >= 0.15, errs[False]
    rec = recs[True]["subset_search"]
    assert rec["paths"] == [C, B]  # the free friction paths, the inertia held
    assert rec["kept"] and rec["local_cost"] <= rec["evolution_cost"] < rec["cost"], rec
    assert recs[True]["subset_local"]["cost"] == pytest.approx(rec["local_cost"], rel=1e-12)
    # measured: Coulomb +27.6 % -> +12.5 %, Σ r² 204 -> 198 (evolution) -> 130 (local)
    assert abs(errs[True][C]) < 0.5 * abs(errs[False][C]), errs
    assert rec["local_cost"] < 0.8 * rec["cost"], rec


def test_cost_spread_per_log_weighs_each_log_by_its_own_spread():
    """``Cost(spread="log")``: eq. (1) with each log's own σ_c,l, so that Σ r² is
    Σ_l Σ_c N_l,c (T / τ) (1 − fit %_l,c / 100)² / λ² (fit % = 100 (1 − ‖y − ŷ‖ / (√N σ)),
    :func:`flexarm.metrics.fit_percent`): the engine's cost checked against the fit % it
    reports per log (rounded to 0.001 point: the tolerance is that rounding's effect).
    Two logs whose moves differ fivefold: with the pooled spread the small log's misfit
    counts (σ_l / σ)² less, so the same check fails there by far more than the rounding."""
    from flexarm.identification.time_domain.general import fit_scenario
    from flexarm.identification.time_domain.options import Local
    from flexarm.identification.time_domain.synthetic import scenario_log
    from flexarm.specs.paths import scenario_with

    base = two_mode_link()
    base = base.model_copy(
        update={"simulation": base.simulation.model_copy(update={"duration": 2.0})}
    )
    t = np.arange(1001) * 0.002
    ref = staircase(t, [0.0, 0.3, -0.2, 0.25], 0.5)
    logs = [scenario_log(base, {"reference": a * ref}, seed=k) for k, a in enumerate((1.0, 0.2))]
    template = scenario_with(base, {J: 0.02 * 1.1, C: 0.02 * 1.3})
    dt, tau, lam = 0.002, Cost().correlation_time, Cost().residual_level
    for spread in ("log", "pooled"):
        opts = FitOptions(
            cost=Cost(spread=spread),
            local=Local(max_nfev=2),
            shooting=Shooting(estimate_states=False),
        )
        res = fit_scenario(template, logs, [J], opts, predict=False)
        expect, tol = 0.0, 0.0
        assert len(res.segment_fit_percent) == 2  # keyed "synthetic", "synthetic#2"
        for log, fps in zip(logs, res.segment_fit_percent.values(), strict=True):
            for fp in fps.values():
                e = 1 - fp / 100
                expect += log.time.size * dt / tau * e**2 / lam**2
                tol += log.time.size * dt / tau * 2 * e * 0.0005 / 100 / lam**2
        cost = res.stages["local"]["cost"]
        if spread == "log":
            assert cost == pytest.approx(expect, abs=tol + 1e-9 * expect), (cost, expect, tol)
        else:
            assert abs(cost - expect) > 10 * tol, (cost, expect, tol)
    with pytest.raises(ValueError, match=r"FitOptions\.cost\.spread = 'each'"):
        FitOptions(cost=Cost(spread="each")).check()


ARM_TOML = """
name = "servo-arm"
[arm]
kind = "single_link"
[arm.motor]
drive = "voltage"
inertia = 0.005
viscous = 0.004
motor_constant = 0.0107
armature_resistance = 3.29
gear_ratio = 48.4
voltage_limit = 5.0
[arm.friction]
model = "coulomb"
coulomb = 0.005
static = 0.03
bias = -0.002
[arm.beam]
model = "lumped"
length = 0.45
flexural_rigidity = 0.03
damping_ratio = 0.09
masses = [{ mass = 0.014, joint = "pinned" }]
[sampling]
period = 0.001
[sensors.motor_angle]
delay = 34
[sensors.tip_deflection]
gain = -0.59
delay = 67
[simulation]
duration = 1.0
[reference]
type = "step"
amplitude = 0.2
[controller]
type = "state_feedback"
k1 = 6.0
"""


def test_servo_bounds_are_the_pipelines_box_over_scenario_paths(tmp_path):
    """:func:`~flexarm.identification.time_domain.presets.servo_bounds`: the rotary servo
    pipeline's box as the general engine's bounds, by hand: the lumped link's mass J_l / L²
    and rigidity ω² J_l L / 3 at the corners of the (ω, J_l) box (the pipeline's own link
    stiffness C = ω² J_l and EI = C L / 3, ``params.derived``), the breakaway up to the sum
    of the Coulomb's and the excess's upper bounds, zero lower bounds raised to 1e-3 of the
    upper (unit 7's held-out hub moved 84.2 -> 82.5 % when the breakaway's lower bound was
    the Coulomb level's 1.2e-4 N·m instead of 2.2e-4: pinned here), the gauge gain's box
    with its sign, and each box widened to hold the scenario's value (the hub inertia here)."""
    from types import SimpleNamespace

    from flexarm.identification.time_domain.params import ParamDef
    from flexarm.identification.time_domain.presets import servo_bounds
    from flexarm.specs import load_scenario

    path = tmp_path / "arm.toml"
    path.write_text(ARM_TOML)
    sc = load_scenario(path)
    defs = [
        ParamDef("hub_inertia", "kg*m**2", 0.001, 0.004, "log"),  # the value 0.005 beyond
        ParamDef("link_frequency", "rad/s", 10.0, 20.0, "log"),
        ParamDef("link_inertia", "kg*m**2", 0.002, 0.05, "log"),
        ParamDef("link_damping", "", 0.002, 0.3, "log"),
        ParamDef("tip_gain", "m/m", 0.2, 1.5, "log"),
        ParamDef("viscous", "N*m*s/rad", 0.0, 0.4, "loglin", 0),
        ParamDef("coulomb", "N*m", 0.0, 0.12, "loglin", 0),
        ParamDef("static_excess", "N*m", 0.0, 0.1, "loglin", 0),
        ParamDef("bias", "N*m", -0.06, 0.06, "lin", 0),
    ]
    b = servo_bounds(SimpleNamespace(defs=defs), sc)
    L = 0.45
    want = {
        "arm.motor.inertia": (0.001, 0.005),
        "arm.motor.viscous": (4e-4, 0.4),
        "arm.friction.coulomb": (1.2e-4, 0.12),
        "arm.friction.static": (2.2e-4, 0.22),
        "arm.friction.bias": (-0.06, 0.06),
        "arm.beam.damping_ratio": (0.002, 0.3),
        "sensors.tip_deflection.gain": (-1.5, -0.2),
        "arm.beam.masses[0].mass": (0.002 / L**2, 0.05 / L**2),
        "arm.beam.flexural_rigidity": (100 * 0.002 * L / 3, 400 * 0.05 * L / 3),
    }
    assert set(b) == set(want)
    for p, (lo, hi) in want.items():
        assert b[p] == pytest.approx((lo, hi), rel=1e-12), p
