"""Sensor low-pass filter (``[sensors.<signal>] bandwidth``): the analog first-order filter
in front of the A/D against its analytic responses, in a closed loop, and bad input."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
from pydantic import ValidationError
from scipy import signal as sps

from flexarm.control import discrete
from flexarm.models.plant import Plant
from flexarm.sim.build import prepare
from flexarm.sim.rig_loop import as_jax, closed_loop_run
from flexarm.sim.sampled import Actuator, SampledLoop, Sensors, simulate_loop
from flexarm.specs import load_scenario
from flexarm.specs.experiment import Sensor

T, SUB = 1e-3, 10


class Oscillator(Plant):
    """ṗ = v, v̇ = −w² p: with p(0) = 0, v(0) = w its signal is sin(w t)."""

    w: float

    def rhs(self, x, u):
        return jnp.stack([x[1], -(self.w**2) * x[0]])

    def signals(self, x, u):
        return x[:1]


class Ramp(Plant):
    """ṗ = 1: its signal is t."""

    def rhs(self, x, u):
        return jnp.ones((1,))

    def signals(self, x, u):
        return x[:1]


def _open_loop(plant, fc, n, x0, **sensor):
    sens = Sensors.make(plant, {"s": {"bandwidth": fc, **sensor}})
    ctrl = discrete.from_transfer_function(([0.0], [1.0]), T, measured="s")
    loop = SampledLoop(
        plant, ctrl, sens, Actuator(jnp.asarray([1.0]), jnp.asarray([0.0])), jnp.asarray(T), SUB
    )
    return simulate_loop(loop, np.asarray(x0), {}, n)


def test_sine_gain_and_phase_are_the_first_order_filters():
    """A 5 Hz sine through a 10 Hz filter: gain 1/√(1 + (f/f_c)²) = 0.894427, phase
    −atan(f/f_c) = −26.565°, from a least-squares fit of a sin + b cos over whole periods
    after the start transient (e^(−2π f_c t) < 1e-27 at t = 1 s). Tolerance 1e-9: RK4 at
    ω h <= 6.3e-3 errs by ~(ω h)^4/120 ~ 1e-11 per substep; a filter driven by the held
    samples instead (ZOH-discretised) would lag by half a sample, π f T = 0.016 rad."""
    f, fc = 5.0, 10.0
    n = 4001
    w = 2 * np.pi * f
    out = _open_loop(Oscillator(("p", "v"), ("s",), ("u",), w), fc, n, [0.0, w])
    t = np.arange(n) * T
    keep = t >= 1.0 - 1e-12  # 3 s: 15 whole periods
    A = np.stack([np.sin(w * t[keep]), np.cos(w * t[keep])], 1)
    a, b = np.linalg.lstsq(A, out["measured"][keep, 0], rcond=None)[0]
    gain, phase = math.hypot(a, b), math.atan2(b, a)
    print(
        f"gain {gain:.12f} (analytic {1 / math.sqrt(1 + (f / fc) ** 2):.12f}), "
        f"phase {math.degrees(phase):.9f} deg (analytic {-math.degrees(math.atan(f / fc)):.9f})"
    )
    assert gain == pytest.approx(1 / math.sqrt(1 + (f / fc) ** 2), abs=1e-9)
    assert phase == pytest.approx(-math.atan(f / fc), abs=1e-9)
    # the unfiltered channel is the sine itself
    raw = _open_loop(Oscillator(("p", "v"), ("s",), ("u",), w), 0.0, n, [0.0, w])
    np.testing.assert_allclose(raw["measured"][:, 0], np.sin(w * t), atol=1e-9)


def test_ramp_lags_by_the_time_constant():
    """A ramp s = t through a filter of 20 Hz lags by τ = 1/(2π f_c) = 7.9577 ms once the
    start transient has died (t > 30 τ; y(0) = s(0) = 0, so y = t − τ(1 − e^(−t/τ))).
    RK4 reproduces the linear particular solution t − τ exactly (its local error is in the
    5th derivative), so only the transient term e^(−t/τ) and rounding remain: 1e-12 s."""
    fc = 20.0
    tau = 1 / (2 * np.pi * fc)
    n = 1001
    out = _open_loop(Ramp(("p",), ("s",), ("u",)), fc, n, [0.0])
    t = np.arange(n) * T
    y = out["measured"][:, 0]
    assert y[0] == 0.0
    np.testing.assert_allclose(y, t - tau * (1 - np.exp(-t / tau)), atol=1e-12)
    lag = (t - y)[t > 30 * tau]
    print(f"ramp lag {lag.mean():.15f} s, analytic tau {tau:.15f} s")
    np.testing.assert_allclose(lag, tau, atol=1e-12)


def test_noise_is_added_after_the_filter_and_quantised():
    """Gain, noise, quantisation with a filter: measured = q(y_f + σ n); the noise keeps its
    per-sample standard deviation (not σ·√(ω_f T/2), which filtering it would give)."""
    fc, n = 20.0, 1001
    plant = Ramp(("p",), ("s",), ("u",))
    clean = _open_loop(plant, fc, n, [0.0], gain=2.0)
    noisy = _open_loop(plant, fc, n, [0.0], gain=2.0, noise=1e-3)
    t = np.arange(n) * T
    tau = 1 / (2 * np.pi * fc)
    np.testing.assert_allclose(
        clean["measured"][:, 0], 2 * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12
    )
    sd = np.std(noisy["measured"][:, 0] - clean["measured"][:, 0])
    assert sd == pytest.approx(1e-3, rel=0.1)  # 1001 samples: sd of the sd estimate 2.2 %
    q = 2.0 / 2**8
    quant = _open_loop(plant, fc, n, [0.0], gain=2.0, bits=8, range=2.0)
    np.testing.assert_array_equal(
        quant["measured"][:, 0], np.round(clean["measured"][:, 0] / q) * q
    )


def _rotary(duration=2.0, period=None, **tip):
    sc = load_scenario("rotary-flexible-link")
    sensors = {
        k: v.model_copy(update={"noise": 0.0, **(tip if k == "tip_deflection" else {})})
        for k, v in sc.sensors.items()
    }
    sampling = sc.sampling.model_copy(update={"period": period or sc.sampling.period})
    return sc.model_copy(
        update={
            "sensors": sensors,
            "sampling": sampling,
            "simulation": sc.simulation.model_copy(update={"duration": duration}),
        }
    )


def test_closed_loop_with_a_filtered_tip_sensor():
    """The rotary flexible link under state feedback on the tip deflection, strain gauge
    filtered at 30 Hz (analog, then the 2-sample delay): the measured tip is the filter's
    response to the true deflection, computed by scipy's lsim from the recorded samples
    linearly interpolated. That interpolation is lsim's error, O(T²) (largest after the
    reference steps, where the command jump kinks the tip's velocity): measured 7.9e-5 of
    the swing at T = 1 ms and 2.0e-5 at 0.5 ms, ratio 3.99. The test asserts < 2e-4 and
    the ratio 4 ± 0.5: a filter lagging by a fraction of a sample (e.g. driven by the held
    samples) would leave an O(T) error, ratio 2. And the filter's lag changes the loop:
    the hub trajectory moves by 0.83 % of its swing (measured), asserted > 0.1 %, far
    above the integration's own error (~1e-10 rad, the RK4 substep)."""
    fc = 30.0
    wf = 2 * np.pi * fc
    errs = []
    for period in (1e-3, 5e-4):
        p = prepare(_rotary(period=period, bandwidth=fc))
        b = simulate_loop(p.loop, p.x0, p.references, p.n_samples)
        tip = p.loop.plant.signal_names.index("tip_deflection")
        d = p.scenario.sensors["tip_deflection"].delay
        true_tip = b["signals"][:, tip]
        _, yf, _ = sps.lsim(
            ([[-wf]], [[wf]], [[1.0]], [[0.0]]), true_tip, p.time, X0=[true_tip[0]], interp=True
        )
        meas = b["measured"][:, p.loop.sensors.names.index("tip_deflection")]
        errs.append(np.max(np.abs(meas[d:] - yf[:-d])) / np.ptp(true_tip))
        if period == 1e-3:
            filtered = b
    print(
        f"filtered tip vs lsim: {errs[0]:.3e} (T = 1 ms), {errs[1]:.3e} (0.5 ms) of the "
        f"swing, ratio {errs[0] / errs[1]:.3f}"
    )
    assert errs[0] < 2e-4
    assert 3.5 < errs[0] / errs[1] < 4.5
    ref = prepare(_rotary())
    a = simulate_loop(ref.loop, ref.x0, ref.references, ref.n_samples)
    hub = ref.loop.plant.signal_names.index("motor_angle")
    diff = np.max(np.abs(a["signals"][:, hub] - filtered["signals"][:, hub])) / np.ptp(
        a["signals"][:, hub]
    )
    print(f"hub angle, filtered vs unfiltered tip sensor: max diff {diff:.3%} of the swing")
    assert diff > 1e-3


