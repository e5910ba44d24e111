"""Transfer-function fit of the sine pipeline (flexarm.tfest with the log-ratio cost of FRB eq. (6))
and the identification pipeline
(flexarm.identification.frequency_domain.identify) on data of an independent simulation
(tests/_frb_sim.py)."""

from __future__ import annotations

import json
import shutil

import control
import numpy as np
import pytest

import _frb_sim as sim
from flexarm.identification.frequency_domain.harmonics import (
    IdentificationError,
    IdentificationWarning,
)
from flexarm.identification.frequency_domain.identify import identify
from flexarm.identification.frequency_domain.tfest import (
    TFEstError,
    tf_coefficients,
    tf_response,
    tfest,
)
from flexarm.specs.arm import SingleLinkArm


def fit_tf(w, H, n_zeros, n_poles, integrators=0):
    """The pipeline's fit (identify.py): tfest, log-ratio cost, no variances."""
    return tfest(
        control.frd(np.asarray(H, complex), np.asarray(w, float)),
        n_poles,
        n_zeros,
        integrators=integrators,
        cost="log",
    )


# FRB eqs. (12), (13), as printed (θm in rad, i in A).
EQ12_NUM = 394.94 * np.array([1.0, 0.06, 43.75])
EQ12_DEN = np.array([1.0, 2.26, 165.7, 103.56, 0.0])
EQ13_NUM = np.array([43.75])
EQ13_DEN = np.array([1.0, 0.06, 43.75])


def _sorted_mags(r):
    return np.sort(np.abs(np.asarray(r)))


def _root_errors(tf, num, den):
    """Relative errors of the root magnitudes (zeros, then poles; s = 0 excluded)."""
    z, zt = _sorted_mags(tf.zeros()), _sorted_mags(np.roots(num))
    p, pt = _sorted_mags(tf.poles()), _sorted_mags(np.roots(den))
    assert len(z) == len(zt) and len(p) == len(pt)
    keep = pt > 0
    assert np.all(p[~keep] < 1e-9)
    return np.abs(z / zt - 1), np.abs(p[keep] / pt[keep] - 1)


def test_fit_exact_on_noise_free_eq12_and_eq13():
    w = np.logspace(np.log10(0.5), np.log10(60), 25)
    s = 1j * w
    H = np.polyval(EQ12_NUM, s) / np.polyval(EQ12_DEN, s)
    f = fit_tf(w, H, 2, 4, integrators=1)
    c = tf_coefficients(f.tf)
    np.testing.assert_allclose(c["num"], EQ12_NUM, rtol=1e-6)
    np.testing.assert_allclose(c["den"], EQ12_DEN, rtol=1e-6, atol=1e-9)
    assert f.relative_error.max() < 1e-8
    Hb = np.polyval(EQ13_NUM, s) / np.polyval(EQ13_DEN, s)
    fb = fit_tf(w, Hb, 0, 2)
    np.testing.assert_allclose(tf_coefficients(fb.tf)["den"], EQ13_DEN, rtol=1e-6)
    np.testing.assert_allclose(tf_response(fb.tf, w), Hb, rtol=1e-8)
    # the result says how the nonlinear refinement ended; noise-free, the cost is rounding
    assert f.message and fb.message and f.cost_kind == "log"
    assert f.cost < 1e-20 and f.expected_cost is None  # no variances: nothing to test


