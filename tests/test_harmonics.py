"""Harmonic analysis (flexarm.identification.frequency_domain.harmonics) on analytic signals."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from flexarm.identification.frequency_domain.harmonics import (
    IdentificationError,
    IdentificationWarning,
    analyse_log,
    estimate_frequency,
    fourier_phasors,
    saturation_level,
    whole_periods,
)
from flexarm.io.logs import Log, read_log, write_log

W0 = 2.345678  # rad/s: 2678.6... samples per period at 1 kHz, not a whole number
PHASORS = {
    0: 0.03,
    1: 0.7 * np.exp(0.4j),
    2: 0.01j,
    3: 0.05 * np.exp(-2.1j),
    5: 0.02 * np.exp(1.3j),
}


def _signal(t, w, ph):
    return sum(
        (np.real(X * np.exp(1j * n * w * t)) if n else np.real(X) * np.ones_like(t))
        for n, X in ph.items()
    )


def _log(t0=0.37, periods=6.4, w=W0, rate=1000.0, path=None, current=None):
    t = t0 + np.arange(int(periods * 2 * math.pi / w * rate)) / rate
    sig = {
        "reference": 0.5 * np.sin(w * t + 0.3),
        "current": _signal(t, w, PHASORS),
        "motor_angle": 0.2 * np.sin(w * t),
        "tip_angle": 0.1 * np.cos(w * t),
    }
    if current is not None:
        sig["current"] = current(t)
    return Log(path=path, time=t, signals=sig)


def test_frequency_exact_on_sinusoid():
    log = _log()
    assert estimate_frequency(log.time, log["reference"]) == pytest.approx(W0, rel=1e-10)
    # with an offset and 1 % white noise
    noisy = 0.2 + log["reference"] + 0.005 * np.random.default_rng(1).standard_normal(len(log))
    assert estimate_frequency(log.time, noisy) == pytest.approx(W0, rel=1e-5)


def test_phasors_exact_on_analytic_signal():
    log = _log()
    a = analyse_log(log, n_max=5, held=())  # analytic continuous signals
    assert a.omega0 == pytest.approx(W0, rel=1e-10)
    for n, X in PHASORS.items():
        assert abs(a.phasor("current", n) - X) < 1e-9, n
    assert abs(a.phasor("current", 4)) < 1e-9
    # convention x(t) = Re{X e^{jωt}} with the log's own time origin
    assert abs(a.phasor("motor_angle") - 0.2 * np.exp(-0.5j * np.pi)) < 1e-9
    assert abs(a.phasor("tip_angle") - 0.1) < 1e-9
    assert abs(a.phasor("reference") - 0.5 * np.exp(1j * (0.3 - np.pi / 2))) < 1e-9


def test_window_is_last_whole_periods():
    log = _log(periods=6.4)
    start, stop, N = whole_periods(log.time, W0, discard_periods=1.0)
    T = 2 * math.pi / W0
    assert N == 5 and stop == len(log)
    assert (stop - start) * log.dt == pytest.approx(N * T, abs=log.dt / 2)
    # a record of 2.5 periods: the discard is given up rather than fall below two
    short = _log(periods=2.5)
    assert whole_periods(short.time, W0, discard_periods=1.0)[2] == 2


def test_fourier_phasors_of_several_signals():
    t = np.arange(5000) * 1e-3
    X = fourier_phasors(t, np.stack([np.cos(3 * t), np.sin(3 * t)]), 3.0, 2)
    np.testing.assert_allclose(X[:, 1], [1, -1j], atol=1e-12)


def test_fewer_than_two_periods_is_an_error_naming_the_file(tmp_path):
    log = _log(periods=1.8)
    p = write_log(tmp_path / "short_record.csv", log.time, log.signals)
    with pytest.raises(IdentificationError) as e:
        analyse_log(read_log(p))
    msg = str(e.value)
    assert str(p) in msg and "fewer than two whole periods" in msg and "1.8" in msg


def test_constant_reference_is_an_error(tmp_path):
    log = _log()
    log.signals["reference"] = np.zeros(len(log))
    log.path = tmp_path / "flat_reference.csv"
    with pytest.raises(
        IdentificationError,
        match=r"flat_reference\.csv: the reference is "
        r"constant",
    ):
        analyse_log(log)


def test_saturated_current_warns_with_file_and_level(tmp_path):
    clipped = _log(current=lambda t: np.clip(3.0 * np.sin(W0 * t), -2.5, 2.5))
    p = write_log(tmp_path / "saturated.csv", clipped.time, clipped.signals)
    with pytest.warns(IdentificationWarning) as rec:
        a = analyse_log(read_log(p))
    msg = str(rec[0].message)
    assert str(p) in msg and "saturated" in msg and "±2.5 A" in msg
    assert a.saturation == pytest.approx(2.5)
    assert a.warnings == [msg]
    # an unclipped sinusoid (and a quantised one) does not warn
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert analyse_log(_log()).saturation is None
    q = np.round(2048 * np.sin(W0 * clipped.time)) / 2048
    assert saturation_level(q) is None


def test_held_command_phasor_is_that_of_the_zoh_signal():
    """A logged command is held from one sample to the next: its corrected phasor equals
    the Fourier coefficient of the held (staircase) signal, integrated on a fine grid."""
    from flexarm.identification.frequency_domain.harmonics import fourier_phasors, zoh_factor

    T, w, n = 0.003, 23.0, 6000
    t = np.arange(n) * T
    x = np.cos(w * t + 0.3)
    stop = int(np.floor(n * T * w / (2 * np.pi)) * 2 * np.pi / w / T)
    sampled = fourier_phasors(t, x, w, 1, window=(0, stop))[1] * zoh_factor(w, T)
    sub = 200  # exact staircase on a fine grid
    tf = (np.arange(stop * sub) + 0.5) * (T / sub)
    xs = np.repeat(x[:stop], sub)
    span = stop * T
    exact = 2 / span * np.sum(xs * np.exp(-1j * w * tf)) * (T / sub)
    assert abs(sampled - exact) < 2e-3 * abs(exact)  # window not whole periods of the fine grid
    assert abs(np.angle(sampled / x[0]) - np.angle(exact / x[0])) < 2e-3
    assert abs(np.angle(zoh_factor(w, T))) == pytest.approx(w * T / 2, rel=1e-12)


def test_measured_friction_shape():
    """sign(θ̇m) rebuilt from θm's harmonics: for a pure sinusoid it is eq. (2)'s square
    wave, 4/(nπ) e^{j(n∠θ1 + π/2)}; a third harmonic in θm shifts its zero crossings and
    with them the friction's fundamental."""
    from flexarm.identification.frequency_domain.harmonics import (
        ideal_friction_phasor,
        measured_friction_shape,
    )

    w, T = 3.0, 1e-4
    t = np.arange(int(20 * 2 * np.pi / w / T)) * T  # whole periods up to one sample
    X = np.zeros(6, complex)
    X[1] = 0.8 * np.exp(0.4j)
    S = measured_friction_shape(t, X, w, 5)
    for n in (1, 3, 5):
        assert abs(S[n] - ideal_friction_phasor(X[1], n)) < 2e-3 * abs(
            ideal_friction_phasor(X[1], n)
        )
    assert abs(S[2]) < 1e-3
    X[3] = 0.05 * np.exp(1.0j)
    S3 = measured_friction_shape(t, X, w, 5)
    assert abs(np.angle(S3[1] / S[1])) > 0.01