def test_bandwidth_zero_is_the_unfiltered_loop_exactly():
    p0 = prepare(_rotary(duration=0.5))
    p1 = prepare(_rotary(duration=0.5, bandwidth=0.0))
    a = simulate_loop(p0.loop, p0.x0, p0.references, p0.n_samples)
    b = simulate_loop(p1.loop, p1.x0, p1.references, p1.n_samples)
    for k in ("states", "measured", "command"):
        np.testing.assert_array_equal(a[k], b[k])


def test_bad_bandwidths():
    with pytest.raises(ValidationError, match=r"(?s)bandwidth.*-5.*must be >= 0 Hz"):
        Sensor(bandwidth=-5)
    with pytest.raises(ValidationError, match=r"(?s)bandwidth.*has units of m.*expects Hz"):
        Sensor(bandwidth="3 m")
    with pytest.raises(ValidationError, match=r"angular frequency.*15.9155 Hz"):
        Sensor(bandwidth="100 rad/s")
    assert Sensor(bandwidth="0.2 kHz").bandwidth == 200.0
    p = prepare(_rotary(duration=0.1, bandwidth=1000.0))  # ω_f h = 0.63 at T/10
    with pytest.raises(ValueError, match=r"'tip_deflection'.*1000 Hz.*substeps to >= 13"):
        simulate_loop(p.loop, p.x0, p.references, p.n_samples)


