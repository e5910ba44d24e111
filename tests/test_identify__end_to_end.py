"""Identification end to end on flexarm's own simulator, from CSV files, via the CLI:
sine experiments (FRB Sec. II-A) on the simulated arm with friction, 12-bit converters
and sensor noise, then `flexarm identify`.

Numbers measured when this test was written (paper arm): C_f 0.1295 A (true 0.132);
the paper's free fit to the corrected data: zeros 2.6 %, resonant poles 1 %, low real
pole ~60 % off; the default structured fit (J, V, C, C_f jointly, friction shape measured
from the motor velocity): zeros 0.0-0.2 %, resonant poles 0.3-0.7 %, low real pole 4.1-4.5 %.
The low pole (0.63 rad/s) is set by V, whose current is a few mA against 132 mA of Coulomb
current, so it is the one the friction-distorted data pin down worst.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from _helpers import scenario_dict
from flexarm.cli import app
from flexarm.models.single_link import SingleLinkModel
from flexarm.specs import scenario_from_dict

runner = CliRunner()
LBF_IN = 0.112984829027616


def roots(coefs):
    return np.roots(np.trim_zeros(np.asarray(coefs, float), "f"))


def compare(got_coefs, true_tf):
    """Relative errors of |zeros|, of the resonant pole pair's |p| (inf when the fit has
    no complex pair: the resonance is missed) and of the low real pole."""
    zt = np.sort(np.abs(roots(true_tf.num[0][0])))
    pt = roots(true_tf.den[0][0])
    zg = np.sort(np.abs(roots(got_coefs["num"])))
    pg = roots(got_coefs["den"])

    def pair(p):
        return np.abs(p[np.abs(p.imag) > 1e-9])

    def low(p):
        return np.sort(np.abs(p[(np.abs(p.imag) <= 1e-9) & (np.abs(p) > 1e-9)]))

    z_err = np.max(np.abs(zg / zt - 1)) if len(zg) == len(zt) else np.inf
    res_err = np.max(np.abs(pair(pg) / pair(pt)[0] - 1)) if len(pair(pg)) else np.inf
    lo_g, lo_t = low(pg), low(pt)
    low_err = float(np.abs(lo_g[0] / lo_t[0] - 1)) if len(lo_g) else np.inf
    return z_err, res_err, low_err


def run_pipeline(tmp_path, data: dict, K_text: str):
    sc_path = tmp_path / "arm.toml"
    import tomli_w

    sc_path.write_text(tomli_w.dumps(data))
    exp = tmp_path / "exp"
    r = runner.invoke(app, ["experiment", str(sc_path), "--out", str(exp), "--periods", "12"])
    assert r.exit_code == 0, r.output
    out = {}
    for label, extra in (("free", ["--free"]), ("structured", [])):
        j = tmp_path / f"{label}.json"
        r = runner.invoke(
            app,
            [
                "identify",
                str(exp),
                "--motor-constant",
                K_text,
                "--json",
                str(j),
                "--plots",
                str(tmp_path / "plots"),
                "--scenario-out",
                str(tmp_path / f"{label}.toml"),
                "--overwrite",
            ]
            + extra,
        )
        assert r.exit_code == 0, r.output
        out[label] = json.loads(j.read_text())
    assert (tmp_path / "plots" / "motor_bode.png").exists()
    return out, scenario_from_dict(data)


def noisy(data: dict) -> dict:
    for name in ("motor_angle", "tip_angle"):
        data["sensors"][name]["noise"] = 2e-4  # rad, about 1/8 of an A/D count
    return data


@pytest.fixture(scope="module")
def paper(tmp_path_factory):
    return run_pipeline(
        tmp_path_factory.mktemp("paper"),
        noisy(scenario_dict("feliu-single-mass-identified")),
        "2.184 lbf*in/A",
    )


@pytest.mark.slow
def test_paper_arm_end_to_end(paper):
    out, sc = paper
    true = SingleLinkModel.from_spec(sc.arm).motor_tf()  # eq. (12) within 0.03 %
    free, structured = out["free"], out["structured"]
    assert free["coulomb_current"] == pytest.approx(0.132, rel=0.10)
    z, res, _ = compare(free["motor_tf"], true)
    assert z < 0.05 and res < 0.05
    z, res, low = compare(structured["motor_tf"], true)
    assert z < 0.05 and res < 0.05 and low < 0.05  # every pole and zero of eq. (12)
    # the raw fit misses the resonance that the corrected fit recovers
    _, res_raw, _ = compare(free["motor_tf_raw"], true)
    assert res_raw > 3 * max(res, 0.01)
    # the beam (friction-free) is recovered: ω² and unit static gain
    den = np.asarray(free["beam_tf"]["den"])
    assert np.sqrt(den[-1] / den[0]) == pytest.approx(np.sqrt(43.75), rel=0.02)  # beam ω
    p = structured["physical_fit"]
    assert p["inertia"] == pytest.approx(0.005529 * LBF_IN, rel=0.05)
    assert p["stiffness"] == pytest.approx(0.674 * LBF_IN, rel=0.05)


@pytest.mark.slow
def test_second_arm_end_to_end(tmp_path):
    """Every parameter differs from the paper's: J, V, C, K, C_f, beam frequency."""
    d = noisy(scenario_dict("feliu-single-mass-identified"))
    d["arm"]["motor"].update(
        inertia=1.1e-3, viscous=3.0e-3, torque_constant=0.35, current_limit=5.0
    )
    d["arm"]["friction"].update(coulomb=0.08 * 0.35, static=0.08 * 0.35)  # 0.08 A
    d["arm"]["beam"].update(stiffness=0.15, tip_num=[90.0], tip_den=[1.0, 0.1, 90.0])
    out, sc = run_pipeline(tmp_path, d, "0.35")
    true = SingleLinkModel.from_spec(sc.arm).motor_tf()
    free, structured = out["free"], out["structured"]
    assert free["coulomb_current"] == pytest.approx(0.08, rel=0.10)
    for fit in (free, structured):
        z, res, _ = compare(fit["motor_tf"], true)
        assert z < 0.05 and res < 0.05
    assert compare(structured["motor_tf"], true)[2] < 0.05
    den = np.asarray(free["beam_tf"]["den"])
    assert np.sqrt(den[-1] / den[0]) == pytest.approx(np.sqrt(90.0), rel=0.02)


def test_identified_scenario_runs(paper, tmp_path):
    """The identified arm writes straight into a scenario the simulator takes."""
    from flexarm.sim.build import simulate
    from flexarm.specs import load_scenario

    out, _ = paper
    # the fixture wrote free.toml / structured.toml next to its JSON
    import glob

    path = sorted(glob.glob(str(tmp_path.parent / "paper*" / "structured.toml")))[0]
    res = simulate(load_scenario(path))
    assert np.isfinite(res["motor_angle"]).all()
