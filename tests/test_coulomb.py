"""Coulomb friction from ω0/3ω0 pairs (flexarm.identification.frequency_domain.coulomb,
FRB eqs. (2)-(6))."""

from __future__ import annotations

import math

import numpy as np
import pytest

import _frb_sim as sim
from flexarm.identification.frequency_domain.coulomb import (
    PairPhasors,
    estimate_coulomb,
    estimate_pair,
    square_wave_phasor,
)
from flexarm.identification.frequency_domain.harmonics import IdentificationWarning, analyse_log
from flexarm.io.logs import Log, read_log

CF = 0.132  # A
GINV = sim.PAPER_ARM.Gm_inv  # i/θm of the linear part, A/rad


@pytest.mark.parametrize("phi", [0.0, 0.4, 2.0, -2.9])
def test_square_wave_harmonics_and_corrected_phase_of_eq4(phi):
    """sign(θ̇m) for θm = a sin(ω0 t + φ): harmonic n has (4/(nπ)) e^{j(n∠θm + π/2)};
    eq. (4) as printed (∠θm + π/2) is right only when 3∠θm ≡ ∠θm (mod 2π)."""
    w = 1.0
    t = np.linspace(0, 2 * np.pi, 400000, endpoint=False)
    sq = np.sign(np.cos(w * t + phi))
    th1 = np.exp(1j * (phi - np.pi / 2))  # phasor of sin(ωt + φ)
    for n in (1, 3, 5, 7):
        X = 2 * np.mean(sq * np.exp(-1j * n * w * t))
        assert abs(X - square_wave_phasor(th1, n)) < 1e-4, n
        assert abs(abs(X) - 4 / (n * np.pi)) < 1e-4
    X3 = 2 * np.mean(sq * np.exp(-3j * w * t))
    printed = 4 / (3 * np.pi) * np.exp(1j * (np.angle(th1) + np.pi / 2))
    if abs(np.exp(2j * np.angle(th1)) - 1) > 0.1:
        assert abs(X3 - printed) > 0.1


#: the default phasors of _pair: θ1, θ3 and θ'1 of the paper's arm
TH1, TH3, TH1P = 0.3 * np.exp(0.7j), 0.002 * np.exp(1.1j), 0.05 * np.exp(-0.4j)


def _pair(w0, cf=CF, th1=TH1, th3=TH3, th1p=TH1P):
    """The five phasors of eqs. (3)-(5) for the linear part G of the paper's arm."""
    i3 = GINV(3j * w0) * th3 + cf * square_wave_phasor(th1, 3)
    i1p = GINV(3j * w0) * th1p + cf * square_wave_phasor(th1p, 1)
    return PairPhasors(th1, th3, i3, th1p, i1p)


@pytest.mark.parametrize("w0", [1.3, 2.2, 4.3])  # 3·2.2 = 6.6: next to the beam frequency
def test_estimator_exact_on_phasors_of_eqs_3_to_5(w0):
    ph = _pair(w0)
    e = estimate_pair(ph)
    assert e.coulomb_current == pytest.approx(CF, rel=1e-6)
    assert e.cost < 1e-12
    assert abs(e.g_3w0 * GINV(3j * w0) - 1) < 1e-6  # G'(3ω0) from eq. (5) is G(3ω0)
    # the cost (6) is larger away from the solution
    assert ph.cost(1.1 * CF) > 1e-4 and ph.cost(0.9 * CF) > 1e-4


def _analytic_log(w, th1, th3, cf, i_extra=0.0, name="x.csv", t0=0.123, periods=8.3):
    """Time signals made of harmonics 1, 3, 5 built from eqs. (3)-(5), 1 kHz."""
    t = t0 + np.arange(int(periods * 2 * math.pi / w * 1000)) / 1000
    i1 = GINV(1j * w) * th1 + cf * square_wave_phasor(th1, 1)
    i3 = GINV(3j * w) * th3 + cf * square_wave_phasor(th1, 3) + i_extra
    i5 = cf * square_wave_phasor(th1, 5)

    def re(X, n):
        return np.real(X * np.exp(1j * n * w * t))

    sig = {
        "reference": abs(th1) * np.sin(w * t + 0.2),
        "current": 0.01 + re(i1, 1) + re(i3, 3) + re(i5, 5),
        "motor_angle": 0.02 + re(th1, 1) + re(th3, 3),
        "tip_angle": re(th1 * 0.8, 1),
    }
    return Log(path=name, time=t, signals=sig)


