"""The real two-mass motor bench multisine (../shared/data/motor-bench) through the whole
frequency-domain path: .mat with examples/motor-bench.toml → FRF, distortion, BLA → the
two-mass fit → the model check; and the CLI's JSON keys."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from flexarm.cli import app
from flexarm.identification.frequency_domain.periodic import periodic_frf
from flexarm.identification.frequency_domain.structures import fit_two_mass
from flexarm.io.logformat import load_log_format

ROOT = Path(__file__).resolve().parents[1]
MAT = Path(__file__).resolve().parents[2] / "shared" / "data" / "motor-bench" / "MultisineTypeB.mat"


@pytest.fixture(scope="module")
def frf():
    if not MAT.is_file():
        pytest.skip(f"real recording absent: {MAT} (the shared data folder beside the repo)")
    fmt = load_log_format(ROOT / "examples" / "motor-bench.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = fmt.read(MAT)
        return periodic_frf(
            r["current"],
            {"motor_angle": r["motor_angle"], "load_angle": r["load_angle"]},
            2500.0,
            source=str(MAT),
        )


def test_frf_design_and_distortion(frf):
    # the README's design: 2500-sample period, lines 13, 17, ..., 249 Hz; first period transient;
    # the irregular last row leaves 19 whole periods
    assert frf.period == 2500
    np.testing.assert_array_equal(frf.frequency_hz, np.arange(13, 250, 4))
    assert frf.transient_periods >= 1 and frf.periods_used == 19 - frf.transient_periods
    # odd distortion well above the noise in the lowest band (measured: ~25 dB; friction)
    low = frf.distortion["motor_angle"][0]
    assert low.odd_db - low.noise_db > 15
    assert "symmetric" in frf.verdict()
    # BLA variance ≥ noise variance at every line (it adds the nonlinear part)
    assert np.all(frf.total_std >= frf.noise_std)


def test_two_mass_fit_physics(frf):
    w = 2 * np.pi * frf.frequency_hz
    G = frf.response
    f = fit_two_mass(w, G[0], G[1], motor_std=frf.total_std[0], load_std=frf.total_std[1])
    p = {k: v["value"] for k, v in f.parameters.items()}
    # the antiresonance lies at the minimum of |G_m| ω² and the resonance at its maximum above
    # it, within the 4 Hz line spacing
    n = np.abs(G[0]) * w**2
    fa = frf.frequency_hz[np.argmin(n)]
    fr = frf.frequency_hz[np.argmin(n) + np.argmax(n[np.argmin(n) :])]
    assert abs(p["antiresonance_hz"] - fa) < 4 and abs(p["resonance_hz"] - fr) < 4
    # rigid-body check, independent of the fit: J ≈ 1/(ω²|G_m|) at the lowest line, where the
    # shaft is stiff (ω/ω_a ~ 0.25 → a (ω/ω_a)² ~ 6 % effect, the damping a few % more)
    J_low = 1 / (w[0] ** 2 * np.abs(G[0][0]))
    assert p["total_inertia"] == pytest.approx(J_low, rel=0.15)
    assert 0 < p["resonance_damping"] < 0.2 and 0 < p["delay_s"] < 1e-3
    # friction distortion: the linear model cannot reach the noise level, and the check says so
    assert f.cost > f.expected_cost + 5 * f.cost_std and "rejected" in f.verdict
    # but the model is within a few total standard deviations on average (measured ~3)
    assert np.sqrt(f.cost / f.n_frequencies) < 5
    # rejected: each parameter also carries its std inflated by sqrt(cost/expected)
    k = np.sqrt(f.cost / f.expected_cost)
    for name, v in f.parameters.items():
        assert v["std_inflated"] == pytest.approx(v["std"] * k, rel=1e-12), name


@pytest.mark.slow
def test_cli_frf_and_tfest_json(frf, tmp_path):
    run = CliRunner()
    r = run.invoke(
        app,
        [
            "frf",
            str(MAT),
            "--log-format",
            str(ROOT / "examples" / "motor-bench.toml"),
            "--input",
            "current",
            "--output",
            "motor_angle,load_angle",
            "--json",
            str(tmp_path / "frf.json"),
        ],
    )
    assert r.exit_code == 0, r.output
    d = json.loads((tmp_path / "frf.json").read_text())
    o = d["outputs"]["load_angle"]
    assert {"re", "im", "noise_std", "total_std", "distortion"} <= set(o)
    assert set(o["distortion"]) == {"band_hz", "odd_db", "even_db", "noise_db"}
    r = run.invoke(
        app,
        [
            "tfest",
            str(tmp_path / "frf.json"),
            "--structure",
            "two-mass",
            "--json",
            str(tmp_path / "tm.json"),
        ],
    )
    assert r.exit_code == 0, r.output
    t = json.loads((tmp_path / "tm.json").read_text())
    assert {"cost", "expected_cost", "verdict", "parameters"} <= set(t)
    assert {
        "total_inertia",
        "inertia_ratio",
        "antiresonance_hz",
        "resonance_hz",
        "resonance_damping",
        "delay_s",
    } <= set(t["parameters"])
    # rejected fit: raw and inflated standard deviations side by side, said which is which
    assert "rejected" in t["verdict"] and "std_inflated" in t["std_note"]
    p = t["parameters"]["resonance_hz"]
    assert p["std_inflated"] == pytest.approx(p["std"] * np.sqrt(t["cost"] / t["expected_cost"]))
    assert "(noise), inflated ±" in r.output
    # the Coulomb level from the odd distortion (measured 0.80 ± 0.05 A). Independent
    # bound: all of the BLA's viscous damping read as Coulomb friction (Bussgang) gives
    # C_f ≤ (d_m + d_l) σ_v / √(2/π) (1.67 A here); the odd distortion is 25 dB above the
    # noise, so it is detected and the line scatter leaves a std below 20 %
    c = t["coulomb"]
    cf = t["parameters"]["coulomb_current"]
    assert c["detected"] and cf["value"] == c["value"]
    bound = (
        (t["parameters"]["motor_viscous"]["value"] + t["parameters"]["load_viscous"]["value"])
        * c["velocity_rms"]
        / np.sqrt(2 / np.pi)
    )
    assert 0 < cf["value"] < bound
    assert 0 < cf["std"] < 0.2 * cf["value"]
    # friction at the motor alone cannot explain the BLA's damping split: said so
    assert any("equivalent damping" in w for w in c["warnings"])
    r = run.invoke(
        app,
        [
            "frf",
            str(MAT),
            "--log-format",
            str(ROOT / "examples" / "motor-bench.toml"),
            "--output",
            "tip",
            "--json",
            str(tmp_path / "x.json"),
        ],
    )
    assert r.exit_code == 2 and "no signal 'tip'" in r.output