def test_log_cost_with_variances_matches_ml():
    """With known variances the log-ratio cost is the ML cost to first order (ln(Ĥ/H) ≈
    (Ĥ−H)/H, weights |H|/σ): the two estimates differ by second-order terms, O(σ²/|H|²)
    per line against a standard deviation O(σ/(|H|√(2F))), i.e. by about
    (σ/|H|)·√(2F) = 0.02·√80 ≈ 0.18 standard deviations (measured 0.15): bound 0.5. Their
    standard deviations agree to first order (5 %), and both costs pass the χ² check."""
    w = np.logspace(np.log10(0.5), np.log10(60), 40)
    G = np.polyval(EQ13_NUM, 1j * w) / np.polyval(EQ13_DEN, 1j * w)
    sd = 0.02 * np.abs(G)
    rng = np.random.default_rng(7)
    H = G + sd * (rng.standard_normal(40) + 1j * rng.standard_normal(40)) / np.sqrt(2)
    frd = control.frd(H, w)
    ml = tfest(frd, 2, 0, std=sd)
    lg = tfest(frd, 2, 0, std=sd, cost="log")
    for k in ("b0", "a0", "a1"):
        assert (
            abs(lg.parameters[k]["value"] - ml.parameters[k]["value"])
            < 0.5 * ml.parameters[k]["std"]
        )
        assert lg.parameters[k]["std"] == pytest.approx(ml.parameters[k]["std"], rel=0.05)
    assert lg.expected_cost == ml.expected_cost == 40 - 3 / 2
    assert "accepted" in lg.verdict and "accepted" in ml.verdict
    with pytest.raises(TFEstError, match="cost = 'l2'"):
        tfest(frd, 2, 0, cost="l2")


def test_fit_refuses_too_few_frequencies():
    with pytest.raises(
        TFEstError, match="2 frequencies give 4 real equations, not more than the 6 parameters"
    ):
        fit_tf([1.0, 2.0], [1.0 + 1j, 0.5j], 2, 4, integrators=1)


# -- pipeline on the simulated paper arm ------------------------------------------------


@pytest.fixture(scope="module")
def paper_dir(tmp_path_factory):
    return sim.experiment_dir(tmp_path_factory, "paper")


@pytest.fixture(scope="module")
def paper(paper_dir):
    before = sim.file_hashes(paper_dir)
    res = identify(
        paper_dir, "2.184 lbf*in/A", structured=False
    )  # catalogue K; the paper's free fit
    assert sim.file_hashes(paper_dir) == before  # the input files are left unchanged
    return res


def test_paper_arm_coulomb_and_corrected_fit_recover_eq12(paper):
    assert paper.motor_constant == pytest.approx(0.24676, rel=1e-4)
    assert paper.coulomb_current == pytest.approx(0.132, rel=0.10)
    assert paper.coulomb_torque == pytest.approx(0.132 * 0.24676, rel=0.10)
    zerr, perr = _root_errors(paper.motor_tf, EQ12_NUM, EQ12_DEN)
    assert zerr.max() < 0.05 and perr.max() < 0.05, (zerr, perr)
    # the high-frequency gain K/J (394.94 rad/A/s²) too
    assert tf_coefficients(paper.motor_tf)["num"][0] == pytest.approx(394.94, rel=0.05)
    # G_b, eq. (13): natural frequency √43.75 and unit static gain
    zb, pb = _root_errors(paper.beam_tf, EQ13_NUM, EQ13_DEN)
    assert pb.max() < 0.01
    assert abs(tf_response(paper.beam_tf, [1e-3])[0] - 1) < 0.01
    # named python-control systems (issue #26), the same coefficients as the fits'
    gm, gb = paper.motor_tf, paper.beam_tf
    assert (gm.name, gm.input_labels, gm.output_labels) == ("G_m", ["current"], ["motor_angle"])
    assert (gb.name, gb.input_labels, gb.output_labels) == ("G_b", ["motor_angle"], ["tip_angle"])
    assert tf_coefficients(gm) == tf_coefficients(paper.motor_fit.tf)
    assert tf_coefficients(gb) == tf_coefficients(paper.beam_fit.tf)