def test_estimator_exact_on_analytic_time_signals():
    """Signals built from eqs. (3)-(5), arbitrary time origins, non-integer samples per
    period: harmonic analysis + estimator give C_f to 1e-6."""
    logs = [
        _analytic_log(2.2, 0.3 * np.exp(0.7j), 0.003 * np.exp(1.1j), CF, name="a.csv"),
        _analytic_log(6.6, 0.04 * np.exp(0.3j), 0.0, CF, name="b.csv", t0=1.7),
        _analytic_log(1.3, 0.5 * np.exp(-1.2j), 0.001 * np.exp(2.5j), CF, name="c.csv"),
        _analytic_log(3.9, 0.2 * np.exp(0.9j), 0.0, CF, name="d.csv", t0=0.5),
    ]
    est = estimate_coulomb(
        [analyse_log(lg, held=(), friction_shape="ideal") for lg in logs]
    )  # samples of a continuous current, not a held command
    assert [e.omega for e in est.pairs] == pytest.approx([2.2, 1.3], rel=1e-9)
    assert [e.partner_name for e in est.pairs] == ["b.csv", "d.csv"]
    for e in est.pairs:
        assert e.coulomb_current == pytest.approx(CF, rel=1e-6)
    assert est.coulomb_current == pytest.approx(CF, rel=1e-6)
    assert est.std < 1e-9 and est.max_rel_dev < 1e-6


def test_partner_matching_tolerance_is_one_percent():
    def logs(factor):
        return [
            analyse_log(
                _analytic_log(2.0, 0.3, 0.0, CF, name="base.csv"), held=(), friction_shape="ideal"
            ),
            analyse_log(
                _analytic_log(6.0 * factor, 0.04, 0.0, CF, name="p.csv"),
                held=(),
                friction_shape="ideal",
            ),
        ]

    est = estimate_coulomb(logs(1.009))
    assert len(est.pairs) == 1 and est.pairs[0].partner_omega == pytest.approx(6.054)
    with pytest.warns(IdentificationWarning) as rec:
        est = estimate_coulomb(logs(1.012))
    assert est.pairs == [] and est.coulomb_current is None
    text = " | ".join(str(r.message) for r in rec)
    assert "base.csv: no 3ω0 partner for ω0 = 2 rad/s" in text
    assert "p.csv: no 3ω0 partner" in text and "no ω0/3ω0 pair" in text


def test_missing_partner_warns_naming_frequency_and_continues():
    logs = [
        _analytic_log(2.2, 0.3 * np.exp(0.7j), 0.003 * np.exp(1.1j), CF, name="a.csv"),
        _analytic_log(6.6, 0.04 * np.exp(0.3j), 0.0, CF, name="b.csv", t0=1.7),
        _analytic_log(5.0, 0.1 * np.exp(0.1j), 0.0, CF, name="lonely.csv"),
    ]
    with pytest.warns(IdentificationWarning) as rec:
        est = estimate_coulomb([analyse_log(lg, held=(), friction_shape="ideal") for lg in logs])
    msgs = [str(r.message) for r in rec]
    assert len(msgs) == 1  # the 6.6 rad/s log is a partner, it needs none itself
    assert "lonely.csv" in msgs[0] and "ω0 = 5 rad/s" in msgs[0] and "15 rad/s" in msgs[0]
    assert est.unpaired == ["lonely.csv"]
    assert est.coulomb_current == pytest.approx(CF, rel=1e-6)


@pytest.fixture(scope="module")
def paper_analyses(tmp_path_factory):
    folder = sim.experiment_dir(tmp_path_factory, "paper")
    return [analyse_log(read_log(p)) for p in sorted(folder.glob("*.csv"))]


def test_coulomb_recovered_from_simulated_paper_arm(paper_analyses):
    """Independent simulation (tanh friction, PD loop, beam): C_f = 0.132 A within 10 %."""
    est = estimate_coulomb(paper_analyses)
    assert len(est.pairs) == len(sim.PAPER_PAIRS)
    assert est.coulomb_current == pytest.approx(0.132, rel=0.10)
    for e in est.pairs:
        assert e.coulomb_current == pytest.approx(0.132, rel=0.10)
    assert est.std < 0.05 * est.coulomb_current
    assert est.max_rel_dev < 0.10


def test_cost_is_finite_where_cf_prime_vanishes():
    """A pair without third-harmonic response (θm and i at 3ω0 both zero) has C_f' = 0
    for every trial C_f: eq. (6) is ln 0 there. The search gets a finite cost (so Brent's
    parabolic steps stay defined), ends at the bound of its grid and says so."""
    ph = PairPhasors(
        theta1=0.1 + 0j, theta3=0j, current3=0j, theta1_partner=0.05 + 0j, current1_partner=0.2 + 0j
    )
    assert ph.cf_prime(0.1) == 0
    assert math.isfinite(ph.cost(0.1)) and ph.cost(0.1) > 1e5
    e = estimate_pair(ph)
    assert math.isfinite(e.cost) and e.at_search_bound
