"""Plants drawn from any fit's covariance over scenario paths (design/plants.py
``from_fit``, eq. (1)), and a two-link fit's plants compared by ``flexarm design --method
lqr`` (issue #43). Synthetic fit results: known values, std and correlations on the
built-in ``quanser-two-link``; no lab data."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import flexarm
from flexarm.design import plants as pl
from flexarm.identification.time_domain.result import FitResult
from flexarm.specs.paths import get

K1 = "arm.links[0].torsional_stiffness"
K2 = "arm.links[1].torsional_stiffness"
FC = "arm.joints[0].friction.coulomb"
GAIN = "sensors.alpha_f_1.gain"
TIED = "sensors.alpha_dot_f_1.gain"  # moves with GAIN (the two-link preset's ties)
HELD = "arm.joints[1].viscous"
FREE = [K1, K2, FC, GAIN, HELD]
#: relative std (= std of ln p) of each free parameter; HELD's is not finite (undetermined)
REL = np.array([0.10, 0.15, 0.20, 0.05, np.inf])
#: the correlation of ln p between the determined ones
R = np.array(
    [
        [1.0, 0.6, -0.4, 0.0],
        [0.6, 1.0, -0.2, 0.3],
        [-0.4, -0.2, 1.0, 0.0],
        [0.0, 0.3, 0.0, 1.0],
    ]
)


def _fit_result(scenario=None) -> FitResult:
    """A two-link fit result with the known std and correlations above (values: the built-in
    rig's)."""
    sc = scenario or flexarm.load_scenario("quanser-two-link")
    d = sc.model_dump()
    params = {p: float(get(d, p)) for p in FREE}
    std = {p: float(r * abs(params[p])) for p, r in zip(FREE, REL, strict=True)}
    corr = np.full((5, 5), np.nan)
    corr[:4, :4] = R
    return FitResult(
        list(FREE),
        params,
        dict(params),
        std,
        corr,
        [],
        {},
        {},
        sc,
        True,
        "converged (synthetic)",
        0,
        0.0,
        0.0,
        stages={"ties": {TIED: GAIN}},
    )


def test_from_fit_draws_the_fits_covariance_over_scenario_paths():
    """200 plants: ln(p / p̂) of each determined parameter has mean 0 within 4 σ/√N, std σ
    within 4 σ/√(2N) (normal), and each pair's correlation ρ within 4 (1 − ρ²)/√N (the
    sample statistics' standard errors); the undetermined parameter is held at its fitted
    value with a warning naming it; the tied gain moves by its master's factor; each
    plant's scenario holds its drawn values; plant j does not depend on N."""
    n = 200
    res = _fit_result()
    b = pl.from_fit(res, n, seed=7)
    assert len(b) == n and b.info["rejected_fraction"] == 0.0
    assert b.names == FREE and b.nominal is res.scenario
    z = np.column_stack([np.log(b.values[p] / res.params[p]) for p in FREE[:4]])
    s = REL[:4]
    assert np.all(np.abs(z.mean(0)) <= 4 * s / math.sqrt(n)), (z.mean(0), s)
    assert np.all(np.abs(z.std(0, ddof=1) - s) <= 4 * s / math.sqrt(2 * n)), z.std(0, ddof=1)
    r_hat = np.corrcoef(z.T)
    for i in range(4):
        for j in range(i + 1, 4):
            rho = R[i, j]
            assert abs(r_hat[i, j] - rho) <= 4 * (1 - rho**2) / math.sqrt(n), (i, j, r_hat)
    # the covariance is used: the strongest pair is far from independent
    assert r_hat[0, 1] > 0.4 and r_hat[0, 2] < -0.2
    # held, tied, set into the scenarios
    assert b.info["held"] == [HELD]
    assert np.all(b.values[HELD] == res.params[HELD])
    assert any(HELD in w and "not determined" in w for w in b.warnings)
    t0 = float(get(res.scenario.model_dump(), TIED))
    np.testing.assert_allclose(b.values[TIED] / t0, b.values[GAIN] / res.params[GAIN], rtol=1e-12)
    for j in (0, 57, n - 1):
        d = b.scenarios[j].model_dump()
        for p in (K1, FC, GAIN, TIED):
            assert get(d, p) == pytest.approx(b.values[p][j], rel=1e-12), (p, j)
    np.testing.assert_array_equal(pl.from_fit(res, 5, seed=7).coordinates, b.coordinates[:5])


def test_from_fit_names_what_is_missing():
    res = _fit_result()
    with pytest.raises(ValueError, match="number of plants"):
        pl.from_fit(res, 0)
    bare = FitResult.from_dict(res.to_dict())  # a document read back without its scenario
    with pytest.raises(ValueError, match="--scenario-out"):
        pl.from_fit(bare, 3)
    with pytest.raises(ValueError, match=r"ties\['sensors.nothing.gain'\]"):
        pl.from_fit(res, 3, ties={"sensors.nothing.gain": GAIN})


def test_a_servo_named_fit_is_drawn_from_its_std_on_the_scenario_paths():
    """A result keyed by the servo pipeline's names (hub_inertia, viscous) is drawn from its
    std on the fitted scenario's paths (report.scenario_spread), independently, with a
    warning: the drawn motor inertia has the fit's std (4 standard errors of a log-normal's
    sample std: sd(s) = σ √((κ − 1)/(4N)), κ its kurtosis)."""
    sc = flexarm.load_scenario("rotary-flexible-link")
    J = float(sc.arm.motor.inertia)
    res = FitResult(
        ["hub_inertia", "viscous"],
        {"hub_inertia": J, "viscous": float(sc.arm.motor.viscous)},
        {},
        {"hub_inertia": 0.1 * J, "viscous": 1e-4},
        np.eye(2),
        [],
        {},
        {},
        sc,
        True,
        "converged",
        0,
        0.0,
        0.0,
    )
    n = 400
    b = pl.from_fit(res, n, seed=2)
    x = b.values["arm.motor.inertia"]
    s2 = math.log1p(0.1**2)
    kurt = math.exp(4 * s2) + 2 * math.exp(3 * s2) + 3 * math.exp(2 * s2) - 3
    assert abs(x.std(ddof=1) - 0.1 * J) <= 4 * 0.1 * J * math.sqrt((kurt - 1) / (4 * n))
    assert abs(x.mean() - J) <= 4 * 0.1 * J / math.sqrt(n)
    assert any("not scenario paths" in w for w in b.warnings)


def test_a_two_link_fit_becomes_plants_that_design_lqr_compares(tmp_path):
    """The issue's chain on a small batch: a two-link fit's document (--json) and its
    scenario (--scenario-out) → ``flexarm design --method lqr --fit-json`` draws 3 plants
    from the fit's covariance and compares the lab's controller and the design on them,
    stepping the shoulder (theta_1, its encoder's count) and measuring its link's tip."""
    from typer.testing import CliRunner

    from flexarm.cli import app
    from flexarm.design.plants import with_overrides

    sc = with_overrides(
        flexarm.load_scenario("quanser-two-link"), {"simulation": {"duration": 2.0}}
    )
    res = _fit_result(sc)
    (tmp_path / "fit.json").write_text(json.dumps(res.to_dict()), encoding="utf-8")
    res.write_scenario(tmp_path / "fitted.toml")
    out = tmp_path / "design"
    r = CliRunner().invoke(
        app,
        [
            "design",
            str(tmp_path / "fitted.toml"),
            "--method",
            "lqr",
            "--out",
            str(out),
            "--fit-json",
            str(tmp_path / "fit.json"),
            "--plants",
            "3",
            "--accept-unstable",
        ],
    )
    assert r.exit_code == 0, r.output
    doc = json.loads((out / "compare.json").read_text(encoding="utf-8"))
    s = doc["settings"]
    assert s["n_plants"] == 3 and s["plants"]["source"].startswith("the fit's covariance")
    assert s["stepped"] == "theta_ref_1" and s["measured"]["hub"] == "theta_1"
    assert s["count_rad"] == pytest.approx(2 * math.pi / 4096 / 100)  # KE_D1
    assert s["limit_V"] == pytest.approx(0.94)  # the shoulder's current limit, A
    rows = doc["rows"]
    assert set(rows) == {"scenario", "lqr"}  # the fitted scenario's own controller, the design
    for row in rows.values():
        assert row["n_plants"] == 3
        assert math.isfinite(row["nominal"]["peak_command_V"])
        assert row["nominal"]["peak_command_V"] <= 0.94 + 1e-9