def test_fast_bench_loop_equals_simulator_with_filters():
    """The bench fitter's batched loop (:mod:`flexarm.sim.rig_loop`) with
    both channels filtered (hub 50 Hz, tip 20 Hz) equals :func:`simulate_loop` on the same arm, to
    rounding, as without filters (tests/test_time_domain_fit.py): 1e-9 rad / m / V."""
    fth, fd = 50.0, 20.0
    sc = _rotary()
    sensors = dict(sc.sensors)
    sensors["motor_angle"] = sensors["motor_angle"].model_copy(update={"bandwidth": fth})
    sensors["tip_deflection"] = sensors["tip_deflection"].model_copy(update={"bandwidth": fd})
    p = prepare(sc.model_copy(update={"sensors": sensors}))
    x0 = p.model.initial_state(0.0, 0.0, 0.01)
    out = simulate_loop(p.loop, x0, p.references, p.n_samples)
    unfiltered = prepare(sc)
    plain = simulate_loop(unfiltered.loop, x0, unfiltered.references, unfiltered.n_samples)
    L, m, EI = 0.42, 0.019841, 0.168
    wc2 = 3 * EI / L**3 / m
    ku = 0.9 * 0.69 * 70 * 7.68e-3 / 2.6
    n = p.n_samples
    const = as_jax(
        dict(
            dt=1e-3,
            length=L,
            k_u=ku,
            k_omega=ku * 70 * 7.68e-3,
            q_th=2 * np.pi / 4096,
            q_d=0.0,
            limit=10.0,
            vel_tol=1e-3,
            omega_th=2 * np.pi * fth,
            omega_d=2 * np.pi * fd,
        )
    )
    z = np.zeros((1, n))
    names = p.loop.sensors.names
    meas = np.asarray(out["measured"])  # the loop reads the "log" while a delay line fills
    data = as_jax(
        dict(
            ref=p.references["reference"][None],
            y_th=meas[:, names.index("motor_angle")][None],
            y_d=meas[:, names.index("tip_deflection")][None],
            w_th=z,
            w_d=z,
            volt=z,
            K=np.array([[6.0, -40.0, 0.15, 0.0]]),
            tau=np.zeros(1),
        )
    )
    model = as_jax(
        {
            k: np.full((1, 1), v)
            for k, v in dict(
                J=2.08e-3,
                B=4e-3,
                wc2=wc2,
                c2z=0.06 * np.sqrt(wc2),
                JlL=m * L,
                Fc=0.03,
                Fs=0.04,
                bias=0.0,
                gain=1.0,
                dth=0,
                dd=2,
                th0=0.0,
                om0=0.0,
                w0=0.01,
                wd0=0.0,
            ).items()
        }
    )
    tr, _ = closed_loop_run(model, data, const, substeps=p.loop.substeps, filters=(True, True))
    names = p.loop.sensors.names
    worst = 0.0
    for k, sig in enumerate(("motor_angle", "tip_deflection")):
        fast, sim = np.asarray(tr[k])[:, 0, 0], out["measured"][:, names.index(sig)]
        worst = max(worst, float(np.max(np.abs(fast - sim))))
        np.testing.assert_allclose(fast, sim, atol=1e-9)
        # and the filters matter: far from the unfiltered measurement
        assert np.max(np.abs(sim - plain["measured"][:, names.index(sig)])) > 1e-4
    np.testing.assert_allclose(np.asarray(tr[2])[:, 0, 0], out["command"][:, 0], atol=1e-9)
    print(f"fast loop vs simulator with filters: max |diff| {worst:.2e}")