def test_raw_data_fit_misses_the_resonance(paper):
    """Without the eq. (7) correction the resonant peak of G_m is hidden (FRB Fig. 9)."""
    raw = paper.motor_fit_raw.tf
    w_res = float(np.sqrt(43.75))  # beam frequency: G_m's antiresonance (zeros)
    true_poles = np.roots(EQ12_DEN)
    w_peak = float(np.abs(true_poles[np.argmax(true_poles.imag)]))  # 12.83 rad/s
    # (1) roots: the resonant pole pair of the raw fit is far off, much more than 5 %
    p_raw = raw.poles()
    p_raw = p_raw[np.abs(p_raw) > 1e-9]
    near = p_raw[np.argmin(np.abs(np.abs(p_raw) - w_peak))]
    assert abs(abs(near) / w_peak - 1) > 0.15
    _, perr = _root_errors(raw, EQ12_NUM, EQ12_DEN)
    assert perr.max() > 1.0  # the low pole (0.63 rad/s) is lost altogether
    z_raw = np.abs(raw.zeros())
    z_cor = np.abs(paper.motor_tf.zeros())
    assert np.max(np.abs(z_raw / w_res - 1)) > 3 * np.max(np.abs(z_cor / w_res - 1))
    # (2) magnitude at the resonance: raw fit more than 10 dB low, corrected within 2 dB
    g_true = abs(np.polyval(EQ12_NUM, 1j * w_peak) / np.polyval(EQ12_DEN, 1j * w_peak))
    g_raw = abs(tf_response(raw, [w_peak])[0])
    g_cor = abs(tf_response(paper.motor_tf, [w_peak])[0])
    assert 20 * np.log10(g_true / g_raw) > 10
    assert abs(20 * np.log10(g_cor / g_true)) < 2
    # and the raw data points next to the resonance are far below it
    fr = paper.response
    k = np.argmin(np.abs(fr.omega - w_peak))
    assert abs(fr.motor_raw[k]) < 0.3 * g_true
    assert abs(fr.motor_corrected[k]) == pytest.approx(
        abs(sim.PAPER_ARM.Gm(1j * fr.omega[k])), rel=0.05
    )


def test_paper_arm_physical_parameters_and_scenario(paper):
    p = paper.parameters
    assert p["inertia"] == pytest.approx(6.2469e-4, rel=0.05)
    assert p["viscous"] == pytest.approx(1.3739e-3, rel=0.05)
    assert p["stiffness"] == pytest.approx(0.076152, rel=0.05)
    sc = paper.to_scenario_dict(current_limit="4.12 A")
    arm = SingleLinkArm.model_validate(sc["arm"])
    assert arm.motor.torque_constant == pytest.approx(0.24676, rel=1e-4)
    assert arm.motor.current_limit == 4.12
    assert arm.friction.model == "coulomb"
    assert arm.friction.coulomb == pytest.approx(paper.coulomb_current * 0.24676, rel=1e-3)
    assert arm.beam.model == "transfer_function"
    assert arm.beam.stiffness == pytest.approx(0.076152, rel=0.05)
    assert arm.beam.tip_den == pytest.approx(tf_coefficients(paper.beam_tf)["den"])
    # without a given limit, the largest recorded current (a lower bound), said so
    sc2 = paper.to_scenario_dict()
    assert 0 < sc2["arm"]["motor"]["current_limit"] < 4.12
    assert "lower bound" in sc2["notes"]["current_limit"]


