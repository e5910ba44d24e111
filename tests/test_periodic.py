"""Excitation design (flexarm.identification.frequency_domain.excitation) and the periodic FRF /
distortion analysis
(flexarm.identification.frequency_domain.periodic) on signals whose answer is known exactly."""

import warnings

import numpy as np
import pytest

from flexarm.identification.frequency_domain.excitation import (
    ExcitationError,
    crest_factor,
    multisine,
    prbs,
    sine_pairs,
    swept_sine,
    write_excitation,
)
from flexarm.identification.frequency_domain.harmonics import IdentificationError
from flexarm.identification.frequency_domain.periodic import detect_period, periodic_frf

FS, P = 1000.0, 500


def G(f):
    """A known lightly damped system (a resonance at 60 Hz, a zero at 40 Hz)."""
    s = 2j * np.pi * f
    w1, w2 = 2 * np.pi * 40, 2 * np.pi * 60
    return (s**2 + 0.1 * w1 * s + w1**2) / (s**2 + 0.05 * w2 * s + w2**2) / w1**2 * w2**2


def steady_output(u, period, H):
    """Exact periodic steady state of y = H u: multiply one period's DFT by H on the grid."""
    U = np.fft.rfft(u[:period])
    f = np.arange(len(U)) * FS / period
    return np.tile(np.fft.irfft(U * H(np.maximum(f, 1e-9)), period), len(u) // period)


def test_multisine_kinds_lines_and_crest():
    e = multisine(P, FS, 10, 200, kind="random-odd", rms=2.0, periods=3, seed=1)
    assert np.all(e.excited % 2 == 1)
    assert np.any(e.detection % 2 == 1) and np.any(e.detection % 2 == 0)
    np.testing.assert_allclose(np.sqrt(np.mean(e.signal**2)), 2.0, rtol=1e-12)
    U = np.abs(np.fft.rfft(e.signal[0, :P]))
    assert set(np.nonzero(U > 1e-9 * U.max())[0]) == set(e.excited)  # exactly the design
    f = multisine(P, FS, 10, 200, kind="full", phases="schroeder")
    assert len(f.excited) == 96  # 10–200 Hz on a 2 Hz grid and len(f.detection) == 0
    r = multisine(P, FS, 10, 200, kind="full", phases="random", seed=3)
    m = multisine(P, FS, 10, 200, kind="full", phases="min-crest", seed=3)
    # clipping starts from the same random phases and keeps the best: never worse
    assert m.crest_factor < r.crest_factor and m.crest_factor < 2.0
    lg = multisine(P, FS, 2, 400, kind="full", grid="log", n_lines=20)
    assert len(lg.excited) <= 20 and np.all(np.diff(np.log(lg.excited_hz)) > 0)
    with pytest.raises(ExcitationError, match="kind='bad'"):
        multisine(P, FS, 10, 200, kind="bad")
    with pytest.raises(ExcitationError, match="Nyquist"):
        multisine(P, FS, 10, 900)


def test_prbs_sweep_pairs_and_writer(tmp_path):
    p = prbs(7, FS, amplitude=0.5, periods=2)
    assert p.period == 127 and crest_factor(p.signal) == pytest.approx(1.0)
    s = swept_sine(P, FS, 5, 100, periods=2)
    assert s.signal.shape == (1, 2 * P)
    assert sine_pairs([2.0]) == [(2.0, 6.0)]
    e = multisine(P, FS, 10, 50, kind="random-odd", periods=2)
    log, lines = write_excitation(tmp_path / "ms.csv", e)
    assert "crest_factor" in log.read_text() and lines.read_text().count("excited") == len(
        e.excited
    )
    with pytest.raises(FileExistsError):
        write_excitation(tmp_path / "ms.csv", e)


def test_frf_exact_noise_free_and_period_detection():
    e = multisine(P, FS, 5, 200, kind="random-odd", periods=6, seed=2)
    u = e.signal[0]
    y = steady_output(u, P, G)
    assert detect_period(u) == P
    r = periodic_frf(u, {"y": y}, FS)
    assert r.period == P and r.transient_periods == 0 and list(r.lines) == list(e.excited)
    # DFT on the exact grid: the only error is rounding (1e-10 of |G|)
    np.testing.assert_allclose(r.response[0], G(e.excited_hz), rtol=1e-9)
    assert np.all(r.noise_std < 1e-9)


def test_frf_noise_std_matches_monte_carlo():
    """The std from the sample variances over periods agrees with the spread over 200
    independent noisy records: ratio within 15 % (the estimated var has ~M−1 = 7 degrees of
    freedom per line, averaged over 40 lines and 200 runs → a few % spread)."""
    e = multisine(P, FS, 5, 200, kind="odd", periods=8, seed=4)
    u0 = e.signal[0]
    y0 = steady_output(u0, P, G)
    rng = np.random.default_rng(5)
    Gs, stds = [], []
    for _ in range(200):
        u = u0 + 0.05 * rng.standard_normal(u0.size)
        y = y0 + 0.05 * rng.standard_normal(u0.size)
        r = periodic_frf(u, {"y": y}, FS, period=P, transient_periods=0, lines=e.excited)
        Gs.append(r.response[0])
        stds.append(r.noise_std[0])
    mc = np.std(np.array(Gs), axis=0)
    ratio = np.mean(np.array(stds), axis=0) / mc
    assert 0.85 < np.median(ratio) < 1.15


def test_distortion_from_cubic_and_transient_and_partial_period():
    e = multisine(P, FS, 5, 150, kind="random-odd", periods=6, seed=7)
    u = e.signal[0]
    ylin = steady_output(u, P, G)
    rng = np.random.default_rng(0)
    noise = 1e-4 * rng.standard_normal(u.size)
    lin = periodic_frf(u, {"y": ylin + noise}, FS, period=P)
    odd = periodic_frf(u, {"y": ylin + 0.05 * ylin**3 + noise}, FS, period=P)
    even = periodic_frf(u, {"y": ylin + 0.05 * ylin**2 + noise}, FS, period=P)
    b_lin, b_odd, b_even = (
        np.array([[b.odd_db, b.even_db, b.noise_db] for b in r.distortion["y"]])
        for r in (lin, odd, even)
    )
    # bands without odd (or even) detection lines hold NaN: compared with nanmax / nanmin
    assert np.nanmax(b_lin[:, :2] - b_lin[:, 2:]) < 6 and "no distortion" in lin.verdict()
    assert np.nanmin(b_odd[:, 0] - b_odd[:, 2]) > 20 and "symmetric" in odd.verdict()
    assert np.nanmin(b_even[:, 1] - b_even[:, 2]) > 20 and "asymmetric" in even.verdict()
    assert np.nanmax(b_even[:, 0] - b_even[:, 2]) < 6  # a square puts nothing on odd lines
    assert np.all(odd.total_std > 3 * odd.noise_std)
    # a transient first period and a trailing partial period
    yt = ylin.copy()
    yt[:P] += np.exp(-np.arange(P) / 50.0)
    with pytest.warns(UserWarning, match="100 trailing sample"):
        r = periodic_frf(
            np.r_[u, u[:100]], {"y": np.r_[yt, yt[:100]] + np.r_[noise, noise[:100]]}, FS
        )
    assert r.transient_periods == 1 and r.periods_used == 5


def test_bad_input_errors():
    e = multisine(P, FS, 5, 200, kind="full", periods=3)
    u = e.signal[0]
    y = steady_output(u, P, G)
    with pytest.raises(IdentificationError, match="at least two whole periods"):
        periodic_frf(u[: P + 10], {"y": y[: P + 10]}, FS, period=P, source="rec.mat")
    with pytest.raises(IdentificationError, match="period of 317 samples does not fit"):
        periodic_frf(u, {"y": y}, FS, period=317, lines=e.excited[:50] // 2 + 1)
    with pytest.raises(IdentificationError, match="no detection lines"):
        periodic_frf(u, {"y": y}, FS, period=P, require_distortion=True)
    yn = y.copy()
    yn[7] = np.nan
    with pytest.raises(IdentificationError, match="'y' has 1 NaN.*sample 7"):
        periodic_frf(u, {"y": yn}, FS)
    with pytest.raises(IdentificationError, match="different lengths: input 1500, y 1499"):
        periodic_frf(u, {"y": y[:-1]}, FS)


def test_robust_bla_over_realisations():
    """R = 6 random-phase realisations of y = G u (+ a cubic term) with white output noise
    of known std: the robust BLA (combine_realisations) is the true FRF within its noise
    std (rms z ~ 1, measured 1.07; bound 1.5), its total variance equals the noise variance
    without nonlinearity (mean ratio over 48 lines, measured 1.18: per line the spread
    estimate has 2(R−1) = 10 real dof (relative std 0.45) and the noise estimate 36
    (0.24, and a bias 36/34), so the mean over 48 lines is 1.06 ± 0.07 → bound ±0.35), and
    exceeds it several-fold with the cubic term (the stochastic nonlinear part changes
    with the phases)."""
    from flexarm.identification.frequency_domain.periodic import combine_realisations

    rng = np.random.default_rng(5)

    def runs(cubic):
        out = []
        for r in range(6):
            e = multisine(P, FS, 10, 200, kind="odd", rms=1.0, periods=4, seed=10 + r)
            u = e.signal[0]
            y = steady_output(u, P, G)
            y = y + cubic * y**3 + 0.01 * rng.standard_normal(len(y))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out.append(periodic_frf(u, {"y": y}, FS, period=P, transient_periods=0))
        return out

    lin = combine_realisations(runs(0.0))
    z = np.abs(lin.response[0] - G(lin.frequency_hz)) / lin.noise_std[0]
    assert np.sqrt(np.mean(z**2)) < 1.5
    ratio = np.mean(lin.total_std[0] ** 2 / lin.noise_std[0] ** 2)
    assert abs(ratio - 1) < 0.35, ratio
    nl = combine_realisations(runs(0.3))
    assert np.mean(nl.total_std[0] ** 2 / nl.noise_std[0] ** 2) > 4
    assert "BLA over 6 realisations" in nl.warnings[-1]
    with pytest.raises(IdentificationError, match="at least two realisations"):
        combine_realisations(runs(0.0)[:1])
    other = multisine(P, FS, 10, 150, kind="odd", rms=1.0, periods=3, seed=1).signal[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        odd = periodic_frf(other, {"y": steady_output(other, P, G)}, FS, period=P)
    with pytest.raises(IdentificationError, match="realisation 2 differs"):
        combine_realisations([lin, odd])


def test_cli_frf_several_realisations(tmp_path):
    """`flexarm frf A.csv B.csv C.csv`: one realisation per file, the robust BLA in the JSON:
    the linear system's FRF within its noise std (z = error/noise_std; the noise std comes
    from 3 × 3 period differences, 18 real dof, so E z² = 18/16: rms ≈ 1.06; bound 1.5),
    and a total std from the realisations' spread at every line."""
    import json

    from typer.testing import CliRunner

    from flexarm.cli import app
    from flexarm.io.logs import write_log

    rng = np.random.default_rng(2)
    files = []
    for r in range(3):
        e = multisine(P, FS, 10, 200, kind="odd", rms=1.0, periods=4, seed=20 + r)
        u = e.signal[0]
        y = steady_output(u, P, G) + 0.01 * rng.standard_normal(len(u))
        f = tmp_path / f"r{r}.csv"
        write_log(f, np.arange(len(u)) / FS, {"current": u, "motor_angle": y}, required=("time",))
        files.append(str(f))
    out = tmp_path / "frf.json"
    res = CliRunner().invoke(
        app,
        [
            "frf",
            *files,
            "--input",
            "current",
            "--output",
            "motor_angle",
            "--period",
            str(P),
            "--json",
            str(out),
        ],
    )
    assert res.exit_code == 0, res.output
    d = json.loads(out.read_text())
    assert d["realisations"] == 3 and d["source"] == files
    # a non-periodic record (white noise through a known discrete filter, from rest): the
    # LPM through the CLI, with its figure
    import scipy.signal

    bb, aa = scipy.signal.cheby1(4, 1, 0.2)
    un = rng.standard_normal(8000)
    yn = scipy.signal.lfilter(bb, aa, un) + 0.01 * rng.standard_normal(un.size)
    write_log(
        tmp_path / "noise.csv",
        np.arange(un.size) / FS,
        {"current": un, "motor_angle": yn},
        required=("time",),
    )
    res2 = CliRunner().invoke(
        app,
        [
            "frf",
            str(tmp_path / "noise.csv"),
            "--input",
            "current",
            "--output",
            "motor_angle",
            "--method",
            "lpm",
            "--json",
            str(tmp_path / "lpm.json"),
            "--plots",
            str(tmp_path / "p"),
        ],
    )
    assert res2.exit_code == 0, res2.output
    d2 = json.loads((tmp_path / "lpm.json").read_text())
    G2 = np.asarray(d2["outputs"]["motor_angle"]["re"]) + 1j * np.asarray(
        d2["outputs"]["motor_angle"]["im"]
    )
    _, Gt = scipy.signal.freqz(bb, aa, worN=2 * np.pi * np.asarray(d2["frequency_hz"]) / FS)
    z2 = np.abs(G2 - Gt) / np.asarray(d2["outputs"]["motor_angle"]["noise_std"])
    assert np.sqrt(np.mean(z2**2)) < 1.6  # as in the LPM test: rms ≈ 1.12
    assert (tmp_path / "p" / "frf-distortion.png").stat().st_size > 10000
    # closed loop through the CLI: the reference column named, the indirect estimate
    bb, aa = scipy.signal.cheby1(2, 1, 0.2)  # the stable loop of the closed-loop LPM test
    kk = 2.0
    den = np.polyadd(aa, kk * bb)
    rr, vv = rng.standard_normal(8000), 0.3 * rng.standard_normal(8000)
    ycl = scipy.signal.lfilter(kk * bb, den, rr) + scipy.signal.lfilter(aa, den, vv)
    ucl = scipy.signal.lfilter(kk * aa, den, rr) - scipy.signal.lfilter(kk * aa, den, vv)
    write_log(
        tmp_path / "cl.csv",
        np.arange(rr.size) / FS,
        {"current": ucl, "motor_angle": ycl, "reference": rr},
        required=("time",),
    )
    res3 = CliRunner().invoke(
        app,
        [
            "frf",
            str(tmp_path / "cl.csv"),
            "--method",
            "lpm",
            "--input",
            "current",
            "--output",
            "motor_angle",
            "--reference",
            "reference",
            "--json",
            str(tmp_path / "cl.json"),
        ],
    )
    assert res3.exit_code == 0, res3.output
    d3 = json.loads((tmp_path / "cl.json").read_text())
    assert "indirect through the reference" in d3["warnings"][-1]
    o3 = d3["outputs"]["motor_angle"]
    _, Pt = scipy.signal.freqz(bb, aa, worN=2 * np.pi * np.asarray(d3["frequency_hz"]) / FS)
    z3 = np.abs(np.asarray(o3["re"]) + 1j * np.asarray(o3["im"]) - Pt) / np.asarray(o3["noise_std"])
    assert np.sqrt(np.mean(z3**2)) < 1.7  # as in the closed-loop LPM test
    o = d["outputs"]["motor_angle"]
    Gh = np.asarray(o["re"]) + 1j * np.asarray(o["im"])
    z = np.abs(Gh - G(np.asarray(d["frequency_hz"]))) / np.asarray(o["noise_std"])
    assert np.sqrt(np.mean(z**2)) < 1.5
    assert len(o["total_std"]) == len(Gh) and np.all(np.asarray(o["total_std"]) > 0)


def test_local_polynomial_method_on_a_transient_record():
    """A non-periodic record: white-noise input from rest through a known discrete system
    (scipy lfilter, so the truth is freqz exactly), output noise σ = 0.01. The LPM FRF is
    the truth within its own std: z = |Ĝ − G|/std has E z² = q/(q−1) = 5/4 for q = 5
    complex dof (rms 1.12; measured 1.08) → band [0.7, 1.6] over 400 lines; the plain
    ratio Y/U of the whole record (leakage and transient) is several times worse
    (measured 7.0 × the LPM's rms error)."""
    import scipy.signal

    from flexarm.identification.frequency_domain.periodic import lpm_frf

    rng = np.random.default_rng(8)
    b, a = scipy.signal.cheby1(4, 1, 0.2)  # 4th order, 1 dB ripple, edge at 0.1 fs
    u = rng.standard_normal(20000)
    y = scipy.signal.lfilter(b, a, u) + 0.01 * rng.standard_normal(u.size)
    res = lpm_frf(u, {"y": y}, FS, f_max=150, max_lines=400)
    _, Gt = scipy.signal.freqz(b, a, worN=2 * np.pi * res.frequency_hz / FS)
    z = np.abs(res.response[0] - Gt) / res.noise_std[0]
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.6, np.sqrt(np.mean(z**2))
    U, Y = np.fft.rfft(u), np.fft.rfft(y)
    plain = Y[res.lines] / U[res.lines]
    assert np.sqrt(np.mean(np.abs(plain - Gt) ** 2)) > 3 * np.sqrt(
        np.mean(np.abs(res.response[0] - Gt) ** 2)
    )
    with pytest.raises(IdentificationError, match="degrees of freedom"):
        lpm_frf(u, {"y": y}, FS, order=2, half_width=2)
    # a periodic random-odd multisine of 4 periods: its record DFT is zero off every 4th
    # line, so no window is rank-sufficient; the error says to use the periodic method
    e = multisine(P, FS, 10, 200, kind="random-odd", rms=1.0, periods=4, seed=1)
    with pytest.raises(IdentificationError, match="use the periodic method"):
        lpm_frf(e.signal[0], {"y": steady_output(e.signal[0], P, G)}, FS)


def test_lpm_closed_loop_through_the_reference():
    """A plant P(z) in a loop u = k (r − y), y = P u + v, white reference r and output
    noise v (std 0.3): u carries −k S v, so the direct LPM (u as regressor) is biased
    towards −1/k; the indirect one (r as regressor, G = G_yr/G_ur) is not. Per line the
    indirect estimate is P within its first-order std (z-rms ≈ 1.1 for q = 5 dof; band
    [0.6, 1.7]). The bias shows in the mean complex error over the L = 1600 lines (every 4th) of the
    passband (≤ 80 Hz), whose random part has std ≈ rms(std)·√(3/L) (neighbouring windows
    share lines: ~L/3 independent): the indirect mean error is within 3 of those, the
    direct one beyond 5 (measured: z-rms 1.16; mean errors 0.77 and 9.4 of them)."""
    import scipy.signal

    from flexarm.identification.frequency_domain.periodic import lpm_frf

    b, a = scipy.signal.cheby1(2, 1, 0.2)
    k = 2.0
    den = np.polyadd(a, k * b)
    assert np.all(np.abs(np.roots(den)) < 1)  # a stable loop
    rng = np.random.default_rng(3)
    N = 80000
    r = rng.standard_normal(N)
    v = 0.3 * rng.standard_normal(N)
    y = scipy.signal.lfilter(k * b, den, r) + scipy.signal.lfilter(a, den, v)
    u = scipy.signal.lfilter(k * a, den, r) - scipy.signal.lfilter(k * a, den, v)
    ind = lpm_frf(u, {"y": y}, FS, reference=r, f_max=80, max_lines=1600)
    _, Pt = scipy.signal.freqz(b, a, worN=2 * np.pi * ind.frequency_hz / FS)
    z = np.abs(ind.response[0] - Pt) / ind.noise_std[0]
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.7, np.sqrt(np.mean(z**2))
    assert "indirect through the reference" in ind.warnings[-1]
    L = len(Pt)
    s_mean = np.sqrt(np.mean(ind.noise_std[0] ** 2)) * np.sqrt(3 / L)
    bias_ind = abs(np.mean(ind.response[0] - Pt))
    assert bias_ind < 3 * s_mean, (bias_ind, s_mean)
    direct = lpm_frf(u, {"y": y}, FS, f_max=80, max_lines=1600)
    bias_dir = abs(np.mean(direct.response[0] - Pt))
    assert bias_dir > 5 * s_mean, (bias_dir, s_mean)