def test_fit_filters_keyword_is_checked(tmp_path):
    from flexarm.identification.time_domain import FitInputError
    from flexarm.identification.time_domain.fit import fit
    from flexarm.identification.time_domain.objective import check_filters

    assert check_filters({"tip_deflection": 50}, 1e-3, 2) == {
        "motor_angle": 0.0,
        "tip_deflection": 50.0,
    }
    head = "time,reference,voltage,motor_angle,tip_deflection\n"
    rows = "\n".join(f"{k * 1e-3:.3f},0,0,{0.001 * k},0" for k in range(100))
    log = tmp_path / "a.csv"
    log.write_text("# controller: state_feedback K1=6 K2=-40 K3=0.15 K4=0\n" + head + rows)
    rig = dict(
        drive="voltage",
        gear_ratio=70,
        motor_constant=7.68e-3,
        armature_resistance=2.6,
        link_length=0.42,
    )
    with pytest.raises(
        FitInputError,
        match=r"field 'filters' has channel 'tip_angle'.*"
        r"not known; use 'motor_angle' or 'tip_deflection'",
    ):
        fit([log], **rig, filters={"tip_angle": 30.0})
    with pytest.raises(FitInputError, match=r"field 'filters\['tip_deflection'\]' = -5: .*>= 0"):
        fit([log], **rig, filters={"tip_deflection": -5})
    with pytest.raises(
        FitInputError,
        match=r"'filters\['motor_angle'\]' = 200 Hz is too fast"
        r".*substeps >= 3",
    ):
        fit([log], **rig, filters={"motor_angle": 200.0})