def test_json_summary_and_bode_figures(paper, tmp_path):
    d = json.loads(paper.to_json())
    for key in (
        "coulomb_current",
        "coulomb_torque",
        "coulomb_current_per_frequency",
        "motor_tf",
        "beam_tf",
        "frequency_response",
        "warnings",
    ):
        assert key in d
    assert d["coulomb_current"] == pytest.approx(paper.coulomb_current)
    assert len(d["coulomb_current_per_frequency"]) == len(sim.PAPER_PAIRS)
    assert [e["omega"] for e in d["coulomb_current_per_frequency"]] == pytest.approx(
        [p[0] for p in sim.PAPER_PAIRS], rel=1e-6
    )
    assert d["motor_tf"]["den"][-1] == 0.0 and len(d["motor_tf"]["den"]) == 5
    assert len(d["beam_tf"]["num"]) == 1 and len(d["beam_tf"]["den"]) == 3
    fr = d["frequency_response"]
    assert len(fr) == 2 * len(sim.PAPER_PAIRS)
    assert [e["omega"] for e in fr] == sorted(e["omega"] for e in fr)
    e = fr[0]
    assert set(e["motor_raw"]) == {"re", "im"} and set(e["motor_corrected"]) == {"re", "im"}
    assert set(e["beam"]) == {"re", "im"}
    assert d["warnings"] == []
    frd = paper.motor_frd()
    np.testing.assert_allclose(frd.omega, [e["omega"] for e in fr])
    paths = paper.bode_figures(tmp_path / "figs")
    assert [p.name for p in paths] == ["motor_bode.png", "beam_bode.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10000


# -- bad inputs to the pipeline ------------------------------------------------------------


def test_missing_partner_warns_and_still_returns_the_response(paper_dir, tmp_path):
    sub = tmp_path / "partial"
    sub.mkdir()
    files = sorted(paper_dir.glob("*.csv"))
    for f in files:
        if "039.00" not in f.name:  # drop the 3ω0 partner of ω0 = 13 rad/s
            shutil.copy(f, sub / f.name)
    with pytest.warns(IdentificationWarning) as rec:
        res = identify(sub, 0.24676)
    msgs = [str(r.message) for r in rec]
    assert any("sine_013.00.csv" in m and "ω0 = 13 rad/s" in m and "39 rad/s" in m for m in msgs), (
        msgs
    )
    assert len(res.coulomb.pairs) == len(sim.PAPER_PAIRS) - 1
    assert len(res.response.omega) == len(files) - 1
    assert res.coulomb_current == pytest.approx(0.132, rel=0.10)

    # no pair at all: warnings, no C_f, the raw response still there (and fitted)
    lone = tmp_path / "lone"
    lone.mkdir()
    for f in files:
        if f.name.split("_")[1][:6] in ("001.60", "002.40", "003.50", "013.00"):
            shutil.copy(f, lone / f.name)
    with pytest.warns(IdentificationWarning) as rec:
        res = identify(lone, 0.24676)
    text = " | ".join(str(r.message) for r in rec)
    assert "no ω0/3ω0 pair" in text and "raw" in text
    d = res.to_dict()
    assert d["coulomb_current"] is None and d["motor_tf_fitted_to"] == "raw"
    assert all(e["motor_corrected"] is None and e["motor_raw"] for e in d["frequency_response"])
    assert len(d["frequency_response"]) == 4


def test_empty_directory_and_bad_files(tmp_path, paper_dir):
    with pytest.raises(IdentificationError, match=r"empty_dir: no experiment logs \(\*\.csv\)"):
        identify(tmp_path.joinpath("empty_dir").mkdir() or tmp_path / "empty_dir", 0.24676)
    with pytest.raises(IdentificationError, match="no_such_dir: no such file"):
        identify(tmp_path / "no_such_dir", 0.24676)
    with pytest.raises(IdentificationError, match="motor_constant"):
        identify(paper_dir, "2 kg")
    bad = tmp_path / "one_bad"
    bad.mkdir()
    good = sorted(paper_dir.glob("*.csv"))[0]
    shutil.copy(good, bad / good.name)
    (bad / "broken.csv").write_text("time,reference,current\n0,0,0\n")
    with pytest.raises(IdentificationError) as e:
        identify(bad, 0.24676)
    assert "1 of 2 log(s) cannot be used" in str(e.value)
    assert "broken.csv: missing column(s) 'motor_angle', 'tip_angle'" in str(e.value)


# -- a second, different arm ------------------------------------------------------------


def test_second_arm(tmp_path_factory):
    arm = sim.SECOND_ARM
    folder = sim.experiment_dir(tmp_path_factory, "second")
    before = sim.file_hashes(folder)
    res = identify(sorted(folder.glob("*.csv")), arm.K, structured=False)  # the paper's free fit
    assert sim.file_hashes(folder) == before
    assert res.coulomb_current == pytest.approx(arm.coulomb_current, rel=0.10)
    num, den = arm.Gm_tf()
    zerr, perr = _root_errors(res.motor_tf, num, den)
    assert zerr.max() < 0.05 and perr.max() < 0.05, (zerr, perr)
    _, pb = _root_errors(res.beam_tf, [arm.wb2], [1, arm.b, arm.wb2])
    assert pb.max() < 0.01
    p = res.parameters
    assert p["inertia"] == pytest.approx(arm.J, rel=0.05)
    assert p["viscous"] == pytest.approx(arm.V, rel=0.05)
    assert p["stiffness"] == pytest.approx(arm.C, rel=0.05)
